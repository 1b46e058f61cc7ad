"""Level 3: a B-spline through the roadmap, smoothed for speed, with a speed profile.

(Kala & Warwick, section IV, read as in ALGORITHM.md.) The control points of a clamped
B-spline are roadmap vertices, after the vehicle's position and a heading point just ahead of
it along its heading. While some point of the curve allows less than ``s_max`` (equation 1),
the control point nearest the slowest point moves to its neighbours' mean (equation 3); a
move is kept only if the vehicle's footprint along the changed part of the curve stays on
the road and clear of the obstacles by the safety margin, and the curvature stays within
the turning limit.

Steps, and the choices beyond the paper:

1. Band simplification picks the control points. Each chosen roadmap vertex ``k`` stands
   on its sweep line at the midpoint ``l_k`` of its free interval ``[lo_k, hi_k]``; its band
   is ``l_k +- rho (hi_k - lo_k) / 2`` (``band_fraction`` rho). Greedy string pulling keeps,
   from the last kept vertex, the farthest vertex such that the straight segments to it
   cross every skipped sweep line inside its band (:func:`band_simplify`): the control
   polygon keeps at least ``1 - rho`` of each interval's separation, so the paper's
   separation is only partly traded for fewer, straighter legs. rho = 0 only drops
   collinear vertices. Legs longer than ``max_control_spacing`` get extra control points on
   them, so that equation (3) has points to move on long straights.
2. Lead-in: the first roadmap vertex used is the farthest that the vehicle's position
   reaches within the bands (within ``max_control_spacing``), and at least the lead-in
   distance ahead.
3. Repair: a clamped B-spline cuts its polygon's corners (by about
   ``|P_{i-1} - 2 P_i + P_{i+1}| / 6`` for a cubic). Where the first curve's footprint is not
   clear, the left-out roadmap vertex nearest the violation comes back; where none is left,
   the control point nearest it is doubled (repeated control points pull the curve onto
   the polygon); a few rounds, and the least violating curve is kept.
4. Equation (3). "Nearest" control point: nearest in parameter, by Greville abscissa, among
   the ``degree + 1`` control points that shape the curve at that point; if it may not
   move, the next nearest of those. Moves whose supports do not overlap commute, so each
   round makes the move of the slowest point and the moves of the slowest points of other
   independent stretches. A move changes the samples linearly (cached basis: new = old +
   basis column * delta), so only the changed stretch is re-evaluated and re-checked.
5. Feasibility: the footprint is the vehicle's rectangle centred on the curve and oriented
   along it; its distance to each nearby obstacle polygon is exact (culled by bounding
   box); on the road its corners and long-side midpoints keep the margin from the road
   edges (the corridor is extended past its ends). Curvature above ``1 / min_turn_radius``
   is infeasible. A curve that starts infeasible is not refused outright: a move is then
   kept if no feasible sample becomes infeasible and the worst violation of the changed
   part does not grow (exactly "the new curve is feasible" when the start is feasible).
   The result reports ``feasible`` honestly.
6. Single moves can sharpen a bend for a while, so the curve returned is the one with the
   highest minimum allowed speed seen after any round: it never decreases.
7. Speed profile (:mod:`splineplan.speed`) along the final curve, sampled evenly in arc length.
8. Detour: where the curve along level 2's path ends infeasible (the widest path can cross
   lanes faster than any curve within the turning limit), the same graph is searched for
   a path of limited lateral rate (:func:`detour_roadmap`) and steps 1-7 run along it; its
   curve is kept if it is feasible.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field, replace

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.interpolate import BSpline
from scipy.ndimage import maximum_filter1d, minimum_filter1d

from splineplan.corridor import Corridor
from splineplan.errors import ParameterError, TrajectoryError
from splineplan.geometry import (
    FloatArray,
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
    patience
        The optimisation also stops after this many rounds in a row that did not raise the
        curve's minimum allowed speed (its objective): the slowest point is then held by a
        bound (road edge, obstacle, turning limit) that the remaining moves cannot change.
        Without it, routes through junction turns spent hundreds of rounds on moves that
        were all refused or undone.
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
    band_reserve
        Room [m] that each band leaves to its free interval's ends on each side.
    detour_rate
        Largest lateral change [m per m of station] of the detour path
        (:func:`detour_roadmap`) tried when the curve along level 2's path is not
        feasible; 0: no detour.
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
    band_fraction: float = 0.8
    max_control_spacing: float = 25.0
    repair_rounds: int = 6
    lead_in_lengths: float = 2.0
    lead_in_time: float = 1.5
    band_reserve: float = 0.15
    patience: int = 12
    detour_rate: float = 0.4

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
        for name in ("lead_in_lengths", "lead_in_time", "band_reserve", "detour_rate"):
            value = getattr(self, name)
            if not (isinstance(value, int | float | np.floating | np.integer)
                    and np.isfinite(value) and value >= 0):
                raise ParameterError(f"TrajectoryParams.{name} must be >= 0 and finite, "
                                     f"got {value!r}")
        for name in ("max_iterations", "repair_rounds", "patience"):
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
    """Footprint clearance of the vehicle at curve samples, vectorised.

    The road check works in the frames of the reference line's segments (cached once:
    origins, stations, unit directions, boundary offsets); it needs an estimate of each
    centre's station, which the optimiser keeps per sample, so that no nearest-neighbour
    search runs per move.
    """

    corridor: Corridor
    half_length: float
    half_width: float
    margin: float
    polys: FloatArray  # (2, V, K): x and y of each polygon's vertices, padded with its last
    bbox: FloatArray  # (K, 4)
    body: FloatArray = field(init=False)  # (2, q) body-frame points: footprint, then centre
    frames: tuple[FloatArray, ...] = field(init=False)
    window: tuple[FloatArray, ...] = field(init=False)

    def __post_init__(self) -> None:
        hl, hw = self.half_length, self.half_width
        pts = np.array([[-hl, -hw], [hl, -hw], [hl, hw], [-hl, hw], [0.0, -hw], [0.0, hw],
                        [0.0, 0.0]])
        object.__setattr__(self, "body", np.ascontiguousarray(pts.T))
        cor = self.corridor
        st = np.asarray(cor.s, dtype=float)
        h = cor.heading_at(st[:-1])
        ref = np.asarray(cor.reference, dtype=float)
        left, right = np.asarray(cor.left, dtype=float), np.asarray(cor.right, dtype=float)
        object.__setattr__(self, "frames", (
            st, ref[:-1, 0].copy(), ref[:-1, 1].copy(), np.cos(h), np.sin(h), left, right))
        # per segment, over the stations the footprint can reach from it: the narrowest
        # boundaries and the largest turn of the reference line (for a quick clear test),
        # and the segment's own heading [rad]
        ds = np.diff(st)
        w = int(np.ceil((np.hypot(hl, hw) + 1.0) / max(float(np.quantile(ds, 0.1)), 1e-3)))
        size = min(2 * w + 1, 2 * len(ds) + 1)
        lmin = minimum_filter1d(left, size, mode="nearest")[:-1]
        rmax = maximum_filter1d(right, size, mode="nearest")[:-1]
        hh = np.unwrap(h)
        turn = (maximum_filter1d(hh, size, mode="nearest")
                - minimum_filter1d(hh, size, mode="nearest"))
        seg_heading = np.arctan2(self.frames[4], self.frames[3])
        object.__setattr__(self, "window", (lmin, rmax, turn, seg_heading))

    @classmethod
    def build(cls, corridor: Corridor, obstacles: Obstacles, params: RoadmapParams,
              near_xy: FloatArray) -> _Checker:
        reach = np.hypot(params.vehicle_length, params.vehicle_width) / 2.0
        radius = reach + params.safety_margin + CLEARANCE_HORIZON + 5.0
        # the obstacles whose bounding box comes within the radius of the points' extent
        lo, hi = near_xy.min(axis=0) - radius, near_xy.max(axis=0) + radius
        b = obstacles.bbox
        sel = np.flatnonzero((b[:, 0] <= hi[0]) & (b[:, 2] >= lo[0]) & (b[:, 1] <= hi[1])
                             & (b[:, 3] >= lo[1]))
        start = obstacles.offsets[sel]
        count = obstacles.offsets[sel + 1] - start
        vmax = int(count.max()) if len(sel) else 3
        idx = start[None, :] + np.minimum(np.arange(vmax)[:, None], count[None, :] - 1)
        polys = np.moveaxis(obstacles.vertices[idx], 2, 0)  # (V, K, 2) -> (2, V, K)
        return cls(corridor, params.vehicle_length / 2.0, params.vehicle_width / 2.0,
                   params.safety_margin, np.ascontiguousarray(polys), b[sel])

    def stations(self, xy: FloatArray) -> FloatArray:
        """Stations [m] of points ``(n, 2)`` on the reference line (exact projection)."""
        return np.asarray(self.corridor.to_sl(xy)[:, 0])

    def road(self, xy: FloatArray, heading: FloatArray, sc: FloatArray | None = None
             ) -> tuple[FloatArray, FloatArray]:
        """Distance [m] of the footprint to the nearer road edge (negative: off the road),
        and the centres' stations [m].

        ``sc`` estimates the centres' stations (``None``: projected exactly). All footprint
        points are projected onto the line of the reference segment at that estimate, then
        measured in the frame of the segment at their own station (the reference is
        resampled finely, so one segment's frame is exact enough; past the ends, the end
        segments extend the road).
        """
        st, rx, ry, hc, hs, left, right = self.frames
        if sc is None:
            sc = self.stations(xy)
        inner = st[1:-1]
        # footprint points (7, n): samples along the last axis, so that numpy's loops are long
        bx, by = self.body[0, :, None], self.body[1, :, None]
        c, s = np.cos(heading), np.sin(heading)
        px = (xy[:, 0] + c * bx) - s * by
        py = (xy[:, 1] + s * bx) + c * by
        # segment at each station, the end segments beyond the ends: searching the inner
        # stations gives it in 0 .. len(st) - 2 directly
        i0 = np.searchsorted(inner, sc, side="right")
        est = st[i0] + ((px - rx[i0]) * hc[i0] + (py - ry[i0]) * hs[i0])
        i = np.searchsorted(inner, est, side="right")
        dx, dy = px - rx[i], py - ry[i]
        ci, si = hc[i], hs[i]
        along = st[i] + dx * ci + dy * si
        lat = dy * ci - dx * si
        f = along[:-1]
        clear = np.minimum(np.interp(f, st, left) - lat[:-1],
                           lat[:-1] - np.interp(f, st, right)).min(axis=0)
        return clear, along[-1]

    def slack(self, xy: FloatArray, heading: FloatArray, sc: FloatArray | None = None
              ) -> tuple[FloatArray, FloatArray]:
        """Footprint clearance [m] beyond the safety margin (negative: too close), and the
        centres' stations [m] (see :meth:`road`)."""
        if sc is None:
            sc = self.stations(xy)
        # the centres in the frame of the reference segment at their station (from the
        # estimate, one step of refinement)
        st, rx, ry, hc, hs, _, _ = self.frames
        lmin, rmax, turn, seg_heading = self.window
        sc_new = sc
        for _ in range(2):
            i = np.searchsorted(st[1:-1], sc_new, side="right")  # as in :meth:`road`
            dx, dy = xy[:, 0] - rx[i], xy[:, 1] - ry[i]
            ci, si = hc[i], hs[i]
            sc_new = st[i] + dx * ci + dy * si
        lat = dy * ci - dx * si
        # clearly on the road (a lower bound of the clearance is above the margin): no
        # exact check of the footprint
        dh = heading - seg_heading[i]
        ext = (self.half_length * np.abs(np.sin(dh)) + self.half_width * np.abs(np.cos(dh))
               + (np.abs(lat) + self.half_length + self.half_width) * turn[i] + 0.05)
        road = np.minimum(lmin[i] - lat, lat - rmax[i]) - ext
        near_edge = np.flatnonzero(road < self.margin + 1e-6)
        if len(near_edge):
            road[near_edge], sc_new[near_edge] = self.road(
                xy[near_edge], heading[near_edge], sc[near_edge])
        near = self.obstacles(xy, heading, horizon=0.0, cull=True)
        return np.minimum(near, road) - self.margin, sc_new

    def obstacles(self, xy: FloatArray, heading: FloatArray,
                  horizon: float = CLEARANCE_HORIZON, cull: bool = False) -> FloatArray:
        """Distance [m] of the footprint to the nearest obstacle, ``inf`` beyond
        ``margin + horizon`` (obstacles are culled by bounding box; with ``cull``, also
        those separated by more than that along the footprint's axes, so that ``inf``
        may stand for any distance beyond ``margin + horizon``)."""
        out = np.full(len(xy), np.inf)
        if len(self.bbox) == 0 or len(xy) == 0:
            return out
        r = np.hypot(self.half_length, self.half_width) + self.margin + horizon
        b = self.bbox
        lo, hi = xy.min(axis=0) - r, xy.max(axis=0) + r
        near = np.flatnonzero((b[:, 0] <= hi[0]) & (b[:, 2] >= lo[0]) & (b[:, 1] <= hi[1])
                              & (b[:, 3] >= lo[1]))
        if len(near) == 0:
            return out
        b = b[near]
        x, y = xy[:, 0, None], xy[:, 1, None]
        hit = (b[:, 0] <= x + r) & (b[:, 2] >= x - r) & (b[:, 1] <= y + r) & (b[:, 3] >= y - r)
        js, os = np.nonzero(hit)
        os = near[os]
        if len(js) == 0:
            return out
        u, v = _body_frame(xy[js], heading[js], np.take(self.polys, os, axis=2))
        if cull:
            gap = self.margin + horizon
            keep = ((u.min(axis=0) < self.half_length + gap)
                    & (u.max(axis=0) > -self.half_length - gap)
                    & (v.min(axis=0) < self.half_width + gap)
                    & (v.max(axis=0) > -self.half_width - gap))
            js, u, v = js[keep], u[:, keep], v[:, keep]
            if len(js) == 0:
                return out
        d = _rect_polygon_distance(u, v, self.half_length, self.half_width)
        # js is sorted (np.nonzero is row-major): the minimum over each run
        run = np.flatnonzero(np.concatenate(([True], js[1:] != js[:-1])))
        out[js[run]] = np.minimum.reduceat(d, run)
        return out


