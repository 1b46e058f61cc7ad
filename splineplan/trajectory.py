"""Level 3: a B-spline through the roadmap, smoothed for speed, with a speed profile.

(Kala & Warwick, section IV, read as in ALGORITHM.md.) The control points of a clamped
B-spline are the roadmap's vertices, plus one just ahead of the start along the vehicle's
heading. While some point of the curve allows less than ``s_max`` (equation 1), the control
point nearest the slowest point moves to its neighbours' mean (equation 3); a move is kept only
if the vehicle's footprint along the changed part of the curve stays on the road and clear of
the obstacles by the safety margin, and the curvature stays within the turning limit.

Design choices, beyond the paper:

- "Nearest" control point: nearest in parameter, by Greville abscissa, among the ``degree + 1``
  control points that shape the curve at that point (the one with the most influence there,
  monotone along the curve); if it may not move, the next nearest of those.
- Moves whose supports do not overlap (indices ``degree + 1`` or more apart) commute, so each
  round makes the move of the slowest point and, beside it, the moves of the slowest points of
  the other independent stretches; the acceptance test of each is the one it would get alone.
- Feasibility is checked at fixed parameter samples, only where a move changes the curve
  (``degree + 1`` knot spans). The footprint is the vehicle's rectangle centred on the curve
  and oriented along it; its distance to each nearby obstacle polygon is computed exactly
  (culled by bounding box); on the road its corners and long-side midpoints keep the margin
  from the road edges (the corridor is extended past its ends along its end segments).
- A curve that starts infeasible (the level-2 disc model is smaller than the rectangle, and the
  spline cuts the roadmap's corners) is not refused outright: a move is then kept if no sample
  that was feasible becomes infeasible and the worst violation of the changed part does not
  grow. When the start is feasible this is exactly "the new curve is feasible". The result
  reports the final clearance and a ``feasible`` flag honestly.
- Single moves to the neighbours' mean can sharpen a bend for a while (beside a point whose
  move was refused, or on a smooth bend before its neighbours follow), so the curve returned
  is the one with the highest minimum allowed speed seen after any round (at worst the
  initial curve): the minimum allowed speed never decreases.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.interpolate import BSpline

from splineplan.corridor import Corridor
from splineplan.errors import ParameterError, TrajectoryError
from splineplan.geometry import (
    FloatArray,
    dedupe_polyline,
    polyline_stations,
    wrap_angle,
)
from splineplan.obstacles import Obstacles
from splineplan.roadmap import Roadmap, RoadmapParams
from splineplan.speed import allowed_speed, speed_profile, times_from_profile

log = logging.getLogger(__name__)

#: Distance [m] beyond the safety margin within which obstacle clearance is computed exactly.
CLEARANCE_HORIZON = 2.0
_TOL = 1e-9


@dataclass(frozen=True)
class TrajectoryParams:
    """Parameters of level 3, checked on creation.

    Attributes
    ----------
    degree
        Degree of the B-spline (3: cubic), 2 to 5.
    mu
        Friction coefficient of equation (1).
    g
        Gravity [m/s^2].
    s_max
        Maximum speed [m/s] (default 50 km/h, urban).
    a_max, b_max
        Acceleration and braking limits [m/s^2].
    sample_spacing
        Spacing [m] of the trajectory's samples along the curve.
    min_turn_radius
        Smallest turning radius [m] of the vehicle: a hard limit on the curvature.
    max_iterations
        Cap on the number of control-point moves tried.
    band_fraction
        Fraction rho in [0, 1] of each free interval, centred on its midpoint, within which
        the initial control polygon crosses the sweep lines (band simplification); 0 keeps
        every turning vertex of the roadmap.
    max_control_spacing
        Longest stretch [m] of the roadmap between two control points of the initial
        polygon, so that equation (3) has points to move on long straights.
    repair_rounds
        Rounds of local repair of the first curve (vertices re-inserted, control points
        doubled) where its footprint is not clear.
    lead_in_lengths, lead_in_time
        The lead-in: roadmap vertices closer ahead of the vehicle than
        ``max(lead_in_lengths * vehicle_length, lead_in_time * start_speed)`` [m] are not
        control points at first, so that a lateral offset is taken over that distance.
    """

    degree: int = 3
    mu: float = 0.7
    g: float = 9.81
    s_max: float = 13.89
    a_max: float = 2.0
    b_max: float = 4.0
    sample_spacing: float = 0.5
    min_turn_radius: float = 5.0
    max_iterations: int = 5000
    band_fraction: float = 0.5
    max_control_spacing: float = 25.0
    repair_rounds: int = 6
    lead_in_lengths: float = 2.0
    lead_in_time: float = 1.5

    def __post_init__(self) -> None:
        if not isinstance(self.degree, int | np.integer) or not 2 <= self.degree <= 5:
            raise ParameterError(f"TrajectoryParams.degree must be an integer in 2..5, "
                                 f"got {self.degree!r}")
        for name in ("mu", "g", "s_max", "a_max", "b_max", "sample_spacing", "min_turn_radius",
                     "max_control_spacing"):
            value = getattr(self, name)
            if not (isinstance(value, int | float | np.floating | np.integer)
                    and np.isfinite(value) and value > 0):
                raise ParameterError(f"TrajectoryParams.{name} must be positive and finite, "
                                     f"got {value!r}")
        if not (isinstance(self.band_fraction, int | float | np.floating | np.integer)
                and 0.0 <= self.band_fraction <= 1.0):
            raise ParameterError(f"TrajectoryParams.band_fraction must be in [0, 1], "
                                 f"got {self.band_fraction!r}")
        for name in ("lead_in_lengths", "lead_in_time"):
            value = getattr(self, name)
            if not (isinstance(value, int | float | np.floating | np.integer)
                    and np.isfinite(value) and value >= 0):
                raise ParameterError(f"TrajectoryParams.{name} must be >= 0 and finite, "
                                     f"got {value!r}")
        for name in ("max_iterations", "repair_rounds"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int | np.integer) or value < 0:
                raise ParameterError(f"TrajectoryParams.{name} must be an integer >= 0, "
                                     f"got {value!r}")

    @property
    def kappa_max(self) -> float:
        """Hard curvature limit [1/m]: ``1 / min_turn_radius``."""
        return 1.0 / self.min_turn_radius

    @property
    def kappa_smax(self) -> float:
        """Curvature [1/m] above which equation (1) allows less than ``s_max``."""
        return self.mu * self.g / self.s_max**2


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
        ``safety_margin + CLEARANCE_HORIZON``) and to the nearer road edge.
    feasible
        Whether the footprint keeps the safety margin from obstacles and road edges at every
        sample and the curvature stays within ``1 / min_turn_radius``.
    iterations
        Moves tried, accepted and refused.
    min_speed_before, min_speed_after
        Lowest speed [m/s] that equation (1) allows on the curve before and after the
        optimisation.
    safety_margin
        Margin [m] the feasibility was checked with.
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
            self.min_speed_before, self.min_speed_after, self.safety_margin)


# ---- curvature -------------------------------------------------------------------------
def curvature_from_derivatives(d1: ArrayLike, d2: ArrayLike) -> FloatArray:
    """Signed curvature [1/m] ``(x'y'' - y'x'') / (x'^2 + y'^2)^(3/2)`` from ``(n, 2)`` derivatives.

    Positive when the curve turns left; its absolute value is the paper's curvature.
    """
    a = np.asarray(d1, dtype=float)
    b = np.asarray(d2, dtype=float)
    cross = a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]
    speed2 = np.einsum("...i,...i->...", a, a)
    with np.errstate(divide="ignore", invalid="ignore"):
        k = cross / speed2**1.5
    return np.asarray(np.where(speed2 > 0, k, np.inf))


def curvature_discrete(points: ArrayLike, h: float) -> FloatArray:
    """Equation (2): ``|S(t+delta) + S(t-delta) - 2 S(t)| / h^2`` [1/m].

    ``points`` ``(n, 2)`` [m] are spaced ``h`` [m] apart in arc length. The two end points,
    which lack a neighbour, copy their neighbour's value.
    """
    p = np.asarray(points, dtype=float)
    if len(p) < 3:
        raise TrajectoryError("discrete curvature needs at least 3 points")
    cu = np.hypot(*(p[2:] + p[:-2] - 2.0 * p[1:-1]).T) / h**2
    return np.concatenate(([cu[0]], cu, [cu[-1]]))


# ---- footprint -------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class _Checker:
    """Footprint clearance of the vehicle at curve samples, vectorised."""

    corridor: Corridor
    half_length: float
    half_width: float
    margin: float
    polys: FloatArray  # (K, V, 2), padded with each ring's last vertex
    bbox: FloatArray  # (K, 4)
    road_points: FloatArray = field(init=False)  # (q, 2) footprint points in the body frame

    def __post_init__(self) -> None:
        hl, hw = self.half_length, self.half_width
        pts = np.array([[-hl, -hw], [hl, -hw], [hl, hw], [-hl, hw], [0.0, -hw], [0.0, hw]])
        object.__setattr__(self, "road_points", pts)

    @classmethod
    def build(cls, corridor: Corridor, obstacles: Obstacles, params: RoadmapParams,
              near_xy: FloatArray) -> _Checker:
        reach = np.hypot(params.vehicle_length, params.vehicle_width) / 2.0
        obs = obstacles.near(near_xy, reach + params.safety_margin + CLEARANCE_HORIZON + 5.0)
        k = len(obs)
        vmax = int(np.max(np.diff(obs.offsets))) if k else 3
        polys = np.zeros((k, vmax, 2))
        for i in range(k):
            p = obs.polygon(i)
            polys[i, :len(p)] = p
            polys[i, len(p):] = p[-1]
        return cls(corridor, params.vehicle_length / 2.0, params.vehicle_width / 2.0,
                   params.safety_margin, polys, obs.bbox.copy() if k else np.zeros((0, 4)))

    def road(self, xy: FloatArray, heading: FloatArray) -> FloatArray:
        """Distance [m] of the footprint to the nearer road edge (negative: off the road).

        The centres are projected onto the reference line; each footprint point then in
        the frame of the reference segment at its own estimated station (the reference is
        resampled finely, so one segment's frame is exact enough; past the ends, the end
        segments extend the road).
        """
        cor = self.corridor
        sc = cor.to_sl(xy)[:, 0]
        ref, st = cor.reference, cor.s
        nseg = len(st) - 1
        ic = np.clip(np.searchsorted(st, sc, side="right") - 1, 0, nseg - 1)
        hseg = cor.heading_at(st[:-1])  # heading of each reference segment
        tc = hseg[ic]
        c, s = np.cos(heading), np.sin(heading)
        bx, by = self.road_points[:, 0], self.road_points[:, 1]
        px = xy[:, None, 0] + c[:, None] * bx - s[:, None] * by
        py = xy[:, None, 1] + s[:, None] * bx + c[:, None] * by
        # stations estimated along the centre's segment, then the segment there
        est = sc[:, None] + ((px - xy[:, None, 0]) * np.cos(tc)[:, None]
                             + (py - xy[:, None, 1]) * np.sin(tc)[:, None])
        i = np.clip(np.searchsorted(st, est, side="right") - 1, 0, nseg - 1)
        h = hseg[i]
        dx, dy = px - ref[i, 0], py - ref[i, 1]
        along = st[i] + dx * np.cos(h) + dy * np.sin(h)
        lat = -dx * np.sin(h) + dy * np.cos(h)
        r, lft = np.interp(along, st, cor.right), np.interp(along, st, cor.left)
        return np.asarray(np.minimum(lft - lat, lat - r).min(axis=1))

    def slack(self, xy: FloatArray, heading: FloatArray) -> FloatArray:
        """Footprint clearance [m] beyond the safety margin (negative: too close)."""
        near = self.obstacles(xy, heading, horizon=0.01)
        return np.asarray(np.minimum(near, self.road(xy, heading)) - self.margin)

    def obstacles(self, xy: FloatArray, heading: FloatArray,
                  horizon: float = CLEARANCE_HORIZON) -> FloatArray:
        """Distance [m] of the footprint to the nearest obstacle, ``inf`` beyond
        ``margin + horizon`` (obstacles are culled by bounding box)."""
        out = np.full(len(xy), np.inf)
        if len(self.polys) == 0 or len(xy) == 0:
            return out
        r = np.hypot(self.half_length, self.half_width) + self.margin + horizon
        b = self.bbox
        hit = ((b[None, :, 0] <= xy[:, None, 0] + r) & (b[None, :, 2] >= xy[:, None, 0] - r)
               & (b[None, :, 1] <= xy[:, None, 1] + r) & (b[None, :, 3] >= xy[:, None, 1] - r))
        js, os = np.nonzero(hit)
        if len(js) == 0:
            return out
        d = _rect_polygon_distance(xy[js], heading[js], self.half_length, self.half_width,
                                   self.polys[os])
        np.minimum.at(out, js, d)
        return out


def _rect_polygon_distance(centers: FloatArray, headings: FloatArray, hl: float, hw: float,
                           polys: FloatArray) -> FloatArray:
    """Distance [m] between oriented rectangles and polygons ``(p, V, 2)``, 0 on overlap."""
    c, s = np.cos(headings)[:, None], np.sin(headings)[:, None]
    rx = polys[..., 0] - centers[:, None, 0]
    ry = polys[..., 1] - centers[:, None, 1]
    u = rx * c + ry * s  # body frame: u along the heading, v to the left
    v = -rx * s + ry * c
    # polygon vertices to the filled rectangle
    dv = np.hypot(np.maximum(np.abs(u) - hl, 0.0), np.maximum(np.abs(v) - hw, 0.0)).min(axis=1)
    ub, vb = np.roll(u, -1, axis=1), np.roll(v, -1, axis=1)
    du, dvv = ub - u, vb - v
    # rectangle corners to polygon edges
    seg2 = du * du + dvv * dvv
    best = np.full(len(u), np.inf)
    for cu, cv in ((-hl, -hw), (hl, -hw), (hl, hw), (-hl, hw)):
        t = np.clip(((cu - u) * du + (cv - v) * dvv) / np.where(seg2 > 0, seg2, 1.0), 0.0, 1.0)
        best = np.minimum(best, np.hypot(u + t * du - cu, v + t * dvv - cv).min(axis=1))
    # polygon edges crossing the rectangle (Liang-Barsky clipping)
    t_in = np.zeros_like(u)
    t_out = np.ones_like(u)
    ok = np.ones(u.shape, dtype=bool)
    for a, d, h in ((u, du, hl), (v, dvv, hw)):
        flat = np.abs(d) < 1e-15
        ok &= ~flat | (np.abs(a) <= h)
        with np.errstate(divide="ignore", invalid="ignore"):
            t1 = (-h - a) / d
            t2 = (h - a) / d
        lo = np.where(flat, -np.inf, np.minimum(t1, t2))
        hi = np.where(flat, np.inf, np.maximum(t1, t2))
        t_in = np.maximum(t_in, lo)
        t_out = np.minimum(t_out, hi)
    crosses = (ok & (t_in <= t_out)).any(axis=1)
    # rectangle inside the polygon: its centre (the origin) by crossing number
    straddle = (v > 0) != (vb > 0)
    with np.errstate(divide="ignore", invalid="ignore"):
        ucross = u + (0.0 - v) * du / (vb - v)
    inside = (straddle & (ucross > 0)).sum(axis=1) % 2 == 1
    return np.asarray(np.where(crosses | inside, 0.0, np.minimum(dv, best)))


# ---- spline set-up ---------------------------------------------------------------------
def _knots(n: int, k: int) -> FloatArray:
    inner = np.linspace(0.0, 1.0, n - k + 1)
    return np.concatenate((np.zeros(k), inner, np.ones(k)))


def _basis(u: FloatArray, t: FloatArray, k: int, n: int) -> tuple[NDArray[np.int64], FloatArray]:
    """First control index ``(m,)`` and basis values ``(3, m, k + 1)`` for nu = 0, 1, 2.

    Row ``j`` holds the values at ``u[j]`` of the basis functions of control points
    ``first[j] .. first[j] + k`` (the only ones that are not zero there) and their first and
    second derivatives with respect to the parameter.
    """
    span = np.clip(np.searchsorted(t, u, side="right") - 1, k, n - 1)
    first = span - k
    rows = np.arange(len(u))[:, None]
    cols = first[:, None] + np.arange(k + 1)[None, :]
    vals = np.zeros((3, len(u), k + 1))
    for nu in range(3):
        if nu <= k:
            vals[nu] = _basis_matrix(u, t, k, nu)[rows, cols]
    return first.astype(np.int64), vals


def _basis_matrix(u: FloatArray, t: FloatArray, k: int, nu: int) -> FloatArray:
    """Dense ``(m, len(t) - k - 1)`` matrix of the ``nu``-th derivatives of the degree-``k``
    basis functions on knots ``t`` at ``u``: ``N'_{i,k} = k (N_{i,k-1} / (t_{i+k} - t_i)
    - N_{i+1,k-1} / (t_{i+k+1} - t_{i+1}))``."""
    if nu == 0:
        return np.asarray(BSpline.design_matrix(u, t, k).toarray())
    # Evaluate the lower degree just left of the end, where its last function is degenerate.
    low = _basis_matrix(np.minimum(u, np.nextafter(t[-1], t[0])), t, k - 1, nu - 1)
    nf = len(t) - k - 1
    i = np.arange(nf)
    den1 = t[i + k] - t[i]
    den2 = t[i + k + 1] - t[i + 1]
    a = np.divide(k, den1, out=np.zeros(nf), where=den1 > 0)
    b = np.divide(k, den2, out=np.zeros(nf), where=den2 > 0)
    return np.asarray(low[:, :nf] * a - low[:, 1:nf + 1] * b)


def _greville(t: FloatArray, k: int, n: int) -> FloatArray:
    return np.array([t[i + 1:i + k + 1].mean() if k > 0 else t[i] for i in range(n)])


# ---- planning --------------------------------------------------------------------------
def plan_trajectory(
    roadmap: Roadmap,
    corridor: Corridor,
    obstacles: Obstacles,
    params: TrajectoryParams | None = None,
    start_heading: float | None = None,
    *,
    start_speed: float = 0.0,
    end_speed: float | None = None,
) -> Trajectory:
    """Speed-optimised B-spline trajectory along a roadmap.

    Parameters
    ----------
    roadmap
        Level 2's result; its vertices are the control points and its parameters give the
        vehicle's size and safety margin.
    corridor, obstacles
        The road segment and the obstacles the roadmap was planned among (the real ones:
        the footprint is checked against them with the safety margin).
    params
        Level-3 parameters (defaults if ``None``).
    start_heading
        Vehicle heading [rad] at ``roadmap.start_xy``; ``None`` starts towards the first
        control point after the lead-in.
    start_speed
        Speed [m/s] at the start.
    end_speed
        Speed [m/s] at the end: 0 stops there, ``None`` keeps going as fast as allowed.

    Raises
    ------
    TrajectoryError
        Fewer than two distinct roadmap points, or a start off the road.
    """
    params = params or TrajectoryParams()
    rp = roadmap.params
    if not (np.isfinite(start_speed) and start_speed >= 0):
        raise TrajectoryError(f"start speed must be >= 0, got {start_speed!r}")
    pool, counts = _control_points(roadmap, corridor, start_heading, params, start_speed)
    checker = _Checker.build(corridor, obstacles, rp, pool)
    curve, refinements, doubled = _refine(pool, counts, checker, params)
    opt = _Optimiser(curve, checker, params)
    kappa_before = opt.kappa.copy()
    stats = opt.run()
    stats = IterationStats(stats.tried, stats.accepted, stats.refused, stats.rounds,
                           refinements, len(curve.ctrl), doubled)
    final = opt.ctrl
    spline = BSpline(curve.knots, final, curve.k)
    traj = _sample(spline, curve, opt, checker, params, rp, start_speed, end_speed)
    v_before = allowed_speed(kappa_before, mu=params.mu, g=params.g, s_max=params.s_max)
    return Trajectory(
        traj["t"], traj["x"], traj["y"], traj["heading"], traj["speed"], traj["curvature"],
        traj["s"], final, spline, traj["clear_obs"], traj["clear_road"],
        bool(traj["feasible"]), stats, float(v_before.min()),
        float(allowed_speed(opt.kappa, mu=params.mu, g=params.g, s_max=params.s_max).min()),
        rp.safety_margin)


def _control_points(roadmap: Roadmap, corridor: Corridor, start_heading: float | None,
                    params: TrajectoryParams, start_speed: float
                    ) -> tuple[FloatArray, NDArray[np.int64]]:
    """Candidate control points ``(c, 2)`` and how often the first curve uses each (0 or 1).

    The candidates are the vehicle's position, a heading point ahead of it and the roadmap
    vertices beyond the heading point. The first curve uses the first two, the last, and the
    vertices that band simplification (:func:`band_simplify`) keeps, beginning at the
    farthest vertex that the vehicle's position reaches within the bands (at least the
    lead-in distance ahead).
    """
    rp = roadmap.params
    raw = np.asarray(roadmap.xy, dtype=float)
    if raw.ndim != 2 or raw.shape[1] != 2 or len(raw) < 2:
        raise TrajectoryError(f"a trajectory needs at least 2 roadmap points, got {len(raw)}")
    distinct = np.concatenate(([True], np.hypot(*np.diff(raw, axis=0).T) > 1e-6))
    pts = raw[distinct]
    if len(pts) < 2:
        raise TrajectoryError(f"a trajectory needs at least 2 roadmap points, got {len(pts)}")
    start = np.asarray(roadmap.start_xy, dtype=float).reshape(2)
    sl = corridor.to_sl(np.vstack((start, pts)))
    if not corridor.contains(start[None])[0]:
        raise TrajectoryError(
            f"start ({start[0]:.2f}, {start[1]:.2f}) is off the road "
            f"(station {corridor.offset + sl[0, 0]:.1f} m, lateral offset {sl[0, 1]:.2f} m)")
    if start_heading is not None and not np.isfinite(start_heading):
        raise TrajectoryError(f"start heading must be finite, got {start_heading!r}")
    s0, vs = float(sl[0, 0]), sl[1:, 0]
    reach = float(vs[-1] - s0)
    if reach <= 1e-6:
        raise TrajectoryError("the roadmap ends at or behind the vehicle: no curve to follow")
    lines = _vertex_lines(roadmap, corridor, distinct, sl[1:], params.band_fraction)
    lead = max(params.lead_in_lengths * rp.vehicle_length, params.lead_in_time * start_speed)
    lead = min(lead, 0.5 * reach)
    head_len = max(min(lead / 2.0, reach / 3.0), 1e-3)
    ahead = vs > s0 + head_len + rp.d / 2.0
    ahead[-1] = True
    verts = pts[ahead]
    lines = tuple(a[ahead] for a in lines)  # type: ignore[assignment]
    stations = polyline_stations(verts)
    first = int(np.searchsorted(vs[ahead], s0 + lead - 1e-9))
    first = min(first, len(verts) - 1)
    # from the vehicle's position as far as the bands allow (within the spacing cap)
    cap = int(np.searchsorted(stations, params.max_control_spacing
                              - float(np.hypot(*(verts[0] - start))), side="right")) - 1
    if cap >= 0:
        first = max(first, _farthest(start, -1, cap, verts, *lines))
    keep_v = np.zeros(len(verts), dtype=np.int64)
    keep_v[first + band_simplify(verts[first:], *(a[first:] for a in lines),
                                 max_spacing=params.max_control_spacing)] = 1
    if start_heading is None:
        direction = verts[first] - start
    else:
        direction = np.array([np.cos(start_heading), np.sin(start_heading)])
    norm = float(np.hypot(*direction))
    if norm <= 1e-12:
        raise TrajectoryError("the roadmap's points coincide with the start: no curve")
    heading_point = start + head_len * direction / norm
    pool = np.vstack((start, heading_point, verts))
    counts = np.concatenate(([1, 1], keep_v)).astype(np.int64)
    return pool, counts


def _vertex_lines(roadmap: Roadmap, corridor: Corridor, distinct: NDArray[np.bool_],
                  sl: FloatArray, band_fraction: float
                  ) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray, FloatArray]:
    """Each roadmap vertex's sweep line and band: origin ``(m, 2)`` (lateral offset 0),
    tangent ``(m, 2)``, normal ``(m, 2)``, band centre ``(m,)`` [m] and half width ``(m,)`` [m].

    The band is ``band_fraction`` of the vertex's free interval, centred on its midpoint
    (the vertex). Without free intervals (a roadmap without its graph) the bands are empty.
    """
    s = sl[:, 0]
    h = corridor.heading_at(s)
    tangent = np.column_stack((np.cos(h), np.sin(h)))
    normal = np.column_stack((-tangent[:, 1], tangent[:, 0]))
    origin = corridor.to_xy(s, np.zeros_like(s))
    path = np.asarray(roadmap.path)
    if len(path) == len(distinct) and len(roadmap.graph_lo) and len(roadmap.graph_hi):
        lo = np.asarray(roadmap.graph_lo, dtype=float)[path][distinct]
        hi = np.asarray(roadmap.graph_hi, dtype=float)[path][distinct]
        half = band_fraction * np.maximum(hi - lo, 0.0) / 2.0
    else:
        half = np.zeros(len(s))
    return origin, tangent, normal, sl[:, 1], half


def band_simplify(points: ArrayLike, origin: ArrayLike, tangent: ArrayLike, normal: ArrayLike,
                  centre: ArrayLike, half: ArrayLike, *, max_spacing: float = np.inf
                  ) -> NDArray[np.int64]:
    """Vertices kept by greedy string pulling through lateral bands.

    Vertex ``k`` of the polyline ``points`` ``(m, 2)`` [m] stands on a line through
    ``origin[k]`` ``(m, 2)`` along ``normal[k]`` ``(m, 2)`` (unit; ``tangent[k]`` is the unit
    direction across it, along the road). Its band is the part of that line at lateral
    offsets ``centre[k] +- half[k]`` [m]. From the last kept vertex ``i``, the next kept
    vertex is the farthest ``j`` such that every segment ``i -> j'`` with ``j' <= j`` crosses
    every line ``k`` with ``i < k < j'`` inside its band, and the polyline from ``i`` to ``j``
    is at most ``max_spacing`` [m] long (always at least ``i + 1``). With ``half = 0`` only
    collinear vertices go.

    Returns
    -------
    Increasing indices, with the first and the last vertex.
    """
    pts = np.asarray(points, dtype=float)
    arrays = tuple(np.asarray(a, dtype=float) for a in (origin, tangent, normal, centre, half))
    m = len(pts)
    if m <= 2:
        return np.arange(m, dtype=np.int64)
    stations = polyline_stations(pts)
    kept = [0]
    i = 0
    while i < m - 1:
        cap = int(np.searchsorted(stations, stations[i] + max_spacing + 1e-9, side="right")) - 1
        cap = min(max(cap, i + 1), m - 1)
        i = _farthest(pts[i], i, cap, pts, *arrays)
        kept.append(i)
    return np.asarray(kept, dtype=np.int64)


def _farthest(p: FloatArray, i: int, cap: int, pts: FloatArray, origin: FloatArray,
              tangent: FloatArray, normal: FloatArray, centre: FloatArray, half: FloatArray,
              tol: float = 1e-7) -> int:
    """Largest ``j`` in ``(i, cap]`` (at least ``i + 1``) such that every segment
    ``p -> pts[j']``, ``i < j' <= j``, crosses the lines ``i < k < j'`` inside their bands."""
    if cap <= i + 1:
        return min(i + 1, len(pts) - 1)
    js = np.arange(i + 2, cap + 1)
    ks = np.arange(i + 1, cap)
    d = pts[js] - p  # (J, 2)
    tk, nk, ok_ = tangent[ks], normal[ks], origin[ks]
    num = np.einsum("kd,kd->k", ok_ - p, tk)
    den = d @ tk.T  # (J, K)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = num[None, :] / den
    # lateral offset of the crossing: (p + t d - origin) . normal
    lat = (np.einsum("kd,kd->k", p - ok_, nk)[None, :] + t * (d @ nk.T))
    inside = ((t >= -tol) & (t <= 1.0 + tol)
              & (np.abs(lat - centre[ks][None, :]) <= half[ks][None, :] + tol))
    inside |= ks[None, :] >= js[:, None]  # only the lines before j count
    good = inside.all(axis=1)
    if good.all():
        return cap
    return int(i + 1 + np.argmin(good))


@dataclass(frozen=True, eq=False)
class _Curve:
    """A clamped B-spline on fixed parameter samples, with its basis there.

    ``first[j]`` is the first of the ``k + 1`` control points that shape sample ``j``;
    ``basis[nu, j]`` their values (nu = 0) and parameter derivatives (nu = 1, 2) there.
    ``pool_index`` maps each control point to its index among the candidates.
    """

    ctrl: FloatArray
    pool_index: NDArray[np.int64]
    knots: FloatArray
    k: int
    u: FloatArray
    first: NDArray[np.int64]
    basis: FloatArray

    @classmethod
    def build(cls, ctrl: FloatArray, pool_index: NDArray[np.int64], degree: int,
              spacing: float) -> _Curve:
        n = len(ctrl)
        k = min(degree, n - 1)
        knots = _knots(n, k)
        # samples per knot span from the longest nearby leg: moves to neighbours' means never
        # lengthen a leg beyond the longest of its neighbours
        legs = np.hypot(*np.diff(ctrl, axis=0).T)
        padded = np.concatenate(([legs[0]], legs, [legs[-1]]))
        span_len = np.array([padded[j:j + k + 2].max() for j in range(n - k)])
        per = np.clip(np.ceil(span_len / spacing).astype(int) + 1, 2, 400)
        inner = knots[k:n + 1]
        u = np.concatenate([np.linspace(inner[j], inner[j + 1], per[j], endpoint=False)
                            for j in range(n - k)] + [np.array([1.0])])
        first, basis = _basis(u, knots, k, n)
        return cls(ctrl, pool_index, knots, k, u, first, basis)

    def evaluate(self, ctrl: FloatArray | None = None) -> tuple[FloatArray, FloatArray,
                                                                  FloatArray]:
        """Positions, first and second parameter derivatives ``(m, 2)`` at the samples."""
        c = self.ctrl if ctrl is None else ctrl
        cols = self.first[:, None] + np.arange(self.k + 1)[None, :]
        gathered = c[cols]
        return tuple(np.einsum("mk,mkd->md", self.basis[nu], gathered)  # type: ignore
                     for nu in range(3))


def _refine(pool: FloatArray, counts: NDArray[np.int64], checker: _Checker,
            params: TrajectoryParams) -> tuple[_Curve, int, int]:
    """The first curve, repaired locally where its footprint is not clear.

    For each sample where the footprint touches an obstacle (with the margin) or leaves the
    road, the left-out candidate nearest to it, among those between the control points that
    shape it, comes back; where none is left there, the shaping control point nearest to
    the sample is doubled (up to ``degree`` copies: repeated control points pull the curve
    onto its control polygon, undoing the corner cut). At most ``repair_rounds`` rounds.
    Curvature above the turning limit is left to the optimisation.

    Returns the curve, the rounds and the number of control points doubled.
    """
    counts = counts.copy()
    rounds = doubled = 0
    n_pool = len(pool)
    while True:
        pool_idx = np.repeat(np.arange(n_pool), counts)
        curve = _Curve.build(pool[pool_idx], pool_idx, params.degree, params.sample_spacing)
        if rounds >= params.repair_rounds:
            return curve, rounds, doubled
        pos, d1, _ = curve.evaluate()
        slack = checker.slack(pos, np.arctan2(d1[:, 1], d1[:, 0]))
        bad = np.flatnonzero(slack < 0)
        if len(bad) == 0:
            return curve, rounds, doubled
        k = curve.k
        n = len(pool_idx)
        add = np.zeros(n_pool, dtype=bool)
        dup = np.zeros(n_pool, dtype=bool)
        for j in bad.tolist():
            f = int(curve.first[j])
            shaping = np.arange(f, min(f + k, n - 1) + 1)
            a, b = int(pool_idx[shaping[0]]), int(pool_idx[shaping[-1]])
            free = np.flatnonzero(counts[a + 1:b] == 0) + a + 1
            if len(free):
                add[free[np.argmin(np.hypot(*(pool[free] - pos[j]).T))]] = True
                continue
            inner = pool_idx[shaping]
            inner = inner[(inner >= 2) & (inner < n_pool - 1) & (counts[inner] < k)]
            if len(inner):
                dup[inner[np.argmin(np.hypot(*(pool[inner] - pos[j]).T))]] = True
        if not (add.any() or dup.any()):
            return curve, rounds, doubled
        counts[add] = 1
        dup &= ~add
        counts[dup] += 1
        doubled += int(dup.sum())
        rounds += 1


class _Optimiser:
    """Equation (3) on fixed parameter samples, with local re-evaluation."""

    def __init__(self, curve: _Curve, checker: _Checker, params: TrajectoryParams) -> None:
        self.ctrl = curve.ctrl.copy()
        first, k, u, knots = curve.first, curve.k, curve.u, curve.knots
        self.first, self.basis, self.k = first, curve.basis, k
        self.checker, self.params = checker, params
        n = len(self.ctrl)
        self.n = n
        cols = first[:, None] + np.arange(k + 1)[None, :]
        self.pos, self.d1, self.d2 = curve.evaluate(self.ctrl)
        self.kappa = np.abs(curvature_from_derivatives(self.d1, self.d2))
        head = np.arctan2(self.d1[:, 1], self.d1[:, 0])
        self.slack = checker.slack(self.pos, head)
        # samples a move of control point i changes: [lo[i], hi[i])
        idx = np.arange(n)
        self.lo = np.searchsorted(first, idx - k, side="left")
        self.hi = np.searchsorted(first, idx, side="right")
        # for each sample, the shaping control points ordered by Greville distance
        grev = _greville(knots, k, n)
        order = np.argsort(np.abs(grev[cols] - u[:, None]), axis=1, kind="stable")
        self.cand = np.take_along_axis(cols, order, axis=1)
        self.movable = np.ones(n, dtype=bool)
        self.movable[:2] = False  # the start and its heading point
        self.movable[-1] = False
        self.refused = np.zeros(n, dtype=bool)

    def _state(self) -> tuple[FloatArray, ...]:
        return tuple(a.copy() for a in (self.ctrl, self.pos, self.d1, self.d2, self.kappa,
                                        self.slack))

    def _restore(self, state: tuple[FloatArray, ...]) -> None:
        self.ctrl, self.pos, self.d1, self.d2, self.kappa, self.slack = state

    def run(self) -> IterationStats:
        p = self.params
        k, n = self.k, self.n
        tried = accepted = refused = rounds = 0
        best = (float(self.kappa.max()), self._state())
        while tried < p.max_iterations:
            slow = self.kappa > p.kappa_smax * (1.0 + 1e-9)
            if not slow.any():
                break
            c = self.ctrl
            at_mean = np.zeros(n, dtype=bool)
            at_mean[1:-1] = np.hypot(*(c[1:-1] - 0.5 * (c[:-2] + c[2:])).T) < 1e-9
            eligible = self.movable & ~self.refused & ~at_mean
            js = np.nonzero(slow)[0]
            ok = eligible[self.cand[js]]
            has = ok.any(axis=1)
            if not has.any():
                break
            js = js[has]
            cp = self.cand[js, np.argmax(ok[has], axis=1)]
            bad = np.zeros(n)
            np.maximum.at(bad, cp, self.kappa[js])
            chosen = _independent(bad, k, p.max_iterations - tried)
            rounds += 1
            tried += len(chosen)
            acc = self._try(np.asarray(chosen, dtype=np.int64))
            accepted += int(acc.sum())
            refused += int((~acc).sum())
            worst = float(self.kappa.max())
            if worst < best[0] - 1e-12 and acc.any():
                best = (worst, self._state())
        if float(self.kappa.max()) > best[0] + 1e-12:
            self._restore(best[1])
        log.debug("optimisation: %d rounds, %d tried, %d accepted", rounds, tried, accepted)
        return IterationStats(tried, accepted, refused, rounds)

    def _try(self, moves: NDArray[np.int64]) -> NDArray[np.bool_]:
        """Try moving each control point in ``moves`` to its neighbours' mean."""
        k, p = self.k, self.params
        delta = 0.5 * (self.ctrl[moves - 1] + self.ctrl[moves + 1]) - self.ctrl[moves]
        lens = self.hi[moves] - self.lo[moves]
        owner = np.repeat(np.arange(len(moves)), lens)
        idx = np.concatenate([np.arange(a, b) for a, b in zip(self.lo[moves], self.hi[moves],
                                                                strict=True)])
        r = moves[owner] - self.first[idx]  # column of the moved point in each sample's row
        dlt = delta[owner]
        pos = self.pos[idx] + self.basis[0, idx, r][:, None] * dlt
        d1 = self.d1[idx] + self.basis[1, idx, r][:, None] * dlt
        d2 = self.d2[idx] + self.basis[2, idx, r][:, None] * dlt
        kap = np.abs(curvature_from_derivatives(d1, d2))
        slack = self.checker.slack(pos, np.arctan2(d1[:, 1], d1[:, 0]))
        old_k, old_s = self.kappa[idx], self.slack[idx]
        # per sample: samples clear of obstacles and road edges stay clear
        bad = (old_s >= 0) & (slack < 0)
        # per move: the worst violation of the changed stretch (curvature beyond the turning
        # limit, footprint within the margin) does not grow
        nm = len(moves)
        worse = np.zeros(nm, dtype=bool)
        np.logical_or.at(worse, owner, bad)
        limits = ((kap, old_k, p.kappa_max), (-slack, -old_s, 0.0))
        for new, old, lim in limits:
            mx_new = np.full(nm, -np.inf)
            mx_old = np.full(nm, -np.inf)
            np.maximum.at(mx_new, owner, new)
            np.maximum.at(mx_old, owner, old)
            worse |= mx_new > np.maximum(mx_old, lim) + 1e-12
        acc = ~worse
        keep = acc[owner]
        ki = idx[keep]
        self.pos[ki], self.d1[ki], self.d2[ki] = pos[keep], d1[keep], d2[keep]
        self.kappa[ki], self.slack[ki] = kap[keep], slack[keep]
        self.ctrl[moves[acc]] += delta[acc]
        self.refused[moves[~acc]] = True
        for i in moves[acc]:
            self.refused[max(i - k, 0):i + k + 1] = False
        return acc


def _independent(bad: FloatArray, k: int, budget: int) -> list[int]:
    """Control points to move this round: the worst first, then others ``k + 1`` apart."""
    order = np.argsort(-bad, kind="stable")
    order = order[bad[order] > 0]
    taken = np.zeros(len(bad) + 2 * k + 2, dtype=bool)
    chosen: list[int] = []
    for i in order.tolist():
        if len(chosen) >= budget:
            break
        if taken[i: i + 2 * k + 1].any():
            continue
        taken[i + k] = True  # offset by k so that i - k >= 0
        chosen.append(i)
    return chosen


def _sample(spline: BSpline, curve: _Curve, opt: _Optimiser, checker: _Checker,
            params: TrajectoryParams, rp: RoadmapParams, start_speed: float,
            end_speed: float | None) -> dict[str, FloatArray]:
    """Samples evenly spaced in arc length, with speeds, times and clearances."""
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
    limit = allowed_speed(kappa, mu=params.mu, g=params.g, s_max=params.s_max)
    speed = speed_profile(s, limit, a_max=params.a_max, b_max=params.b_max,
                          start_speed=start_speed, end_speed=end_speed)
    clear_obs = checker.obstacles(pos, head)
    clear_road = checker.road(pos, head)
    feasible = (np.all(clear_obs >= rp.safety_margin - 1e-6)
                and np.all(clear_road >= rp.safety_margin - 1e-6)
                and np.all(np.abs(kappa) <= params.kappa_max * (1 + 1e-6))
                and np.all(opt.slack >= -1e-6)
                and np.all(opt.kappa <= params.kappa_max * (1 + 1e-6)))
    return {"t": _times(s, speed), "x": pos[:, 0], "y": pos[:, 1], "heading": head,
            "speed": speed, "curvature": kappa, "s": s, "clear_obs": clear_obs,
            "clear_road": clear_road, "feasible": np.asarray(feasible)}


def _times(s: FloatArray, v: FloatArray) -> FloatArray:
    """Times [s]; a step between two zero speeds (a cusp) never ends: ``inf`` from there."""
    stuck = (v[:-1] + v[1:] <= 0) & (np.diff(s) > 0)
    if not stuck.any():
        return times_from_profile(s, v)
    j = int(np.argmax(stuck))
    out = np.full(len(s), np.inf)
    out[:j + 1] = times_from_profile(s[:j + 1], v[:j + 1])
    return out
