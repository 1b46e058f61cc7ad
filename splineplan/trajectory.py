"""Level 3: a B-spline through the roadmap, smoothed for speed, with a speed profile.

(Kala & Warwick, section IV, read as in ALGORITHM.md.) The control points of a clamped
B-spline are roadmap vertices, after the vehicle's position and a heading point just ahead of
it along its heading. While some point of the curve allows less than ``s_max`` (equation 1),
the control point nearest the slowest point moves to its neighbours' mean (equation 3); a
move is kept only if the vehicle's footprint along the changed part of the curve stays on
the road (``TrajectoryParams.road_margin`` inside its edges, by default none) and clear of
the obstacles by the safety margin, and the curvature stays within the turning limit.

Steps, and the choices beyond the paper:

1. Band simplification picks the control points. Each chosen roadmap vertex ``k`` stands
   on its sweep line at the midpoint ``l_k`` of its free interval ``[lo_k, hi_k]``; its band
   is ``l_k +- rho (hi_k - lo_k) / 2`` (``band_fraction`` rho). Greedy string pulling keeps,
   from the last kept vertex, the farthest vertex such that the straight segments to it
   cross every skipped sweep line inside its band
   (:func:`~splineplan.control_polygon.band_simplify`), within level 2's band
   (:attr:`~splineplan.roadmap.Roadmap.band_lo`, ``band_hi``: 90 % of the vertex's
   separation from the obstacles, and its lane where it keeps one's centre), so that the
   separation is not traded for fewer, straighter legs. rho = 0 only drops collinear
   vertices. Legs
   longer than ``max_control_spacing`` get extra control points on them, so that
   equation (3) has points to move on long straights.
2. Lead-in: the first roadmap vertex used is the farthest that the vehicle's position
   reaches within the bands (within ``max_control_spacing``), and at least the lead-in
   distance ahead. Where that curve makes the vehicle start slower than it drives (an
   obstacle beside its lane just ahead: the curve keeps the start's heading for half the
   lead-in and then bends sharply past it), the lead-in is shortened to two thirds and a
   third of it in turn (:data:`SHORT_LEADS`), and the better curve kept
   (:func:`_better`). Where the road bends tighter than twice the turning radius (a
   junction turn, a kinked lane), the first polygon is instead the one that spreads the
   turn over the bands (:func:`~splineplan.control_polygon.min_turning_offsets`: least
   bending, reweighted towards the least largest turn), from a heading point one sweep
   line ahead through every vertex; where its curve still turns beyond the limit, the
   same polygon again with every vertex kept where it turns (a long leg among short
   ones bends the uniform-knot spline beyond its polygon), and then with the bands
   widened to the free intervals (which keep the safety margin by construction; within
   level 2's bands where it placed the vertices).
3. Repair: a clamped B-spline cuts its polygon's corners (by about
   ``|P_{i-1} - 2 P_i + P_{i+1}| / 6`` for a cubic). Where the first curve's footprint is not
   clear, or where it strays more than ``BAND_TOL`` beyond level 2's bands (the rounding
   of a corner beside an obstacle), the left-out roadmap vertex nearest the violation
   comes back; where none is left,
   the control point nearest it is doubled (repeated control points pull the curve onto
   the polygon); a few rounds, and the least violating curve is kept. Where it still comes
   within the margin of one road edge while the other leaves room (a lane's curve cutting
   a corner by a few centimetres), the control points that shape it move sideways by what
   it lacks (:func:`~splineplan.optimiser._push`).
4. Equation (3). "Nearest" control point: nearest in parameter, by Greville abscissa, among
   the ``degree + 1`` control points that shape the curve at that point; if it may not
   move, the next nearest of those. Moves whose supports do not overlap commute, so each
   round makes the move of the slowest point and the moves of the slowest points of other
   independent stretches. A move changes the samples linearly (cached basis: new = old +
   basis column * delta), so only the changed stretch is re-evaluated and re-checked.
   Where level 2 placed the vertices, no move (nor the steering's smoothing) brings a
   sample that keeps 90 % of its vertex's separation from the obstacles, at most
   ``TrajectoryParams.keep_separation`` beyond the safety margin, below that
   (:meth:`~splineplan.optimiser._Optimiser.keep_separation`).
5. Feasibility: the footprint is the vehicle's rectangle centred on the curve and oriented
   along it; its distance to each nearby obstacle polygon is exact (culled by bounding
   box); on the road its corners and long-side midpoints keep the road margin from the road
   edges (the corridor is extended past its ends), and so do the edges' vertices that
   point into the road, which can meet the footprint's sides between those points.
   Curvature above ``1 / min_turn_radius`` is infeasible. A curve that starts infeasible
   is not refused outright: a move is then kept if no feasible sample becomes infeasible
   and the worst violation of the changed part does not grow (exactly "the new curve is
   feasible" when the start is feasible).
   The result reports ``feasible`` honestly.
6. Single moves can sharpen a bend for a while, so the curve returned is the one with the
   highest minimum allowed speed seen after any round: it never decreases.
   Where neither control polygon (nor the detour, step 8) gives a feasible curve, the one
   returned is the least violating: footprint first, then curvature, as in step 3.
7. Speed profile (:mod:`splineplan.speed`) along the final curve, sampled evenly in arc length.
8. Where no feasible curve keeps level 2's bands, steps 1-7 run through the free
   intervals' midpoints (:meth:`~splineplan.roadmap.Roadmap.at_midpoints`), the paper's
   vertices. Detour: where the curve along level 2's path ends infeasible (the widest path can cross
   lanes faster than any curve within the turning limit), the same graph is searched for
   a path of limited lateral rate (:func:`~splineplan.control_polygon.detour_roadmap`)
   and steps 1-7 run along it; its curve is kept if it is feasible.

Modules: the control polygon and the detour (steps 1, 2, 8) in
:mod:`splineplan.control_polygon`, the curve, its repair and equation (3) (steps 3, 4, 6) in
:mod:`splineplan.optimiser`, the footprint check (step 5) in :mod:`splineplan.footprint`,
the parameters in :mod:`splineplan.trajectory_params` and the curvature in
:mod:`splineplan.curvature`; here the entry point, the result and the sampling (step 7).
"""