def _body_frame(centers: FloatArray, headings: FloatArray, polys: FloatArray
                ) -> tuple[FloatArray, FloatArray]:
    """Vertices of polygons ``(2, V, p)`` (x and y) in the frames of poses ``(p, 2)``,
    ``(p,)``: ``u`` [m] along the heading and ``v`` [m] to its left, each ``(V, p)``."""
    c, s = np.cos(headings), np.sin(headings)
    rx = polys[0] - centers[:, 0]
    ry = polys[1] - centers[:, 1]
    return rx * c + ry * s, ry * c - rx * s


def _rect_polygon_distance(u: FloatArray, v: FloatArray, hl: float, hw: float) -> FloatArray:
    """Distance ``(p,)`` [m] between the rectangle ``|u| <= hl``, ``|v| <= hw`` and polygons
    given by their vertices ``(V, p)`` in its frame (:func:`_body_frame`), 0 on overlap.

    Polygons run along the last axis (long rows, so that numpy's loops are long).
    """
    # squared distances: polygon vertices to the filled rectangle
    gu = np.maximum(np.abs(u) - hl, 0.0)
    gv = np.maximum(np.abs(v) - hw, 0.0)
    out = (gu * gu + gv * gv).min(axis=0)
    ub = np.concatenate((u[1:], u[:1]))  # the next vertex
    vb = np.concatenate((v[1:], v[:1]))
    du, dv = ub - u, vb - v
    seg2 = du * du + dv * dv
    inv = 1.0 / np.where(seg2 > 0, seg2, 1.0)
    # rectangle corners to polygon edges (a loop: arrays for all corners at once are
    # slower, out of cache)
    for cu, cv in ((-hl, -hw), (hl, -hw), (hl, hw), (-hl, hw)):
        wu, wv = cu - u, cv - v
        t = wu * du
        t += wv * dv
        t *= inv
        np.maximum(t, 0.0, out=t)
        np.minimum(t, 1.0, out=t)
        gu = t * du
        gu -= wu
        t *= dv
        t -= wv
        gu *= gu
        t *= t
        gu += t
        np.minimum(out, gu.min(axis=0), out=out)
    np.sqrt(out, out=out)
    # overlap needs the polygon's extent to meet the rectangle: only there do the
    # crossing and containment tests run
    meet = np.flatnonzero((u.min(axis=0) <= hl) & (u.max(axis=0) >= -hl)
                          & (v.min(axis=0) <= hw) & (v.max(axis=0) >= -hw))
    if len(meet):
        out[meet[_overlap(u[:, meet], v[:, meet], ub[:, meet], vb[:, meet], hl, hw)]] = 0.0
    return out


