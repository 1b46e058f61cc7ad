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
from numpy.lib.stride_tricks import sliding_window_view
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
    polys: FloatArray  # (K, V, 2), padded with each ring's last vertex
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
        # boundaries and the largest turn of the reference line (for a quick clear test)
        ds = np.diff(st)
        w = int(np.ceil((np.hypot(hl, hw) + 1.0) / max(float(np.quantile(ds, 0.1)), 1e-3)))
        size = min(2 * w + 1, 2 * len(ds) + 1)
        lmin = minimum_filter1d(left, size, mode="nearest")[:-1]
        rmax = maximum_filter1d(right, size, mode="nearest")[:-1]
        hh = np.unwrap(h)
        turn = (maximum_filter1d(hh, size, mode="nearest")
                - minimum_filter1d(hh, size, mode="nearest"))
        object.__setattr__(self, "window", (lmin, rmax, turn))

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
        nseg = len(st) - 2
        bx, by = self.body
        c, s = np.cos(heading)[:, None], np.sin(heading)[:, None]
        px = (xy[:, 0, None] + c * bx) - s * by
        py = (xy[:, 1, None] + s * bx) + c * by
        i0 = np.searchsorted(st, sc, side="right") - 1
        np.clip(i0, 0, nseg, out=i0)
        est = st[i0, None] + ((px - rx[i0, None]) * hc[i0, None]
                              + (py - ry[i0, None]) * hs[i0, None])
        i = np.searchsorted(st, est, side="right") - 1
        np.clip(i, 0, nseg, out=i)
        dx, dy = px - rx[i], py - ry[i]
        ci, si = hc[i], hs[i]
        along = st[i] + dx * ci + dy * si
        lat = dy * ci - dx * si
        f = along[:, :-1]
        clear = np.minimum(np.interp(f, st, left) - lat[:, :-1],
                           lat[:, :-1] - np.interp(f, st, right)).min(axis=1)
        return clear, along[:, -1]

    def slack(self, xy: FloatArray, heading: FloatArray, sc: FloatArray | None = None
              ) -> tuple[FloatArray, FloatArray]:
        """Footprint clearance [m] beyond the safety margin (negative: too close), and the
        centres' stations [m] (see :meth:`road`)."""
        if sc is None:
            sc = self.stations(xy)
        # the centres in the frame of the reference segment at their station (from the
        # estimate, one step of refinement)
        st, rx, ry, hc, hs, _, _ = self.frames
        lmin, rmax, turn = self.window
        sc_new = sc
        for _ in range(2):
            i = np.searchsorted(st, sc_new, side="right") - 1
            np.clip(i, 0, len(st) - 2, out=i)
            dx, dy = xy[:, 0] - rx[i], xy[:, 1] - ry[i]
            ci, si = hc[i], hs[i]
            sc_new = st[i] + dx * ci + dy * si
        lat = dy * ci - dx * si
        # clearly on the road (a lower bound of the clearance is above the margin): no
        # exact check of the footprint
        dh = heading - np.arctan2(si, ci)
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
        if len(self.polys) == 0 or len(xy) == 0:
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
        if len(js) and cull:
            c, s = np.cos(heading[js])[:, None], np.sin(heading[js])[:, None]
            pol = self.polys[os]
            rx, ry = pol[..., 0] - xy[js, 0, None], pol[..., 1] - xy[js, 1, None]
            u, v = rx * c + ry * s, ry * c - rx * s
            gap = self.margin + horizon
            keep = ((u.min(axis=1) < self.half_length + gap)
                    & (u.max(axis=1) > -self.half_length - gap)
                    & (v.min(axis=1) < self.half_width + gap)
                    & (v.max(axis=1) > -self.half_width - gap))
            js, os = js[keep], os[keep]
        if len(js) == 0:
            return out
        d = _rect_polygon_distance(xy[js], heading[js], self.half_length, self.half_width,
                                   self.polys[os])
        np.minimum.at(out, js, d)
        return out


_CORNERS = np.array([[-1.0, -1.0], [1.0, -1.0], [1.0, 1.0], [-1.0, 1.0]])