from __future__ import annotations

import logging
import math
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
from numpy.typing import ArrayLike
from scipy.interpolate import BSpline

from splineplan.control_polygon import (
    VertexFrame,
    _control_points,
    _sharp_bend,
    _steep,
    detour_roadmap,
    vertex_frame,
)
from splineplan.corridor import Corridor
from splineplan.curvature import curvature_discrete, curvature_from_derivatives
from splineplan.errors import ParameterError, TrajectoryError
from splineplan.footprint import _Checker
from splineplan.geometry import FloatArray, wrap_angle
from splineplan.obstacles import Obstacles
from splineplan.optimiser import _Curve, _Optimiser, _refine
from splineplan.roadmap import Roadmap, RoadmapParams
from splineplan.speed import (
    allowed_speed,
    nearby_curvature,
    speed_profile,
    times_from_profile,
    towed_speed_limit,
)
from splineplan.trajectory_params import TrajectoryParams

__all__ = [
    "IterationStats",
    "Trajectory",
    "TrajectoryParams",
    "Violation",
    "broken_limits",
    "curvature_discrete",
    "curvature_from_derivatives",
    "plan_trajectory",
    "sample_violations",
]

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class IterationStats:
    """Control-point moves of the optimisation: tried, accepted and refused, and rounds;
    the repair rounds of the first curve, the control points used, and how many control
    points the repair doubled."""

    tried: int = 0
    accepted: int = 0
    refused: int = 0
    rounds: int = 0
    refinements: int = 0
    control_points: int = 0
    doubled: int = 0


@dataclass(frozen=True)
class Violation:
    """Where a trajectory breaks one of its limits, at its worst point.

    ``kind`` is ``"obstacle"`` (the footprint comes within the safety margin of an
    obstacle), ``"road"`` (within the road margin of a road edge, negative: off the road) or
    ``"curvature"`` (a turn tighter than ``1 / min_turn_radius``); ``value`` is the worst
    clearance [m] or curvature [1/m] and ``limit`` the margin or the turning limit it
    breaks; ``s`` [m] is the arc length along the trajectory and ``x, y`` [m] the vehicle's
    centre there.
    """

    kind: str
    value: float
    limit: float
    s: float
    x: float
    y: float

    def describe(self, corridor: Corridor | None = None) -> str:
        """One phrase saying what is broken where; with the corridor the plan followed,
        also the station along it and the SUMO edge (or junction) there."""
        what = (f"curvature {self.value:.3f} 1/m above the turning limit {self.limit:.3f} 1/m"
                if self.kind == "curvature" else
                f"footprint {self.value:.2f} m from an obstacle (safety margin "
                f"{self.limit:.2f} m)" if self.kind == "obstacle" else
                f"footprint {self.value:.2f} m from the road edge (road margin "
                f"{self.limit:.2f} m)" if self.value >= 0 else
                f"footprint {-self.value:.2f} m off the road")
        where = f"{self.s:.1f} m along the trajectory, at ({self.x:.1f}, {self.y:.1f})"
        if corridor is not None:
            station = float(corridor.to_sl(np.array([[self.x, self.y]]))[0, 0])
            junction = corridor.junction_at(station)
            edge = corridor.edge_at(station)
            where += f", station {corridor.offset + station:.1f} m"
            if junction is not None:
                where += f" (junction {junction[0]} -> {junction[1]})"
            elif edge is not None:
                where += f" (edge {edge})"
        return f"{what}, {where}"