def _overlap(u: FloatArray, v: FloatArray, ub: FloatArray, vb: FloatArray, hl: float,
             hw: float) -> NDArray[np.bool_]:
    """Whether polygons cross the rectangle ``|u| <= hl``, ``|v| <= hw`` or hold its centre.

    ``u``, ``v`` ``(V, p)``: the vertices in the rectangle's frame; ``ub``, ``vb``: the next
    vertex of each.
    """
    # polygon edges crossing the rectangle (Liang-Barsky clipping)
    du, dv = ub - u, vb - v
    t_in = np.zeros_like(u)
    t_out = np.ones_like(u)
    ok = np.ones(u.shape, dtype=bool)
    for a, d, h in ((u, du, hl), (v, dv, hw)):
        flat = np.abs(d) < 1e-15
        ok &= ~flat | (np.abs(a) <= h)
        with np.errstate(divide="ignore", invalid="ignore"):
            t1 = (-h - a) / d
            t2 = (h - a) / d
        lo = np.where(flat, -np.inf, np.minimum(t1, t2))
        hi = np.where(flat, np.inf, np.maximum(t1, t2))
        np.maximum(t_in, lo, out=t_in)
        np.minimum(t_out, hi, out=t_out)
    crosses = (ok & (t_in <= t_out)).any(axis=0)
    # rectangle inside the polygon: its centre (the origin) by crossing number
    straddle = (v > 0) != (vb > 0)
    with np.errstate(divide="ignore", invalid="ignore"):
        ucross = u - v * du / dv
    inside = (straddle & (ucross > 0)).sum(axis=0) % 2 == 1
    return np.asarray(crosses | inside)


# ---- spline set-up ---------------------------------------------------------------------
def _knots(n: int, k: int) -> FloatArray:
    inner = np.linspace(0.0, 1.0, n - k + 1)
    return np.concatenate((np.zeros(k), inner, np.ones(k)))


def _basis(u: FloatArray, t: FloatArray, k: int, n: int) -> tuple[NDArray[np.int64], FloatArray]:
    """First control index ``(m,)`` and basis values ``(3, k + 1, m)`` for nu = 0, 1, 2.

    ``basis[nu, :, j]`` holds the values at ``u[j]`` of the basis functions of control
    points ``first[j] .. first[j] + k`` (the only ones that are not zero there) and their
    first and second derivatives with respect to the parameter (Cox-de Boor recursion,
    vectorised over the samples, which run along the last axis; at ``u = 1`` the left
    limits).
    """
    span = np.clip(np.searchsorted(t, u, side="right") - 1, k, n - 1)
    first = span - k
    m = len(u)
    # the knots around each sample: row r holds t[span + r - k], r = 0 .. 2k + 1
    tt = t[span + np.arange(-k, k + 2)[:, None]]
    tables = [np.ones((1, m))]
    for p in range(1, k + 1):
        # functions span - p .. span: t[i], t[i + 1], t[i + p], t[i + p + 1] as rows of tt
        ti, ti1 = tt[k - p:k + 1], tt[k - p + 1:k + 2]
        tip, tip1 = tt[k:k + p + 1], tt[k + 1:k + p + 2]
        ext = _pad(tables[-1])
        left = _ratio(u - ti, tip - ti)
        right = _ratio(tip1 - u, tip1 - ti1)
        tables.append(left * ext[:-1] + right * ext[1:])
    vals = np.zeros((3, k + 1, m))
    vals[0] = tables[k]
    vals[1] = _derive(tables[k - 1], tt, k, k)
    if k >= 2:
        vals[2] = _derive(_derive(tables[k - 2], tt, k, k - 1), tt, k, k)
    return first.astype(np.int64), vals


def _pad(b: FloatArray) -> FloatArray:
    """A zero row on each side of ``(p, m)``."""
    out = np.zeros((b.shape[0] + 2, b.shape[1]))
    out[1:-1] = b
    return out


def _ratio(a: FloatArray, b: FloatArray) -> FloatArray:
    """``a / b`` where ``b > 0``, else 0."""
    return np.divide(a, b, out=np.zeros(np.broadcast(a, b).shape), where=b > 0)


def _derive(b: FloatArray, tt: FloatArray, k: int, p: int) -> FloatArray:
    """Parameter derivatives ``(p + 1, m)`` of the degree-``p`` basis functions
    ``span - p .. span`` from the degree ``p - 1`` ones ``b`` ``(p, m)``:
    ``N'_{i,p} = p (N_{i,p-1} / (t_{i+p} - t_i) - N_{i+1,p-1} / (t_{i+p+1} - t_{i+1}))``
    (``tt``: the knots around the samples, as in :func:`_basis`)."""
    ext = _pad(b)
    return p * (_ratio(ext[:-1], tt[k:k + p + 1] - tt[k - p:k + 1])
                - _ratio(ext[1:], tt[k + 1:k + p + 2] - tt[k - p + 1:k + 2]))