def _rect_polygon_distance(centers: FloatArray, headings: FloatArray, hl: float, hw: float,
                           polys: FloatArray) -> FloatArray:
    """Distance [m] between oriented rectangles and polygons ``(p, V, 2)``, 0 on overlap."""
    c, s = np.cos(headings)[:, None], np.sin(headings)[:, None]
    rx = polys[..., 0] - centers[:, None, 0]
    ry = polys[..., 1] - centers[:, None, 1]
    u = rx * c + ry * s  # body frame: u along the heading, v to the left
    v = ry * c - rx * s
    au, av = np.abs(u), np.abs(v)
    # polygon vertices to the filled rectangle
    dv = np.hypot(np.maximum(au - hl, 0.0), np.maximum(av - hw, 0.0)).min(axis=1)
    ub = np.concatenate((u[:, 1:], u[:, :1]), axis=1)  # the next vertex (np.roll, cheaper)
    vb = np.concatenate((v[:, 1:], v[:, :1]), axis=1)
    du, dvv = ub - u, vb - v
    # rectangle corners ``(4,)`` to polygon edges: arrays (p, 4, V)
    seg2 = du * du + dvv * dvv
    inv = 1.0 / np.where(seg2 > 0, seg2, 1.0)
    cu, cv = hl * _CORNERS[:, 0, None], hw * _CORNERS[:, 1, None]
    wu, wv = cu - u[:, None, :], cv - v[:, None, :]
    du3, dv3 = du[:, None, :], dvv[:, None, :]
    t = wu * du3  # in place from here: the arrays are the largest of the check
    t += wv * dv3
    t *= inv[:, None, :]
    np.clip(t, 0.0, 1.0, out=t)
    gu = t * du3
    gu -= wu
    t *= dv3
    t -= wv
    best = np.hypot(gu, t, out=gu).min(axis=(1, 2))
    # polygon edges crossing the rectangle (Liang-Barsky clipping)
    t_in = np.zeros_like(u)
    t_out = np.ones_like(u)
    ok = np.ones(u.shape, dtype=bool)
    for a, aa, d, h in ((u, au, du, hl), (v, av, dvv, hw)):
        flat = np.abs(d) < 1e-15
        ok &= ~flat | (aa <= h)
        with np.errstate(divide="ignore", invalid="ignore"):
            t1 = (-h - a) / d
            t2 = (h - a) / d
        lo = np.where(flat, -np.inf, np.minimum(t1, t2))
        hi = np.where(flat, np.inf, np.maximum(t1, t2))
        np.maximum(t_in, lo, out=t_in)
        np.minimum(t_out, hi, out=t_out)
    crosses = (ok & (t_in <= t_out)).any(axis=1)
    # rectangle inside the polygon: its centre (the origin) by crossing number
    straddle = (v > 0) != (vb > 0)
    with np.errstate(divide="ignore", invalid="ignore"):
        ucross = u - v * du / (vb - v)
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
    second derivatives with respect to the parameter (Cox-de Boor recursion, vectorised over
    the samples; at ``u = 1`` the left limits).
    """
    span = np.clip(np.searchsorted(t, u, side="right") - 1, k, n - 1)
    first = span - k
    m = len(u)
    tables = [np.ones((m, 1))]
    for p in range(1, k + 1):
        i = span[:, None] + np.arange(-p, 1)[None, :]  # (m, p + 1) function indices
        ext = _pad(tables[-1])
        left = _ratio(u[:, None] - t[i], t[i + p] - t[i])
        right = _ratio(t[i + p + 1] - u[:, None], t[i + p + 1] - t[i + 1])
        tables.append(left * ext[:, :-1] + right * ext[:, 1:])
    vals = np.zeros((3, m, k + 1))
    vals[0] = tables[k]
    vals[1] = _derive(tables[k - 1], span, t, k)
    if k >= 2:
        vals[2] = _derive(_derive(tables[k - 2], span, t, k - 1), span, t, k)
    return first.astype(np.int64), vals


def _pad(b: FloatArray) -> FloatArray:
    """A zero column on each side of ``(m, p)``."""
    out = np.zeros((len(b), b.shape[1] + 2))
    out[:, 1:-1] = b
    return out


def _ratio(a: FloatArray, b: FloatArray) -> FloatArray:
    """``a / b`` where ``b > 0``, else 0."""
    return np.divide(a, b, out=np.zeros(np.broadcast(a, b).shape), where=b > 0)


def _derive(b: FloatArray, span: NDArray[np.int64], t: FloatArray, p: int) -> FloatArray:
    """Parameter derivatives ``(m, p + 1)`` of the degree-``p`` basis functions
    ``span - p .. span`` from the degree ``p - 1`` ones ``b`` ``(m, p)``:
    ``N'_{i,p} = p (N_{i,p-1} / (t_{i+p} - t_i) - N_{i+1,p-1} / (t_{i+p+1} - t_{i+1}))``."""
    i = span[:, None] + np.arange(-p, 1)[None, :]
    ext = _pad(b)
    return p * (_ratio(ext[:, :-1], t[i + p] - t[i])
                - _ratio(ext[:, 1:], t[i + p + 1] - t[i + 1]))


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
    traj = _plan_once(roadmap, corridor, obstacles, params, start_heading, start_speed,
                      end_speed)
    if traj.feasible or params.detour_rate <= 0 or not _steep(roadmap, params.detour_rate):
        return traj
    detour = detour_roadmap(roadmap, corridor, params.detour_rate)
    if detour is None:
        return traj
    other = _plan_once(detour, corridor, obstacles, params, start_heading, start_speed,
                       end_speed)
    log.debug("level 2's path gives no feasible curve; detour feasible: %s", other.feasible)
    return other if other.feasible else traj