@dataclass(frozen=True, eq=False)
class Trajectory:
    """Result of level 3: samples along the curve, evenly spaced in arc length.

    Attributes
    ----------
    t, x, y, heading, speed, curvature, s
        ``(n,)`` arrays: time [s] from the start, the vehicle centre [m], heading [rad]
        (counter-clockwise from east), speed [m/s], signed curvature [1/m] (positive to the
        left) and arc length [m].
    control_points
        Final control points ``(c, 2)`` [m] of the spline.
    spline
        The final curve (``scipy.interpolate.BSpline``, parameter in [0, 1]); ``None`` for
        a trajectory joined from several splines.
    clearance_obstacles, clearance_road
        ``(n,)`` [m]: distance of the footprint to the nearest obstacle (``inf`` beyond
        ``safety_margin`` + :data:`splineplan.footprint.CLEARANCE_HORIZON`) and to the
        nearer road edge.
    feasible
        Whether the footprint keeps the safety margin from the obstacles and the road margin
        from the road edges at every sample, and the curvature stays within
        ``1 / min_turn_radius``.
    iterations
        Moves tried, accepted and refused.
    min_speed_before, min_speed_after
        Lowest speed [m/s] that equation (1) allows on the curve before and after the
        optimisation.
    safety_margin, road_margin
        Margins [m] from the obstacles and from the road edges that the feasibility was
        checked with.
    violations
        Why the trajectory is infeasible: each broken limit at its worst point
        (:class:`Violation`; one per limit and planned piece, in order along the curve
        within a piece), empty exactly when ``feasible``. The limits are also checked
        on the optimiser's own samples of the curve, which lie between these samples.
    """

    t: FloatArray
    x: FloatArray
    y: FloatArray
    heading: FloatArray
    speed: FloatArray
    curvature: FloatArray
    s: FloatArray
    control_points: FloatArray
    spline: BSpline | None
    clearance_obstacles: FloatArray
    clearance_road: FloatArray
    feasible: bool
    iterations: IterationStats = field(default_factory=IterationStats)
    min_speed_before: float = float("nan")
    min_speed_after: float = float("nan")
    safety_margin: float = 0.0
    road_margin: float = 0.0
    violations: tuple[Violation, ...] = ()

    @property
    def xy(self) -> FloatArray:
        """Centre points ``(n, 2)`` [m]."""
        return np.column_stack((self.x, self.y))

    @property
    def duration(self) -> float:
        """Time [s] to drive the whole trajectory."""
        return float(self.t[-1])

    @property
    def length(self) -> float:
        """Arc length [m] of the curve."""
        return float(self.s[-1])

    @property
    def min_clearance(self) -> float:
        """Smallest footprint clearance [m] to an obstacle or a road edge along the curve."""
        return float(min(np.min(self.clearance_obstacles), np.min(self.clearance_road)))

    def at_time(self, t: ArrayLike) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
        """Pose and speed at times ``t`` [s], clamped to the trajectory's span.

        Returns x, y [m], heading [rad] and speed [m/s], each shaped like ``t``.
        """
        tt = np.clip(np.asarray(t, dtype=float), self.t[0], self.t[-1])
        head = np.unwrap(self.heading)
        return (np.interp(tt, self.t, self.x), np.interp(tt, self.t, self.y),
                wrap_angle(np.interp(tt, self.t, head)), np.interp(tt, self.t, self.speed))

    def at_station(self, s: ArrayLike) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
        """Pose and speed at arc lengths ``s`` [m]: x, y [m], heading [rad], speed [m/s]."""
        ss = np.clip(np.asarray(s, dtype=float), self.s[0], self.s[-1])
        head = np.unwrap(self.heading)
        return (np.interp(ss, self.s, self.x), np.interp(ss, self.s, self.y),
                wrap_angle(np.interp(ss, self.s, head)), np.interp(ss, self.s, self.speed))

    def resample(self, dt: float) -> Trajectory:
        """The trajectory at time steps ``dt`` [s] (a simulation step), ending at its end."""
        if not (np.isfinite(dt) and dt > 0):
            raise ParameterError(f"time step must be positive, got {dt!r}")
        if not np.isfinite(self.t[-1]):
            raise TrajectoryError("trajectory never ends (zero speed on the way)")
        tt = np.arange(0.0, self.t[-1], dt)
        tt = np.append(tt, self.t[-1]) if self.t[-1] - tt[-1] > 1e-9 else tt
        x, y, head, v = self.at_time(tt)
        s = np.interp(tt, self.t, self.s)
        return Trajectory(
            tt, x, y, head, v, np.interp(tt, self.t, self.curvature), s, self.control_points,
            self.spline, np.interp(tt, self.t, self.clearance_obstacles),
            np.interp(tt, self.t, self.clearance_road), self.feasible, self.iterations,
            self.min_speed_before, self.min_speed_after, self.safety_margin, self.road_margin,
            self.violations)