def _greville(t: FloatArray, k: int, n: int) -> FloatArray:
    if k == 0:
        return np.asarray(t[:n], dtype=float)
    cs = np.concatenate(([0.0], np.cumsum(t)))
    i = np.arange(n)
    return np.asarray((cs[i + k + 1] - cs[i + 1]) / k)


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
    if not (np.isfinite(start_speed) and start_speed >= 0):
        raise TrajectoryError(f"start speed must be >= 0, got {start_speed!r}")
    smooth = _sharp_bend(roadmap, corridor, params)
    traj = _plan_once(roadmap, corridor, obstacles, params, start_heading, start_speed,
                      end_speed, smooth)
    if not traj.feasible:
        other = _plan_once(roadmap, corridor, obstacles, params, start_heading, start_speed,
                           end_speed, not smooth)
        log.debug("first control polygon gives no feasible curve; the other: %s",
                  other.feasible)
        traj = other if other.feasible else traj
    if traj.feasible or params.detour_rate <= 0 or not _steep(roadmap, params.detour_rate):
        return traj
    detour = detour_roadmap(roadmap, corridor, params.detour_rate)
    if detour is None:
        return traj
    other = _plan_once(detour, corridor, obstacles, params, start_heading, start_speed,
                       end_speed)
    log.debug("level 2's path gives no feasible curve; detour feasible: %s", other.feasible)
    return other if other.feasible else traj


#: Stretch [m] of the road over which :func:`_sharp_bend` measures the road's heading change.
_BEND_BASE = 4.0


def _sharp_bend(roadmap: Roadmap, corridor: Corridor, params: TrajectoryParams) -> bool:
    """Whether the road along the roadmap bends on a radius below twice the turning radius
    (a junction turn): there the first control polygon is the least-bending one."""
    s = np.asarray(roadmap.s, dtype=float)
    dh = (corridor.heading_at(s + _BEND_BASE / 2.0)
          - corridor.heading_at(s - _BEND_BASE / 2.0))
    turn = np.abs((dh + np.pi) % (2.0 * np.pi) - np.pi)
    return bool(np.any(turn > 0.5 * params.kappa_max * _BEND_BASE))


def _steep(roadmap: Roadmap, rate: float) -> bool:
    """Whether level 2's path changes its lateral offset faster than ``rate`` somewhere
    (only then can :func:`detour_roadmap` find a path a curve follows better)."""
    ds = np.diff(np.asarray(roadmap.s, dtype=float))
    dl = np.abs(np.diff(np.asarray(roadmap.l, dtype=float)))
    return bool(np.any(dl > rate * np.maximum(ds, 1e-9) + 1e-9))