def _steep(roadmap: Roadmap, rate: float) -> bool:
    """Whether level 2's path changes its lateral offset faster than ``rate`` somewhere
    (only then can :func:`detour_roadmap` find a path a curve follows better)."""
    ds = np.diff(np.asarray(roadmap.s, dtype=float))
    dl = np.abs(np.diff(np.asarray(roadmap.l, dtype=float)))
    return bool(np.any(dl > rate * np.maximum(ds, 1e-9) + 1e-9))


def _plan_once(roadmap: Roadmap, corridor: Corridor, obstacles: Obstacles,
               params: TrajectoryParams, start_heading: float | None, start_speed: float,
               end_speed: float | None) -> Trajectory:
    """:func:`plan_trajectory` along the roadmap's chosen path."""
    rp = roadmap.params
    pool, counts = _control_points(roadmap, corridor, start_heading, params, start_speed)
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
    # from the vehicle's position as far as the bands allow
    cap = int(np.searchsorted(polyline_stations(verts), params.max_control_spacing
                              - float(np.hypot(*(verts[0] - start))), side="right")) - 1
    if cap >= 0:
        first = max(first, _farthest(start, -1, cap, verts, *lines))
    kept = first + band_simplify(verts[first:], *(a[first:] for a in lines))
    if start_heading is None:
        direction = verts[first] - start
    else:
        direction = np.array([np.cos(start_heading), np.sin(start_heading)])
    norm = float(np.hypot(*direction))
    if norm <= 1e-12:
        raise TrajectoryError("the roadmap's points coincide with the start: no curve")
    heading_point = start + head_len * direction / norm
    # long legs get extra control points on them (they stay within the bands)
    vst = vs[ahead]
    extra_xy, extra_s = [], []
    for a, b in zip(np.concatenate(([first], kept[:-1])).tolist(), kept.tolist(), strict=True):
        pieces = int(np.ceil(np.hypot(*(verts[b] - verts[a])) / params.max_control_spacing
                             - 1e-9))
        if a == b or pieces <= 1:
            continue
        f = np.arange(1, pieces) / pieces
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
    inside = (frm >= 0) & (frm < nb)
    fv = np.where(inside[None], vid[:-1][:, np.clip(frm, 0, nb - 1)], -1)
    tv = vid[1:][:, :, None]
    arcs = np.asarray(roadmap.arcs, dtype=np.int64)
    keys = np.sort(arcs[:, 0] * n_v + arcs[:, 1])
    key = fv * n_v + tv
    at = np.minimum(np.searchsorted(keys, key), len(keys) - 1)
    ok = (fv >= 0) & (tv >= 0) & (keys[at] == key)
    ok &= np.abs(dlt)[None, None, :] * h <= rate * ds[:, None, None] + 1e-9
    lat_cost = (dlt[None, :] * h) ** 2 / ds[:, None]  # (lines - 1, 2r + 1)
    frm_c = np.clip(frm, 0, nb - 1)
    # start: the source vertex, at the vehicle's offset
    src = int(roadmap.path[0])
    l_start = float(corridor.to_sl(np.asarray(roadmap.start_xy, dtype=float)[None])[0, 1])
    cost = np.where(vid[0] == src, np.abs(grid - l_start), np.inf)
    cost = np.where(cost <= np.min(cost) + 1e-9, penalty[0], np.inf)
    back = np.zeros((n_lines, nb), dtype=np.int64)
    rows = np.arange(nb)
    for k in range(n_lines - 1):
        cand = np.where(ok[k], cost[frm_c] + lat_cost[k], np.inf)
        j = np.argmin(cand, axis=1)
        cost = cand[rows, j] + penalty[k + 1]
        back[k + 1] = frm_c[rows, j]
    if not np.isfinite(cost).any():
        return None
    bins = np.zeros(n_lines, dtype=np.int64)
    bins[-1] = int(np.argmin(cost))
    for k in range(n_lines - 1, 0, -1):
        bins[k - 1] = back[k, bins[k]]
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
    on = np.abs(np.einsum("kd,kd->k", origin[ks] - p, tangent[ks])) < 1e-9
    lo[on], hi[on] = -np.inf, np.inf
    # bounds from the lines strictly before each candidate
    low = np.maximum.accumulate(np.concatenate(([-np.inf], lo[:-1])))
    high = np.minimum.accumulate(np.concatenate(([np.inf], hi[:-1])))
    good = (th >= low - tol) & (th <= high + tol)
    good[0] = True
    if good.all():
        return cap
    return int(i + np.argmin(good))


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
        span_len = sliding_window_view(padded, k + 2)[:n - k].max(axis=1)
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
        cols = self.first[:, None] + np.arange(self.k + 1)[None, :]
        gathered = c[cols]
        return tuple(np.einsum("mk,mkd->md", self.basis[nu], gathered)  # type: ignore
                     for nu in range(3))


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
        b = self.basis[:, idx, r]  # (3, q)
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