# ---- planning --------------------------------------------------------------------------
def plan_trajectory(
    roadmap: Roadmap,
    corridor: Corridor,
    obstacles: Obstacles | None,
    params: TrajectoryParams | None = None,
    start_heading: float | None = None,
    *,
    start_speed: float = 0.0,
    end_speed: float | None = None,
    polish: bool = True,
) -> Trajectory:
    """Speed-optimised B-spline trajectory along a roadmap.

    Parameters
    ----------
    roadmap
        Level 2's result; its vertices are the control points and its parameters give the
        vehicle's size and safety margin.
    corridor, obstacles
        The road segment and the obstacles the roadmap was planned among (the real ones:
        the footprint is checked against them with the safety margin); ``None``: none.
    params
        Level-3 parameters (defaults if ``None``).
    start_heading
        Vehicle heading [rad] at ``roadmap.start_xy``; ``None`` starts towards the first
        control point after the lead-in.
    start_speed
        Speed [m/s] at the start, from 0 to ``params.s_max``: a vehicle already faster than
        it may drive is an error, not a plan that silently starts slower. Below ``s_max``
        but above what the curve ahead allows, the profile starts at what it allows.
    end_speed
        Speed [m/s] at the end: 0 stops there, ``None`` keeps going as fast as allowed.
    polish
        ``False``: the first curve through the roadmap as it comes, with its speed
        profile: no repair, no equation (3), no other control polygon and no detour
        (steps 3, 4 and 8), for a roadmap that no forward curve can drive (a turnaround).

    Raises
    ------
    TrajectoryError
        Fewer than two distinct roadmap points, a start off the road, or a start speed
        below 0 or above ``params.s_max``.
    """
    params = params or TrajectoryParams()
    check_start_speed(start_speed, params)
    obstacles = Obstacles.empty() if obstacles is None else obstacles
    if not polish:
        params = replace(params, max_iterations=0, repair_rounds=0, bend_rounds=0)
    traj = _plan_polygons(roadmap, corridor, obstacles, params, start_heading, start_speed,
                          end_speed, polish)
    if traj.feasible or not polish or len(roadmap.band_lo) != len(roadmap.s):
        return traj
    # no feasible curve keeps the separation of level 2's placed vertices: the curve
    # through the free intervals' midpoints, without the bands, as the paper's
    other = _plan_polygons(roadmap.at_midpoints(), corridor, obstacles, params, start_heading,
                           start_speed, end_speed, polish)
    log.debug("no feasible curve within level 2's bands; through the midpoints: %s",
              other.feasible)
    return _less_violating(traj, other, params)