def _plan_once(roadmap: Roadmap, corridor: Corridor, obstacles: Obstacles,
               params: TrajectoryParams, start_heading: float | None, start_speed: float,
               end_speed: float | None, smooth: bool = False) -> Trajectory:
    """:func:`plan_trajectory` along the roadmap's chosen path (``smooth``: from the
    least-bending control polygon, see :func:`_control_points`)."""
    rp = roadmap.params
    pool, counts = _control_points(roadmap, corridor, start_heading, params, start_speed,
                                   smooth)
    checker = _Checker.build(corridor, obstacles, rp, pool)
    curve, refinements, doubled, samples = _refine(pool, counts, checker, params)
    opt = _Optimiser(curve, checker, params, samples)
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
                    params: TrajectoryParams, start_speed: float, smooth: bool = False
                    ) -> tuple[FloatArray, NDArray[np.int64]]:
    """Candidate control points ``(c, 2)`` and how often the first curve uses each (0 or 1).

    The candidates are the vehicle's position, a heading point ahead of it and the roadmap
    vertices beyond the heading point. The first curve uses the first two, the last, and the
    vertices that band simplification (:func:`band_simplify`) keeps, beginning at the
    farthest vertex that the vehicle's position reaches within the bands (at least the
    lead-in distance ahead).

    With ``smooth``, the vertices beyond the lead-in first move within their bands to the
    polygon of least bending (:func:`min_bending_offsets`), band simplification then drops
    those that stand in line, and long legs are split in pieces that grow gradually from
    the short legs beside them (:func:`_leg_splits`): the first curve then turns as gently
    as the bands allow, which a junction turn needs.
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
    lines = _vertex_lines(roadmap, corridor, distinct, sl[1:], params.band_fraction,
                          params.band_reserve)
    # the control points stand at the bands' centres (the roadmap vertices, except where
    # the band reserve moved them off an interval's end)
    moved = np.abs(lines[3] - sl[1:, 1]) > 1e-9
    pts = pts.copy()
    pts[moved] = lines[0][moved] + lines[3][moved, None] * lines[2][moved]
    lead = max(params.lead_in_lengths * rp.vehicle_length, params.lead_in_time * start_speed)
    lead = min(lead, 0.5 * reach)
    head_len = max(min(lead / 2.0, reach / 3.0), 1e-3)
    ahead = vs > s0 + head_len + rp.d / 2.0
    ahead[-1] = True
    verts = pts[ahead]
    lines = tuple(a[ahead] for a in lines)  # type: ignore[assignment]
    first = int(np.searchsorted(vs[ahead], s0 + lead - 1e-9))
    first = min(first, len(verts) - 1)
    if not smooth:
        # from the vehicle's position as far as the bands allow
        cap = int(np.searchsorted(polyline_stations(verts), params.max_control_spacing
                                  - float(np.hypot(*(verts[0] - start))), side="right")) - 1
        if cap >= 0:
            first = max(first, _farthest(start, -1, cap, verts, *lines))
    if start_heading is None:
        direction = verts[first] - start
    else:
        direction = np.array([np.cos(start_heading), np.sin(start_heading)])
    norm = float(np.hypot(*direction))
    if norm <= 1e-12:
        raise TrajectoryError("the roadmap's points coincide with the start: no curve")
    heading_point = start + head_len * direction / norm
    origin, tangent, normal, centre, half = (a[first:] for a in lines)
    if smooth:
        # the vehicle's position and heading point are fixed (bands of zero width)
        fixed = np.zeros(2)
        lat = min_bending_offsets(
            np.vstack((start, heading_point, origin)), np.vstack((np.zeros((2, 2)), normal)),
            np.concatenate((fixed, centre - half)), np.concatenate((fixed, centre + half)),
            np.concatenate((fixed, centre)), SMOOTH_CENTRE_WEIGHT)[2:]
        verts = verts.copy()
        verts[first:] = origin + lat[:, None] * normal
        centre, half = lat, np.minimum(half, SMOOTH_TOLERANCE)
    kept = first + band_simplify(verts[first:], origin, tangent, normal, centre, half)
    # long legs get extra control points on them (they stay within the bands)
    vst = vs[ahead]
    legs = np.column_stack((np.concatenate(([first], kept[:-1])), kept))
    leg_len = np.hypot(*(verts[legs[:, 1]] - verts[legs[:, 0]]).T)
    extra_xy, extra_s = [], []
    for j, (a, b) in enumerate(legs.tolist()):
        if a == b:
            continue
        if smooth:
            f = _leg_splits(float(leg_len[j]), float(leg_len[j - 1]) if j > 0 else np.inf,
                            float(leg_len[j + 1]) if j + 1 < len(legs) else np.inf,
                            params.max_control_spacing, LEG_GROWTH)
        else:
            pieces = int(np.ceil(leg_len[j] / params.max_control_spacing - 1e-9))
            f = np.arange(1, pieces) / max(pieces, 1)
        if len(f) == 0:
            continue
        extra_xy.append(verts[a] + f[:, None] * (verts[b] - verts[a]))
        extra_s.append(vst[a] + f * (vst[b] - vst[a]))
    counts = np.zeros(len(verts), dtype=np.int64)
    counts[kept] = 1
    if extra_xy:
        ex = np.concatenate(extra_xy)
        es = np.concatenate(extra_s)
        at = np.searchsorted(vst, es, side="right")
        verts = np.insert(verts, at, ex, axis=0)
        counts = np.insert(counts, at, 1)
    pool = np.vstack((start, heading_point, verts))
    return pool, np.concatenate(([1, 1], counts)).astype(np.int64)


#: Weight [1/m^2] that pulls the least-bending polygon towards level 2's path (its share of
#: the objective against the bending, so that straights among obstacles keep to the path).
SMOOTH_CENTRE_WEIGHT = 1e-4
#: Half width [m] of the bands within which band simplification drops vertices of the
#: least-bending polygon.
SMOOTH_TOLERANCE = 0.05
#: Largest ratio of two neighbouring legs of the smooth control polygon.
LEG_GROWTH = 2.0


def min_bending_offsets(origin: FloatArray, normal: FloatArray, lo: FloatArray,
                           hi: FloatArray, centre: FloatArray, weight: float,
                           max_rounds: int = 30) -> FloatArray:
    """Lateral offsets ``(m,)`` [m] of the points ``origin + l * normal`` that minimise the
    sum of squared second differences of the points (the discrete bending of the polyline)
    plus ``weight`` times the squared distance of ``l`` to ``centre``, within ``lo <= l <=
    hi``.

    Equation (3) moves a point to its neighbours' mean, which drives exactly this sum down;
    this is its fixed point within the bands, found at once: the Hessian is banded
    (pentadiagonal), solved by banded Cholesky inside a primal active-set loop.
    """
    from scipy.linalg import solveh_banded

    m = len(origin)
    if m < 3:
        return np.clip(centre, lo, hi)
    # second differences D (m - 2, m) for uneven spacing (curvature-like, weighted by the
    # length each one stands for); M = D^T D is pentadiagonal
    h = np.maximum(np.hypot(*np.diff(origin, axis=0).T), 1e-3)
    w = np.sqrt(2.0 / (h[:-1] + h[1:]))  # 2 / (h0 + h1) * sqrt((h0 + h1) / 2)
    coef = np.column_stack((w / h[:-1], -w * (1.0 / h[:-1] + 1.0 / h[1:]), w / h[1:]))
    m0 = np.zeros(m)
    m1 = np.zeros(m - 1)
    for a in range(3):
        m0[a:m - 2 + a] += coef[:, a] ** 2
    for a in range(2):
        m1[a:m - 2 + a] += coef[:, a] * coef[:, a + 1]
    m2 = coef[:, 0] * coef[:, 2]
    nn1 = np.einsum("ij,ij->i", normal[:-1], normal[1:])
    nn2 = np.einsum("ij,ij->i", normal[:-2], normal[2:])
    n0 = np.einsum("ij,ij->i", normal, normal)
    # (a tiny ridge keeps the system definite where nothing else pins the offsets down)
    h0, h1, h2 = m0 * n0 + weight + 1e-9, m1 * nn1, m2 * nn2
    second = (coef[:, 0, None] * origin[:-2] + coef[:, 1, None] * origin[1:-1]
              + coef[:, 2, None] * origin[2:])  # D @ origin
    dt = np.zeros((m, 2))  # D^T @ second
    dt[:-2] += coef[:, 0, None] * second
    dt[1:-1] += coef[:, 1, None] * second
    dt[2:] += coef[:, 2, None] * second
    g = np.einsum("ij,ij->i", normal, dt) - weight * centre

    def hess(x: FloatArray) -> FloatArray:
        y = h0 * x
        y[:-1] += h1 * x[1:]
        y[1:] += h1 * x[:-1]
        y[:-2] += h2 * x[2:]
        y[2:] += h2 * x[:-2]
        return y

    fixed = lo >= hi

    def solve(at_lo: NDArray[np.bool_], at_hi: NDArray[np.bool_]) -> FloatArray:
        """Minimum with the offsets in ``at_lo`` / ``at_hi`` held at those bounds (by a
        stiff penalty, which keeps the system banded)."""
        act = at_lo | at_hi
        ab = np.zeros((3, m))
        ab[2] = h0 + _PIN * act
        ab[1, 1:] = h1
        ab[0, 2:] = h2
        rhs = -g + _PIN * np.where(at_lo, lo, np.where(at_hi, hi, 0.0))
        return solveh_banded(ab, rhs, lower=False, check_finite=False)

    # primal-dual active set: fast, usually exact, but not guaranteed to settle
    at_lo = np.zeros(m, dtype=bool)
    at_hi = fixed.copy()
    for _ in range(max_rounds):
        x = solve(at_lo, at_hi)
        grad = hess(x) + g
        new_lo = ((at_lo & (grad >= 0)) | (x < lo - 1e-9)) & ~fixed
        new_hi = ((at_hi & (grad <= 0)) | (x > hi + 1e-9)) & ~new_lo | fixed
        if np.array_equal(new_lo, at_lo) and np.array_equal(new_hi, at_hi):
            break
        at_lo, at_hi = new_lo, new_hi
    # primal active set from there: each step stays within the bounds and lowers the
    # objective, so it ends at the optimum
    x = np.clip(x, lo, hi)
    at_lo = (x <= lo) & ~fixed
    at_hi = (x >= hi) | fixed
    for _ in range(4 * m + 10):
        y = solve(at_lo, at_hi)
        free = ~(at_lo | at_hi)
        out = free & ((y < lo) | (y > hi))
        if not out.any():
            x = np.where(free, y, x)
            grad = hess(x) + g
            wrong = np.where(at_lo, -grad, 0.0) + np.where(at_hi & ~fixed, grad, 0.0)
            i = int(np.argmax(wrong))
            if wrong[i] <= 1e-9 * (1.0 + float(np.abs(grad).max())):
                break
            at_lo[i] = at_hi[i] = False
            continue
        d = y - x
        with np.errstate(divide="ignore", invalid="ignore"):
            room = np.where(d < 0, (lo - x) / d, np.where(d > 0, (hi - x) / d, np.inf))
        room = np.where(free, np.clip(room, 0.0, None), np.inf)
        j = int(np.argmin(room))
        x = np.where(free, x + min(float(room[j]), 1.0) * d, x)
        at_lo[j], at_hi[j] = d[j] < 0, d[j] > 0
    return np.clip(x, lo, hi)


#: Stiffness that holds an offset at its bound in :func:`min_bending_offsets`.
_PIN = 1e8


def _leg_splits(length: float, before: float, after: float, cap: float, ratio: float
                ) -> FloatArray:
    """Fractions ``(k,)`` of a control-polygon leg of ``length`` [m] at which to split it so
    that no piece is longer than ``cap`` [m] nor ``ratio`` times its neighbour: pieces grow
    geometrically from the legs ``before`` and ``after`` it (their lengths [m]).

    A uniform B-spline turns within its shortest legs, so a short leg beside a long one
    gives a sharp bend that the control polygon does not have.
    """
    cuts_a, cuts_b = [], []
    pos, step = 0.0, min(max(ratio * before, 0.5), cap)
    while pos + step < length / 2.0:
        pos += step
        cuts_a.append(pos)
        step = min(step * ratio, cap)
    pos, step = length, min(max(ratio * after, 0.5), cap)
    while pos - step > length / 2.0:
        pos -= step
        cuts_b.append(pos)
        step = min(step * ratio, cap)
    lo = cuts_a[-1] if cuts_a else 0.0
    hi = cuts_b[-1] if cuts_b else length
    mid = int(np.ceil((hi - lo) / cap - 1e-9))
    cuts = np.concatenate((cuts_a, lo + (hi - lo) * np.arange(1, mid) / max(mid, 1),
                           cuts_b[::-1]))
    return np.asarray(cuts, dtype=float) / length


#: Lateral grid step [m] of :func:`detour_roadmap`'s search.
_DETOUR_STEP = 0.1
#: Distance [m] to a free interval's ends below which the detour search pays for nearness.
_DETOUR_CLEAR = 1.0


def detour_roadmap(roadmap: Roadmap, corridor: Corridor, rate: float) -> Roadmap | None:
    """Level 2's roadmap with its path replaced by one that a curve can follow.

    The widest path may jump between lanes wherever a sweep line is free across (its
    vertex stands mid-road), and a lane a hair narrower than the bottleneck elsewhere
    sends it across two lanes and back within a gap between parked cars, which no curve
    within the turning limit follows. This searches the same graph (its free intervals
    and arcs) on a lateral grid of :data:`_DETOUR_STEP` [m] for the path whose lateral
    offset changes by at most ``rate`` [m per m of station] from line to line, starting
    at the vehicle's offset, that minimises the sum of squared lateral steps over their
    lengths plus a penalty for passing within :data:`_DETOUR_CLEAR` [m] of an interval's
    end (dynamic programming over the lines). Its vertices stand at those offsets, inside
    their free intervals. ``None`` if the graph has no such path.
    """
    line = np.asarray(roadmap.graph_line, dtype=np.int64)
    if len(line) == 0 or len(roadmap.arcs) == 0 or rate <= 0:
        return None
    lo_v = np.asarray(roadmap.graph_lo, dtype=float)
    hi_v = np.asarray(roadmap.graph_hi, dtype=float)
    n_lines, n_v = int(line.max()) + 1, len(line)
    st = np.zeros(n_lines)
    st[line] = roadmap.graph_s
    h = _DETOUR_STEP
    l0 = float(lo_v.min()) - h
    nb = int(np.ceil((float(hi_v.max()) + h - l0) / h)) + 1
    grid = l0 + h * np.arange(nb)
    # vid[k, b]: the vertex of line k whose interval holds grid offset b (half a step of
    # tolerance, so that zero-width intervals count), -1 where none does
    vid = np.full((n_lines, nb), -1, dtype=np.int64)
    b_lo = np.ceil((lo_v - h / 2 - l0) / h - 1e-9).astype(np.int64)
    b_hi = np.floor((hi_v + h / 2 - l0) / h + 1e-9).astype(np.int64)
    for v in range(n_v):
        vid[line[v], b_lo[v]:b_hi[v] + 1] = v
    lv = np.clip(grid[None, :], lo_v[vid], hi_v[vid])
    near = np.minimum(lv - lo_v[vid], hi_v[vid] - lv)
    penalty = np.where(vid >= 0, np.maximum(_DETOUR_CLEAR - near, 0.0) ** 2, np.inf)
    # moves b - dlt -> b between lines k and k + 1 that follow an arc within the rate:
    # ok[k, b, dlt + r], with their lateral cost
    ds = np.maximum(np.diff(st), 1e-6)
    r = int(np.floor(rate * float(ds.max()) / h + 1e-9))
    dlt = np.arange(-r, r + 1)
    frm = np.arange(nb)[:, None] - dlt[None, :]
    # arcs as tables per pair of lines, (lines - 1, P + 1, P + 1), over each vertex's index
    # on its line (P: none, never connected)
    by_line = np.argsort(line, kind="stable")
    loc = np.empty(n_v, dtype=np.int64)
    loc[by_line] = np.arange(n_v) - np.searchsorted(line[by_line], line[by_line])
    n_loc = int(loc.max()) + 1
    arcs = np.asarray(roadmap.arcs, dtype=np.int64)
    arcs = arcs[line[arcs[:, 1]] == line[arcs[:, 0]] + 1]
    table = np.zeros((n_lines - 1, n_loc + 1, n_loc + 1), dtype=bool)
    table[line[arcs[:, 0]], loc[arcs[:, 0]], loc[arcs[:, 1]]] = True
    lid = np.full((n_lines, nb + 2 * r), n_loc)  # padded by r bins of none on each side
    lid[:, r:r + nb] = np.where(vid >= 0, loc[vid], n_loc)
    # flat index into the tables: (line, from, to)
    flat = lid[:-1][:, frm + r]
    flat += (n_loc + 1) * np.arange(n_lines - 1)[:, None, None]
    flat *= n_loc + 1
    flat += lid[1:, r:r + nb, None]
    ok = table.ravel()[flat]
    ok &= np.abs(dlt)[None, None, :] * h <= rate * ds[:, None, None] + 1e-9
    lat_cost = (dlt[None, :] * h) ** 2 / ds[:, None]  # (lines - 1, 2r + 1)
    step_cost = np.where(ok, lat_cost[:, None, :], np.inf)  # (lines - 1, nb, 2r + 1)
    frm_c = np.clip(frm, 0, nb - 1)
    # start: the source vertex, at the vehicle's offset
    src = int(roadmap.path[0])
    l_start = float(corridor.to_sl(np.asarray(roadmap.start_xy, dtype=float)[None])[0, 1])
    cost = np.where(vid[0] == src, np.abs(grid - l_start), np.inf)
    cost = np.where(cost <= np.min(cost) + 1e-9, penalty[0], np.inf)
    back = np.zeros((n_lines, nb), dtype=np.int64)
    rows = np.arange(nb)
    for k in range(n_lines - 1):
        cand = cost[frm_c] + step_cost[k]
        j = np.argmin(cand, axis=1)
        cost = cand[rows, j] + penalty[k + 1]
        back[k + 1] = j
    if not np.isfinite(cost).any():
        return None
    bins = np.zeros(n_lines, dtype=np.int64)
    bins[-1] = int(np.argmin(cost))
    for k in range(n_lines - 1, 0, -1):
        bins[k - 1] = frm_c[bins[k], back[k, bins[k]]]
    ks = np.arange(n_lines)
    path = vid[ks, bins]
    lat = lv[ks, bins]
    xy = corridor.to_xy(st, lat)
    width = np.asarray(roadmap.graph_width, dtype=float)[path]
    j = int(np.argmin(width))
    return replace(roadmap, xy=xy, s=st.copy(), l=lat, width=width,
                   bottleneck_width=float(width[j]), bottleneck_index=j,
                   length=float(polyline_stations(xy)[-1]), path=path,
                   links=np.zeros((0, 2, 2)))


def _vertex_lines(roadmap: Roadmap, corridor: Corridor, distinct: NDArray[np.bool_],
                  sl: FloatArray, band_fraction: float, band_reserve: float = 0.0
                  ) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray, FloatArray]:
    """Each roadmap vertex's sweep line and band: origin ``(m, 2)`` (lateral offset 0),
    tangent ``(m, 2)``, normal ``(m, 2)``, band centre ``(m,)`` [m] and half width ``(m,)`` [m].

    Each vertex moves ``band_reserve`` [m] off its free interval's ends (where the interval
    is wide enough), which is where the band is centred; the band spans ``band_fraction``
    of the free interval, within the interval less ``band_reserve`` [m] on each side
    (room for the footprint's turn away from the road's heading). Without free
    intervals (a roadmap without its graph) the bands are empty and centred on the vertices.
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
        # the vertex, moved off its interval's ends by the reserve where it can
        q = np.minimum(band_reserve, (hi - lo) / 2.0)
        centre = np.clip(sl[:, 1], lo + q, hi - q)
        room = np.minimum(centre - lo, hi - centre)
        half = np.clip(np.minimum(band_fraction * np.maximum(hi - lo, 0.0) / 2.0,
                                  room - band_reserve), 0.0, None)
    else:
        centre, half = sl[:, 1], np.zeros(len(s))
    return origin, tangent, normal, centre, half


def band_simplify(points: ArrayLike, origin: ArrayLike, tangent: ArrayLike, normal: ArrayLike,
                  centre: ArrayLike, half: ArrayLike) -> NDArray[np.int64]:
    """Vertices kept by greedy string pulling through lateral bands.

    Vertex ``k`` of the polyline ``points`` ``(m, 2)`` [m] stands on a line through
    ``origin[k]`` ``(m, 2)`` along ``normal[k]`` ``(m, 2)`` (unit; ``tangent[k]`` is the unit
    direction across it, along the road). Its band is the part of that line at lateral
    offsets ``centre[k] +- half[k]`` [m]. From the last kept vertex ``i``, the next kept
    vertex is the farthest ``j`` such that every segment ``i -> j'`` with ``j' <= j`` crosses
    every line ``k`` with ``i < k < j'`` inside its band (at least ``j = i + 1``). With
    ``half = 0`` only collinear vertices go.

    Returns
    -------
    Increasing indices, with the first and the last vertex.
    """
    pts = np.asarray(points, dtype=float)
    org, tan, nrm, cen, hlf = (np.asarray(a, dtype=float)
                               for a in (origin, tangent, normal, centre, half))
    m = len(pts)
    if m <= 2:
        return np.arange(m, dtype=np.int64)
    kept = [0]
    i = 0
    ends = _band_ends(pts, org, nrm, cen, hlf)
    while i < m - 1:
        i = _farthest(pts[i], i, m - 1, pts, org, tan, nrm, cen, hlf, ends=ends)
        kept.append(i)
    return np.asarray(kept, dtype=np.int64)