def _plan_polygons(roadmap: Roadmap, corridor: Corridor, obstacles: Obstacles,
                   params: TrajectoryParams, start_heading: float | None,
                   start_speed: float, end_speed: float | None, polish: bool
                   ) -> Trajectory:
    """:func:`plan_trajectory` along one placement of the roadmap's vertices: both control
    polygons, then the detour; where none is feasible, those curves again with their
    bends eased (:meth:`splineplan.optimiser._Optimiser.ease_bends`), least violating
    first, until one is."""
    made: list[tuple[Trajectory, Roadmap, TrajectoryParams, dict[str, Any]]] = []

    def attempt(rm: Roadmap, tp: TrajectoryParams = params, **how: Any) -> Trajectory:
        tr = _plan_once(rm, corridor, obstacles, tp, start_heading, start_speed,
                        end_speed, **how)
        made.append((tr, rm, tp, how))
        return tr

    smooth = _sharp_bend(roadmap, corridor, params)
    frame = vertex_frame(roadmap, corridor, params)  # shared by both control polygons
    traj = attempt(roadmap, smooth=smooth, frame=frame)
    if smooth and polish and _too_sharp(traj, params):
        # the curve turns beyond the limit: the smooth polygon keeping its turning vertices
        other = attempt(roadmap, smooth=True, frame=frame, keep_turns=True)
        traj = _less_violating(traj, other, params)
        if _too_sharp(other, params):
            # and within the whole free intervals, not only the bands
            other = attempt(roadmap, smooth=True, frame=frame, keep_turns=True, free=True)
            traj = _less_violating(traj, other, params)
    if polish and (not traj.feasible or _slowed(traj, start_speed)):
        other = attempt(roadmap, smooth=not smooth, frame=frame)
        if not traj.feasible:
            log.debug("first control polygon gives no feasible curve; the other: %s",
                      other.feasible)
            traj = _less_violating(traj, other, params)
        else:
            log.debug("first control polygon's curve starts at %.1f m/s, below the start "
                      "speed; the other polygon's (feasible %s) at %.1f m/s",
                      float(traj.speed[0]), other.feasible, float(other.speed[0]))
            if other.feasible and float(other.speed[0]) > float(traj.speed[0]):
                traj = other
    for share in SHORT_LEADS if polish and not smooth else ():
        if not (traj.feasible and _slowed(traj, start_speed)):
            break
        # the lead-in holds the curve on the start's heading too long for what lies ahead
        # (an obstacle beside the lane just ahead): the first polygon with a shorter one
        # takes the offset over more of the way
        short = replace(params, lead_in_time=share * params.lead_in_time,
                        lead_in_lengths=share * params.lead_in_lengths)
        other = attempt(roadmap, short, frame=frame)
        log.debug("with %.2f of the lead-in the curve (feasible %s) starts at %.1f m/s",
                  share, other.feasible, float(other.speed[0]))
        if other.feasible and _better(other, traj, start_speed):
            traj = other
    if (not traj.feasible and polish and params.detour_rate > 0
            and _steep(roadmap, params.detour_rate)):
        detour = detour_roadmap(roadmap, corridor, params.detour_rate)
        if detour is not None:
            other = attempt(detour)
            log.debug("level 2's path gives no feasible curve; detour feasible: %s",
                      other.feasible)
            traj = _less_violating(traj, other, params)
    if traj.feasible or not polish or params.bend_rounds <= 0:
        return traj
    # the curves made again with their bends eased, least violating first, until one is
    # feasible
    for tr, rm, tp, how in sorted(made, key=lambda m: _violation(m[0], params)):
        if _violation(tr, params)[0] > 0 or not _too_sharp(tr, params):
            continue  # the footprint too close, or a kink: easing does not mend them
        for target in BEND_TARGETS:
            other = _plan_once(rm, corridor, obstacles, tp, start_heading, start_speed,
                               end_speed, **how, ease=target)
            log.debug("no feasible curve; with its bends eased to %.3f of the limit: %s",
                      target, other.feasible)
            traj = _less_violating(traj, other, params)
            if traj.feasible or _violation(other, params)[1] > NEAR_LIMIT * params.kappa_max:
                break
        if traj.feasible:
            break
    return traj


def check_start_speed(start_speed: float, params: TrajectoryParams) -> None:
    """Raise :class:`TrajectoryError` unless ``start_speed`` [m/s] is a number from 0 to
    ``params.s_max`` (rounding allowed)."""
    try:
        v = float(start_speed)
    except (TypeError, ValueError):
        raise TrajectoryError(f"start_speed must be a number, got {start_speed!r}") from None
    if not (math.isfinite(v) and v >= 0):
        raise TrajectoryError(f"start_speed must be >= 0 m/s, got {start_speed!r}")
    if v > params.s_max + _SPEED_TOL:
        raise TrajectoryError(
            f"start_speed {v:.2f} m/s exceeds TrajectoryParams.s_max ({params.s_max:.2f} "
            "m/s), the most the vehicle may drive; raise s_max or start slower")