def _farthest(p: FloatArray, i: int, cap: int, pts: FloatArray, origin: FloatArray,
              tangent: FloatArray, normal: FloatArray, centre: FloatArray, half: FloatArray,
              tol: float = 1e-9, ends: FloatArray | None = None) -> int:
    """Largest ``j`` in ``(i, cap]`` (at least ``i + 1``) such that every segment
    ``p -> pts[j']``, ``i < j' <= j``, crosses the lines ``i < k < j'`` inside their bands.

    The rays from ``p`` that meet band ``k`` form the angle between its two ends (seen
    from ``p``, relative to the road's direction at ``k``); a segment ``p -> pts[j]``
    crosses every band before ``j`` if its direction lies in all their angles (running
    maximum of the lower and minimum of the upper ends), and reaches each line ``k < j``
    as the lines do not cross.
    """
    if cap <= i + 1:
        return min(i + 1, len(pts) - 1)
    # the test is a running one: a window of candidates gives the same answer as all of
    # them unless every candidate in it passes, then a window four times as long
    window = 32
    if ends is None:
        ends = _band_ends(pts, origin, normal, centre, half)
    while True:
        end = min(cap, i + window)
        j = _farthest_upto(p, i, end, pts, origin, tangent, normal, centre, half, tol, ends)
        if j < end or end == cap:
            return j
        window *= 4


def _band_ends(pts: FloatArray, origin: FloatArray, normal: FloatArray, centre: FloatArray,
               half: FloatArray) -> FloatArray:
    """Per vertex ``(m, 3, 2)``: the lower and the upper end of its band, and the vertex."""
    return np.stack((origin + (centre - half)[:, None] * normal,
                     origin + (centre + half)[:, None] * normal, pts), axis=1)


def _farthest_upto(p: FloatArray, i: int, cap: int, pts: FloatArray, origin: FloatArray,
                   tangent: FloatArray, normal: FloatArray, centre: FloatArray,
                   half: FloatArray, tol: float, ends: FloatArray | None = None) -> int:
    """:func:`_farthest` over all candidates ``(i, cap]`` at once (``ends``: the
    :func:`_band_ends` of all vertices, computed here if ``None``)."""
    ks = slice(i + 1, cap + 1)
    ref = tangent[i + 1] if i + 1 < len(tangent) else tangent[-1]
    c, s = ref[0], ref[1]
    if ends is None:
        ends = _band_ends(pts, origin, normal, centre, half)
    # directions (relative to the road's) from p to both band ends and to the vertex
    q = ends[ks]
    dx, dy = q[..., 0] - p[0], q[..., 1] - p[1]
    ang = np.arctan2(-dx * s + dy * c, dx * c + dy * s)
    a1, a2, th = ang[:, 0], ang[:, 1], ang[:, 2]
    lo, hi = np.minimum(a1, a2), np.maximum(a1, a2)
    # a line through p itself does not constrain the direction
    o, t = origin[ks], tangent[ks]
    on = np.abs((o[:, 0] - p[0]) * t[:, 0] + (o[:, 1] - p[1]) * t[:, 1]) < 1e-9
    lo[on], hi[on] = -np.inf, np.inf
    # bounds from the lines strictly before each candidate
    low, high = np.empty(len(lo)), np.empty(len(hi))
    low[0], high[0] = -np.inf, np.inf
    np.maximum.accumulate(lo[:-1], out=low[1:])
    np.minimum.accumulate(hi[:-1], out=high[1:])
    good = (th >= low - tol) & (th <= high + tol)
    good[0] = True
    if good.all():
        return cap
    return int(i + np.argmin(good))


@dataclass(frozen=True, eq=False)
class _Curve:
    """A clamped B-spline on fixed parameter samples, with its basis there.

    ``first[j]`` is the first of the ``k + 1`` control points that shape sample ``j``;
    ``basis[nu, :, j]`` their values (nu = 0) and parameter derivatives (nu = 1, 2) there.
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
        span_len = padded[:n - k].copy()  # the longest of the k + 2 legs around each span
        for j in range(1, k + 2):
            np.maximum(span_len, padded[j:j + n - k], out=span_len)
        per = np.clip(np.ceil(span_len / spacing).astype(int) + 1, 2, 400)
        inner = knots[k:n + 1]
        # per span, evenly spaced from its start (as np.linspace without the end point)
        step = np.repeat(np.diff(inner) / per, per)
        within = np.arange(int(per.sum())) - np.repeat(np.cumsum(per) - per, per)
        u = np.concatenate((within * step + np.repeat(inner[:-1], per), [1.0]))
        first, basis = _basis(u, knots, k, n)
        return cls(ctrl, pool_index, knots, k, u, first, basis)

    def evaluate(self, ctrl: FloatArray | None = None) -> tuple[FloatArray, FloatArray,
                                                                  FloatArray]:
        """Positions, first and second parameter derivatives ``(m, 2)`` at the samples."""
        c = self.ctrl if ctrl is None else ctrl
        cols = self.first + np.arange(self.k + 1)[:, None]
        gx, gy = c[:, 0][cols], c[:, 1][cols]  # (k + 1, m)
        out = []
        for b in self.basis:
            x, y = b[0] * gx[0], b[0] * gy[0]
            for j in range(1, self.k + 1):
                x += b[j] * gx[j]
                y += b[j] * gy[j]
            out.append(np.column_stack((x, y)))
        return out[0], out[1], out[2]


def _refine(pool: FloatArray, counts: NDArray[np.int64], checker: _Checker,
            params: TrajectoryParams) -> tuple[_Curve, int, int, tuple[FloatArray, ...]]:
    """The first curve, repaired locally where its footprint is not clear.

    For each sample where the footprint touches an obstacle (with the margin) or leaves the
    road, the left-out candidate nearest to it, among those between the control points that
    shape it, comes back; where none is left there, the shaping control point nearest to
    the sample is doubled (up to ``degree`` copies: repeated control points pull the curve
    onto its control polygon, undoing the corner cut). At most ``repair_rounds`` rounds,
    and none after two rounds that did not improve on the best curve; the least violating
    curve is returned (footprint first, then curvature: the curvature is left to the
    optimisation).

    Returns the curve, the rounds, the number of control points doubled and the curve's
    samples (positions, derivatives, footprint slack, stations) for the optimiser.
    """
    counts = counts.copy()
    rounds = doubled = stall = 0
    n_pool = len(pool)
    best: tuple[tuple[float, float], _Curve, int, int, tuple[FloatArray, ...]] | None = None
    while True:
        pool_idx = np.repeat(np.arange(n_pool), counts)
        curve = _Curve.build(pool[pool_idx], pool_idx, params.degree, params.sample_spacing)
        pos, d1, d2 = curve.evaluate()
        slack, sc = checker.slack(pos, np.arctan2(d1[:, 1], d1[:, 0]))
        kmax = float(np.abs(curvature_from_derivatives(d1, d2)).max())
        # violation: footprint [m] inside the margin, then curvature beyond the limit
        score = (max(-float(slack.min()), 0.0), max(kmax - params.kappa_max, 0.0))
        if best is None or score < best[0]:
            best = (score, curve, rounds, doubled, (pos, d1, d2, slack, sc))
            stall = 0
        else:
            stall += 1
        bad = np.flatnonzero(slack < 0)
        if len(bad) == 0 or rounds >= params.repair_rounds or stall >= 2:
            break
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
        if not add.any():
            # no vertex left to re-insert: double the control point nearest each violation
            for j in bad.tolist():
                f = int(curve.first[j])
                inner = pool_idx[f:min(f + k, n - 1) + 1]
                inner = inner[(inner >= 2) & (inner < n_pool - 1) & (counts[inner] < k)]
                if len(inner):
                    dup[inner[np.argmin(np.hypot(*(pool[inner] - pos[j]).T))]] = True
        if not (add.any() or dup.any()):
            break
        counts[add] = 1
        counts[dup] += 1
        doubled += int(dup.sum())
        rounds += 1
    # the least violating curve seen (the first clear one, if any)
    assert best is not None
    return best[1], best[2], best[3], best[4]


class _Optimiser:
    """Equation (3) on fixed parameter samples, with local re-evaluation."""

    def __init__(self, curve: _Curve, checker: _Checker, params: TrajectoryParams,
                 samples: tuple[FloatArray, ...]) -> None:
        self.ctrl = curve.ctrl.copy()
        first, k, u, knots = curve.first, curve.k, curve.u, curve.knots
        self.first, self.basis, self.k = first, curve.basis, k
        self.checker, self.params = checker, params
        n = len(self.ctrl)
        self.n = n
        cols = first[:, None] + np.arange(k + 1)[None, :]
        self.pos, self.d1, self.d2, self.slack, self.station = (a.copy() for a in samples)
        self.kappa = np.abs(curvature_from_derivatives(self.d1, self.d2))
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
                                        self.slack, self.station))

    def _restore(self, state: tuple[FloatArray, ...]) -> None:
        self.ctrl, self.pos, self.d1, self.d2, self.kappa, self.slack, self.station = state

    def run(self) -> IterationStats:
        p = self.params
        k, n = self.k, self.n
        tried = accepted = refused = rounds = 0
        best = (float(self.kappa.max()), self._state())
        idle = 0
        while tried < p.max_iterations and idle < p.patience:
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
                idle = 0
            else:
                idle += 1
        if float(self.kappa.max()) > best[0] + 1e-12:
            self._restore(best[1])
        log.debug("optimisation: %d rounds, %d tried, %d accepted", rounds, tried, accepted)
        return IterationStats(tried, accepted, refused, rounds)

    def _try(self, moves: NDArray[np.int64]) -> NDArray[np.bool_]:
        """Try moving each control point in ``moves`` to its neighbours' mean."""
        k, p = self.k, self.params
        delta = 0.5 * (self.ctrl[moves - 1] + self.ctrl[moves + 1]) - self.ctrl[moves]
        lo, hi = self.lo[moves], self.hi[moves]
        lens = hi - lo
        nm = len(moves)
        if nm == 1:
            idx = np.arange(lo[0], hi[0])
            owner = np.zeros(len(idx), dtype=np.int64)
        else:
            owner = np.repeat(np.arange(nm), lens)
            idx = np.arange(int(lens.sum())) + np.repeat(lo - np.cumsum(lens) + lens, lens)
        r = moves[owner] - self.first[idx]  # column of the moved point in each sample's row
        dlt = delta[owner]
        b = self.basis[:, r, idx]  # (3, q)
        pos = self.pos[idx] + b[0, :, None] * dlt
        d1 = self.d1[idx] + b[1, :, None] * dlt
        d2 = self.d2[idx] + b[2, :, None] * dlt
        kap = np.abs(curvature_from_derivatives(d1, d2))
        slack, sc = self.checker.slack(pos, np.arctan2(d1[:, 1], d1[:, 0]), self.station[idx])
        old_k, old_s = self.kappa[idx], self.slack[idx]
        # per sample: samples clear of obstacles and road edges stay clear
        bad = (old_s >= 0) & (slack < 0)
        # per move: the worst violation of the changed stretch (curvature beyond the turning
        # limit, footprint within the margin) does not grow
        starts = np.cumsum(lens) - lens  # each move's samples: one run, never empty
        worse = np.logical_or.reduceat(bad, starts)
        limits = ((kap, old_k, p.kappa_max), (-slack, -old_s, 0.0))
        for new, old, lim in limits:
            worse |= (np.maximum.reduceat(new, starts)
                      > np.maximum(np.maximum.reduceat(old, starts), lim) + 1e-12)
        acc = ~worse
        keep = acc[owner]
        ki = idx[keep]
        self.pos[ki], self.d1[ki], self.d2[ki] = pos[keep], d1[keep], d2[keep]
        self.kappa[ki], self.slack[ki], self.station[ki] = kap[keep], slack[keep], sc[keep]
        self.ctrl[moves[acc]] += delta[acc]
        self.refused[moves[~acc]] = True
        for i in moves[acc]:
            self.refused[max(i - k, 0):i + k + 1] = False
        return acc


def _independent(bad: FloatArray, k: int, budget: int) -> list[int]:
    """Control points to move this round: the worst first, then others ``k + 1`` apart."""
    order = np.argsort(-bad, kind="stable")
    order = order[bad[order] > 0]
    taken = [False] * (len(bad) + 2 * k + 2)  # a list: a few short slices, no array calls
    chosen: list[int] = []
    for i in order.tolist():
        if len(chosen) >= budget:
            break
        if any(taken[i: i + 2 * k + 1]):
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
    clear_road, _ = checker.road(pos, head, np.interp(uu, curve.u, opt.station))
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