#: Rounding [m/s] allowed above ``s_max`` in a start speed (a closed loop's speed read back).
_SPEED_TOL = 1e-6


def _violation(tr: Trajectory, params: TrajectoryParams) -> tuple[float, float]:
    """How far [m] the footprint comes inside its margins (obstacles and road edges), and
    the curvature [1/m] beyond the turning limit: 0 and 0 where feasible."""
    inside = max(tr.safety_margin - float(np.min(tr.clearance_obstacles)),
                 tr.road_margin - float(np.min(tr.clearance_road)), 0.0)
    return inside, max(float(np.max(np.abs(tr.curvature))) - params.kappa_max, 0.0)


def _less_violating(first: Trajectory, other: Trajectory, params: TrajectoryParams
                    ) -> Trajectory:
    """The feasible one of two curves, the first if both are; where neither is, the one
    whose footprint comes less far inside its margins, then the one less over the turning
    limit (the order of the repair, step 3): a curve that leaves the road is worse than
    one that asks for a tighter turn than the vehicle has."""
    if first.feasible or (not other.feasible and (
            _violation(first, params) <= _violation(other, params))):
        return first
    return other


def _slowed(tr: Trajectory, start_speed: float) -> bool:
    """Whether the curve makes the vehicle start more than :data:`SLOW_START` slower than
    it drives (its first bend too sharp for the speed, within less than the braking
    distance): no vehicle can, and a closed loop would have to brake hard."""
    return float(tr.speed[0]) < start_speed - SLOW_START


#: Shortfall [m/s] of a curve's first speed below the start speed at which
#: :func:`_plan_polygons` tries the other control polygon too.
SLOW_START = 0.5
#: Shares of the lead-in's length with which :func:`_plan_polygons` tries the first
#: polygon again, in turn, while the curve still starts slower than the vehicle drives
#: (:func:`_slowed`).
SHORT_LEADS = (2.0 / 3.0, 1.0 / 3.0)


def _better(tr: Trajectory, than: Trajectory, start_speed: float) -> bool:
    """Whether curve ``tr`` drives better than ``than`` from the start: it starts at the
    vehicle's speed where the other does not, or as well and reaches the shorter one's
    end sooner."""
    ok, ok_than = not _slowed(tr, start_speed), not _slowed(than, start_speed)
    if ok != ok_than:
        return ok
    end = min(float(tr.s[-1]), float(than.s[-1]))
    return float(np.interp(end, tr.s, tr.t)) < float(np.interp(end, than.s, than.t))


def _too_sharp(tr: Trajectory, params: TrajectoryParams) -> bool:
    """Whether the trajectory breaks the turning limit, by at most :data:`NEAR_MISS` times
    it (sharper bends, which the polygon's variants did not mend, are not worth their
    time)."""
    return any(v.kind == "curvature" and v.value <= NEAR_MISS * params.kappa_max
               for v in tr.violations)


#: Largest share of the turning limit at which :func:`_plan_polygons` tries the junction
#: polygon's variants and eases a curve's bends.
NEAR_MISS = 2.5
#: Shares of the turning limit that the bends' easing aims the curvature at, in turn: the
#: final curve is sampled more densely than the optimiser's samples, and a bend eased to
#: just under the limit there can come out just over it between them.
BEND_TARGETS = (0.985, 0.9)
#: How far an eased curve may still turn beyond the limit, as a share of it, for the next,
#: lower target of :data:`BEND_TARGETS` to be tried.
NEAR_LIMIT = 0.05


def _plan_once(roadmap: Roadmap, corridor: Corridor, obstacles: Obstacles,
               params: TrajectoryParams, start_heading: float | None, start_speed: float,
               end_speed: float | None, smooth: bool = False,
               frame: VertexFrame | None = None, keep_turns: bool = False,
               free: bool = False, ease: float = 0.0) -> Trajectory:
    """:func:`plan_trajectory` along the roadmap's chosen path (``smooth``: from the
    least-bending control polygon, ``keep_turns``: keeping its turning vertices, ``free``:
    within the free intervals, see :func:`_control_points`; ``frame``: the roadmap's
    :func:`~splineplan.control_polygon.vertex_frame`, computed here if ``None``; ``ease``:
    above 0, with the bends that equation (3) leaves beyond the turning limit eased to that
    share of it)."""
    rp = roadmap.params
    pool, counts = _control_points(roadmap, corridor, start_heading, params, start_speed,
                                   smooth, frame=frame, keep_turns=keep_turns, free=free)
    checker = _Checker.build(corridor, obstacles, rp, pool, params.road_margin)
    band = None
    if len(roadmap.band_lo) == len(roadmap.s):
        band = (np.asarray(roadmap.s, dtype=float), np.asarray(roadmap.band_lo, dtype=float),
                np.asarray(roadmap.band_hi, dtype=float))
    curve, refinements, doubled, samples = _refine(pool, counts, checker, params, band)
    opt = _Optimiser(curve, checker, params, samples)
    if band is not None and len(roadmap.separation) == len(roadmap.s):
        opt.keep_separation(band[0], np.asarray(roadmap.separation, dtype=float))
    kappa_before = opt.kappa.copy()
    tried, accepted, refused, rounds = opt.run()
    if ease > 0:
        opt.ease_bends(params.bend_rounds, ease)
    opt.smooth_steering(start_speed)
    stats = IterationStats(tried, accepted, refused, rounds, refinements, len(curve.ctrl),
                           doubled)
    final = opt.ctrl
    spline = BSpline(curve.knots, final, curve.k)
    traj = _sample(spline, curve, opt, checker, params, rp, start_speed, end_speed)
    v_before = allowed_speed(kappa_before, mu=params.mu, g=params.g, s_max=params.s_max)
    return Trajectory(
        traj["t"], traj["x"], traj["y"], traj["heading"], traj["speed"], traj["curvature"],
        traj["s"], final, spline, traj["clear_obs"], traj["clear_road"],
        not traj["violations"], stats, float(v_before.min()),
        float(allowed_speed(opt.kappa, mu=params.mu, g=params.g, s_max=params.s_max).min()),
        rp.safety_margin, params.road_margin, traj["violations"])


def _sample(spline: BSpline, curve: _Curve, opt: _Optimiser, checker: _Checker,
            params: TrajectoryParams, rp: RoadmapParams, start_speed: float,
            end_speed: float | None) -> dict[str, Any]:
    """Samples evenly spaced in arc length, with speeds, times, clearances and the limits
    they break."""
    # arc length on a table four times denser than the optimiser's samples
    sub = 4
    grid = curve.u[:-1, None] + np.diff(curve.u)[:, None] * (np.arange(sub) / sub)[None, :]
    ud = np.concatenate((grid.ravel(), curve.u[-1:]))
    pd = spline(ud)
    sd = np.concatenate(([0.0], np.cumsum(np.hypot(*np.diff(pd, axis=0).T))))
    m = max(int(np.ceil(sd[-1] / params.sample_spacing)), 1) + 1
    s = np.linspace(0.0, sd[-1], m)
    uu = np.interp(s, sd, ud)
    pos, d1, d2 = spline(uu), spline(uu, 1), spline(uu, 2)
    kappa = curvature_from_derivatives(d1, d2)
    head = np.arctan2(d1[:, 1], d1[:, 0])
    limit = speed_limit(s, kappa, params)
    speed = speed_profile(s, limit, a_max=params.a_max, b_max=params.b_max,
                          start_speed=start_speed, end_speed=end_speed)
    clear_obs = checker.obstacles(pos, head)
    clear_road, _ = checker.road(pos, head, np.interp(uu, curve.u, opt.station))
    violations = sample_violations(s, pos, kappa, clear_obs, clear_road, rp.safety_margin,
                                   params.road_margin, params.kappa_max)
    # the optimiser's samples lie between these, and its verdict counts too: a limit
    # broken only there is reported at its sample (arc length read off the dense table)
    s_opt = np.interp(curve.u, ud, sd)
    between = sample_violations(s_opt, opt.pos, opt.kappa, np.full(len(s_opt), np.inf),
                                np.full(len(s_opt), np.inf), rp.safety_margin,
                                params.road_margin, params.kappa_max)
    if np.any(opt.slack < -1e-6):
        j = int(np.argmin(opt.slack))
        pj, hj = opt.pos[j:j + 1], np.arctan2(opt.d1[j:j + 1, 1], opt.d1[j:j + 1, 0])
        obs = float(checker.obstacles(pj, hj)[0]) - rp.safety_margin
        road = float(checker.road(pj, hj, opt.station[j:j + 1])[0][0]) - params.road_margin
        kind, margin = (("obstacle", rp.safety_margin) if obs <= road
                        else ("road", params.road_margin))
        between += (Violation(kind, margin + float(opt.slack[j]), margin, float(s_opt[j]),
                              float(pj[0, 0]), float(pj[0, 1])),)
    return {"t": _times(s, speed), "x": pos[:, 0], "y": pos[:, 1], "heading": head,
            "speed": speed, "curvature": kappa, "s": s, "clear_obs": clear_obs,
            "clear_road": clear_road, "violations": _worst_of(violations + between)}


#: Reach [m] either side of a point within which the sharpest curvature sets its cornering
#: speed (equation (1)): where a bend tightens, the path's curvature measured over a few
#: metres (:func:`splineplan.metrics.path_curvature`) runs ahead of its value at the
#: point, and a car driven at the point's cornering speed went up to 5 % beyond mu g.
CORNER_REACH = 2.0


def speed_limit(s: FloatArray, curvature: FloatArray, params: TrajectoryParams, *,
                slip0: float | None = None) -> FloatArray:
    """Speed limit ``(n,)`` [m/s] along a curve sampled at arc lengths ``s`` [m]: the
    cornering speed of equation (1), ``s_max``, and what the steering rate allows for the
    wheel angles of the car whose rear axle is towed half the wheelbase behind the curve
    (:func:`~splineplan.speed.towed_speed_limit`), from the slip angle ``slip0`` [rad] at
    the start (``None``: the steady turn's at the start's curvature)."""
    return np.minimum(
        allowed_speed(nearby_curvature(s, curvature, CORNER_REACH), mu=params.mu, g=params.g,
                      s_max=params.s_max),
        towed_speed_limit(s, curvature, wheelbase=params.wheelbase,
                          max_steering_rate=params.max_steering_rate, slip0=slip0))


def sample_violations(s: FloatArray, xy: FloatArray, curvature: FloatArray,
                      clear_obstacles: FloatArray, clear_road: FloatArray,
                      safety_margin: float, road_margin: float, kappa_max: float
                      ) -> tuple[Violation, ...]:
    """The worst sample of each limit that the samples break (see :func:`broken_limits`):
    ``s`` [m] arc lengths, ``xy`` ``(n, 2)`` centres [m], clearances [m], curvature [1/m]."""
    masks = broken_limits(curvature, clear_obstacles, clear_road, safety_margin,
                          road_margin, kappa_max)
    out = []
    for kind, bad, worst, value, limit in (
            ("obstacle", masks[0], np.argmin, clear_obstacles, safety_margin),
            ("road", masks[1], np.argmin, clear_road, road_margin),
            ("curvature", masks[2], np.argmax, np.abs(curvature), kappa_max)):
        if np.any(bad):
            j = int(worst(value))
            out.append(Violation(kind, float(value[j]), float(limit), float(s[j]),
                                 float(xy[j, 0]), float(xy[j, 1])))
    return tuple(out)


def broken_limits(curvature: FloatArray, clear_obstacles: FloatArray, clear_road: FloatArray,
                  safety_margin: float, road_margin: float, kappa_max: float
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per sample, with level 3's tolerance for rounding: the footprint within the safety
    margin [m] of an obstacle, within the road margin [m] of a road edge, and the
    curvature [1/m] over ``kappa_max``."""
    return (clear_obstacles < safety_margin - 1e-6, clear_road < road_margin - 1e-6,
            np.abs(curvature) > kappa_max * (1.0 + 1e-6))


def _worst_of(violations: tuple[Violation, ...]) -> tuple[Violation, ...]:
    """One violation per kind, the worst, in the order obstacle, road, curvature."""
    best: dict[str, Violation] = {}
    for v in violations:
        old = best.get(v.kind)
        if old is None or ((v.value > old.value) if v.kind == "curvature"
                           else (v.value < old.value)):
            best[v.kind] = v
    return tuple(best[k] for k in ("obstacle", "road", "curvature") if k in best)


def _times(s: FloatArray, v: FloatArray) -> FloatArray:
    """Times [s]; a step between two zero speeds (a cusp) never ends: ``inf`` from there."""
    stuck = (v[:-1] + v[1:] <= 0) & (np.diff(s) > 0)
    if not stuck.any():
        return times_from_profile(s, v)
    j = int(np.argmax(stuck))
    out = np.full(len(s), np.inf)
    out[:j + 1] = times_from_profile(s[:j + 1], v[:j + 1])
    return out
