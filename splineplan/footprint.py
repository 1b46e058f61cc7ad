"""The vehicle's footprint against obstacles and road edges, at many curve samples at once.

Level 3 checks each sample of a curve: the vehicle's rectangle, centred on the curve and
oriented along it, keeps the safety margin from every obstacle polygon (exact
rectangle-polygon distance, culled by bounding box) and from the road edges (its corners
and long-side midpoints in the frames of the corridor's reference segments, and the road
edges' inward vertices, which can come between those points, by exact rectangle-point
distance). A module of its own because both the repair of the first curve and the
optimiser's moves (:mod:`splineplan.optimiser`) and the final samples
(:mod:`splineplan.trajectory`) use it.

The checks are loops over samples compiled with numba (cached on disk after the first
run): level 3 calls them a few thousand times per route on tens to hundreds of samples,
where array code spent most of its time in the overhead of small numpy calls.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numba import njit
from numpy.typing import NDArray
from scipy.ndimage import maximum_filter1d, minimum_filter1d

from splineplan.corridor import Corridor
from splineplan.geometry import FloatArray
from splineplan.obstacles import Obstacles
from splineplan.roadmap import RoadmapParams

#: Distance [m] beyond the safety margin within which obstacle clearance is computed exactly.
CLEARANCE_HORIZON = 2.0
#: Distance [m] beyond the safety margin within which the road clearance also counts the
#: road edges' inward vertices (a vertex between two probe points of the footprint comes
#: up to about 0.2 m closer than they do at a 40 degree corner of a lane).
CORNER_BAND = 1.0


@dataclass(frozen=True, eq=False)
class _Checker:
    """Footprint clearance of the vehicle at curve samples.

    The road check works in the frames of the reference line's segments (cached once:
    origins, stations, unit directions, boundary offsets); it needs an estimate of each
    centre's station, which the optimiser keeps per sample, so that no nearest-neighbour
    search runs per move.
    """

    corridor: Corridor
    half_length: float
    half_width: float
    margin: float
    vx: FloatArray  # (V,): x and y of the obstacles' vertices, polygon after polygon
    vy: FloatArray
    offsets: NDArray[np.int64]  # (K + 1,): polygon k's vertices are offsets[k]:offsets[k + 1]
    bbox: FloatArray  # (K, 4)
    body: FloatArray = field(init=False)  # (2, q) body-frame points: footprint, then centre
    frames: tuple[FloatArray, ...] = field(init=False)
    window: tuple[FloatArray, ...] = field(init=False)
    corners: tuple[FloatArray, ...] = field(init=False)  # stations, x, y, side (+1 left)

    def __post_init__(self) -> None:
        hl, hw = self.half_length, self.half_width
        pts = np.array([[-hl, -hw], [hl, -hw], [hl, hw], [-hl, hw], [0.0, -hw], [0.0, hw],
                        [0.0, 0.0]])
        object.__setattr__(self, "body", np.ascontiguousarray(pts.T))
        cor = self.corridor
        # writable copies: the compiled kernels take one array type
        st = np.array(cor.s, dtype=float)
        h = cor.heading_at(st[:-1])
        ref = np.asarray(cor.reference, dtype=float)
        left, right = np.array(cor.left, dtype=float), np.array(cor.right, dtype=float)
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
        # the road edges' vertices that point into the road (where an edge turns towards
        # it): the footprint's sides can meet them between the probe points
        found = []
        for side, line in ((1.0, cor.left_xy()), (-1.0, cor.right_xy())):
            d = np.diff(line, axis=0)
            turn_in = side * (d[:-1, 0] * d[1:, 1] - d[:-1, 1] * d[1:, 0]) > 1e-12
            j = np.flatnonzero(turn_in) + 1
            found.append((st[j], line[j, 0], line[j, 1], np.full(len(j), side)))
        cat = [np.concatenate(a) for a in zip(*found, strict=True)]
        order = np.argsort(cat[0], kind="stable")
        object.__setattr__(self, "corners", tuple(a[order] for a in cat))

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
        count = obstacles.offsets[sel + 1] - obstacles.offsets[sel]
        offsets = np.concatenate(([0], np.cumsum(count))).astype(np.int64)
        idx = np.repeat(obstacles.offsets[sel] - offsets[:-1], count) + np.arange(offsets[-1])
        verts = obstacles.vertices[idx]
        return cls(corridor, params.vehicle_length / 2.0, params.vehicle_width / 2.0,
                   params.safety_margin, np.ascontiguousarray(verts[:, 0]),
                   np.ascontiguousarray(verts[:, 1]), offsets, np.ascontiguousarray(b[sel]))

    def stations(self, xy: FloatArray) -> FloatArray:
        """Stations [m] of points ``(n, 2)`` on the reference line (exact projection)."""
        return np.asarray(self.corridor.to_sl(xy)[:, 0])

    def road(self, xy: FloatArray, heading: FloatArray, sc: FloatArray | None = None,
             sides: bool = False) -> tuple[FloatArray, FloatArray]:
        """Distance [m] of the footprint to the nearer road edge (negative: off the road),
        and the centres' stations [m]; with ``sides``, its distances to the left and to the
        right road edge instead.

        ``sc`` estimates the centres' stations (``None``: projected exactly). All footprint
        points are projected onto the line of the reference segment at that estimate, then
        measured in the frame of the segment at their own station (the reference is
        resampled finely, so one segment's frame is exact enough; past the ends, the end
        segments extend the road).
        """
        if sc is None:
            sc = self.stations(xy)
        to_left, to_right, station = _road_kernel(
            *_xyh(xy, heading), np.asarray(sc, dtype=float), *self._road_args())
        if sides:
            return to_left, to_right
        return np.minimum(to_left, to_right), station

    def slack(self, xy: FloatArray, heading: FloatArray, sc: FloatArray | None = None
              ) -> tuple[FloatArray, FloatArray]:
        """Footprint clearance [m] beyond the safety margin (negative: too close), and the
        centres' stations [m] (see :meth:`road`)."""
        if sc is None:
            sc = self.stations(xy)
        return _slack_kernel(*_xyh(xy, heading), np.asarray(sc, dtype=float),
                             *self._road_args(), *self.window, *self._obstacle_args())

    def obstacles(self, xy: FloatArray, heading: FloatArray,
                  horizon: float = CLEARANCE_HORIZON, cull: bool = False) -> FloatArray:
        """Distance [m] of the footprint to the nearest obstacle, ``inf`` beyond
        ``margin + horizon`` (obstacles are culled by bounding box; with ``cull``, also
        those separated by more than that along the footprint's axes, so that ``inf``
        may stand for any distance beyond ``margin + horizon``)."""
        return _obstacle_kernel(*_xyh(xy, heading), *self._obstacle_args(), self.half_length,
                                self.half_width, self.margin, float(horizon), bool(cull))

    def _road_args(self) -> tuple[Any, ...]:
        reach = np.hypot(self.half_length, self.half_width) + self.margin + CORNER_BAND
        return (*self.frames, *self.body, *self.corners, self.half_length, self.half_width,
                self.margin, self.margin + CORNER_BAND, reach)

    def _obstacle_args(self) -> tuple[Any, ...]:
        return self.vx, self.vy, self.offsets, self.bbox


def _xyh(xy: FloatArray, heading: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
    return (np.ascontiguousarray(xy[:, 0], dtype=float),
            np.ascontiguousarray(xy[:, 1], dtype=float),
            np.ascontiguousarray(heading, dtype=float))


# ---- compiled kernels: loops over samples, one call per check ---------------------------
@njit(cache=True)
def _upper(a: FloatArray, x: float) -> int:  # pragma: no cover - compiled
    """``np.searchsorted(a, x, side="right")`` for a sorted ``a``."""
    lo, hi = 0, len(a)
    while lo < hi:
        mid = (lo + hi) // 2
        if a[mid] <= x:
            lo = mid + 1
        else:
            hi = mid
    return lo


@njit(cache=True)
def _lower(a: FloatArray, x: float) -> int:  # pragma: no cover - compiled
    """``np.searchsorted(a, x, side="left")`` for a sorted ``a``."""
    lo, hi = 0, len(a)
    while lo < hi:
        mid = (lo + hi) // 2
        if a[mid] < x:
            lo = mid + 1
        else:
            hi = mid
    return lo


@njit(cache=True)
def _segment(st: FloatArray, s: float, guess: int = -1) -> int:  # pragma: no cover
    """Reference segment holding station ``s`` (``st``: the vertices' stations), the end
    segments beyond the ends: ``np.searchsorted(st[1:-1], s, side="right")``. From a
    ``guess`` nearby, a few steps of walking; else a binary search."""
    last = len(st) - 2
    if 0 <= guess <= last:
        i = guess
        for _ in range(8):
            if i > 0 and s < st[i]:
                i -= 1
            elif i < last and s >= st[i + 1]:
                i += 1
            else:
                return i
    return _upper(st[1:-1], s)


@njit(cache=True)
def _interp_near(x: float, xp: FloatArray, fp: FloatArray, guess: int) -> float:
    """``np.interp`` at one point, searching from the interval ``guess`` nearby."""
    n = len(xp)
    if x <= xp[0]:
        return float(fp[0])
    if x >= xp[n - 1]:
        return float(fp[n - 1])
    k = _segment(xp, x, guess)
    return float((fp[k + 1] - fp[k]) / (xp[k + 1] - xp[k]) * (x - xp[k]) + fp[k])


@njit(cache=True)
def _road_one(x: float, y: float, h: float, sc: float, st: FloatArray, rx: FloatArray,
              ry: FloatArray, hc: FloatArray, hs: FloatArray, left: FloatArray,
              right: FloatArray, bu: FloatArray, bv: FloatArray, cs: FloatArray,
              cx: FloatArray, cy: FloatArray, cside: FloatArray, hl: float, hw: float,
              band: float, reach: float, guess: int
              ) -> tuple[float, float, float]:  # pragma: no cover - compiled
    """Footprint of one pose to the left and right road edges [m], and its station [m]
    (see :meth:`_Checker.road`; ``guess``: a reference segment near station ``sc``)."""
    c, s = np.cos(h), np.sin(h)
    i0 = _segment(st, sc, guess)
    to_left = to_right = np.inf
    station = sc
    for p in range(len(bu)):
        px = (x + c * bu[p]) - s * bv[p]
        py = (y + s * bu[p]) + c * bv[p]
        est = st[i0] + ((px - rx[i0]) * hc[i0] + (py - ry[i0]) * hs[i0])
        i = _segment(st, est, i0)
        dx, dy = px - rx[i], py - ry[i]
        along = st[i] + dx * hc[i] + dy * hs[i]
        lat = dy * hc[i] - dx * hs[i]
        if p == len(bu) - 1:  # the centre
            station = along
        else:
            to_left = min(to_left, _interp_near(along, st, left, i) - lat)
            to_right = min(to_right, lat - _interp_near(along, st, right, i))
    if min(to_left, to_right) < band:
        # the edges' inward vertices near the centre's station, by rectangle-point distance
        for k in range(_lower(cs, station - reach), _upper(cs, station + reach)):
            dx, dy = cx[k] - x, cy[k] - y
            gu = abs(dx * c + dy * s) - hl
            gv = abs(dy * c - dx * s) - hw
            inside = gu <= 0 and gv <= 0
            d = max(gu, gv) if inside else np.hypot(max(gu, 0.0), max(gv, 0.0))
            if cside[k] > 0:
                to_left = min(to_left, d)
            else:
                to_right = min(to_right, d)
    return to_left, to_right, station


@njit(cache=True)
def _road_kernel(x: FloatArray, y: FloatArray, h: FloatArray, sc: FloatArray, st: FloatArray,
                 rx: FloatArray, ry: FloatArray, hc: FloatArray, hs: FloatArray,
                 left: FloatArray, right: FloatArray, bu: FloatArray, bv: FloatArray,
                 cs: FloatArray, cx: FloatArray, cy: FloatArray, cside: FloatArray,
                 hl: float, hw: float, margin: float, band: float, reach: float
                 ) -> tuple[FloatArray, FloatArray, FloatArray]:  # pragma: no cover
    """:meth:`_Checker.road` for each pose: to the left edge, to the right, stations."""
    n = len(x)
    to_left, to_right, station = np.empty(n), np.empty(n), np.empty(n)
    i = -1  # the previous sample's segment: samples run along the curve
    for j in range(n):
        i = _segment(st, sc[j], i)
        to_left[j], to_right[j], station[j] = _road_one(
            x[j], y[j], h[j], sc[j], st, rx, ry, hc, hs, left, right, bu, bv, cs, cx, cy,
            cside, hl, hw, band, reach, i)
    return to_left, to_right, station


@njit(cache=True)
def _slack_kernel(x: FloatArray, y: FloatArray, h: FloatArray, sc: FloatArray,
                  st: FloatArray, rx: FloatArray, ry: FloatArray, hc: FloatArray,
                  hs: FloatArray, left: FloatArray, right: FloatArray, bu: FloatArray,
                  bv: FloatArray, cs: FloatArray, cx: FloatArray, cy: FloatArray,
                  cside: FloatArray, hl: float, hw: float, margin: float, band: float,
                  reach: float, lmin: FloatArray, rmax: FloatArray, turn: FloatArray,
                  seg_heading: FloatArray, vx: FloatArray, vy: FloatArray,
                  offsets: NDArray[np.int64], bbox: FloatArray
                  ) -> tuple[FloatArray, FloatArray]:  # pragma: no cover - compiled
    """:meth:`_Checker.slack`: clearance beyond the margin [m] and stations [m]."""
    n = len(x)
    road = np.empty(n)
    station = np.empty(n)
    i = -1  # the previous sample's segment: samples run along the curve
    for j in range(n):
        # the centre in the frame of the reference segment at its station (from the
        # estimate, one step of refinement)
        s_new = sc[j]
        dx = dy = 0.0
        for _ in range(2):
            i = _segment(st, s_new, i)
            dx, dy = x[j] - rx[i], y[j] - ry[i]
            s_new = st[i] + dx * hc[i] + dy * hs[i]
        lat = dy * hc[i] - dx * hs[i]
        # clearly on the road (a lower bound of the clearance is above the margin): no
        # exact check of the footprint
        dh = h[j] - seg_heading[i]
        ext = (hl * abs(np.sin(dh)) + hw * abs(np.cos(dh))
               + (abs(lat) + hl + hw) * turn[i] + 0.05)
        r = min(lmin[i] - lat, lat - rmax[i]) - ext
        if r < margin + 1e-6:
            tl, tr, s_new = _road_one(x[j], y[j], h[j], sc[j], st, rx, ry, hc, hs, left,
                                      right, bu, bv, cs, cx, cy, cside, hl, hw, band, reach,
                                      i)
            r = min(tl, tr)
        road[j] = r
        station[j] = s_new
    near = _obstacle_kernel(x, y, h, vx, vy, offsets, bbox, hl, hw, margin, 0.0, True)
    return np.minimum(near, road) - margin, station


@njit(cache=True)
def _obstacle_kernel(x: FloatArray, y: FloatArray, h: FloatArray, vx: FloatArray,
                     vy: FloatArray, offsets: NDArray[np.int64], bbox: FloatArray,
                     hl: float, hw: float, margin: float, horizon: float, cull: bool
                     ) -> FloatArray:  # pragma: no cover - compiled
    """:meth:`_Checker.obstacles`: each pose's footprint to the nearest obstacle [m]."""
    n = len(x)
    out = np.full(n, np.inf)
    k = len(offsets) - 1
    if k == 0:
        return out
    r = np.hypot(hl, hw) + margin + horizon
    gap = margin + horizon
    u = np.empty(int(np.max(offsets[1:] - offsets[:-1])))
    v = np.empty_like(u)
    for j in range(n):
        c, s = np.cos(h[j]), np.sin(h[j])
        for o in range(k):
            if not (bbox[o, 0] <= x[j] + r and bbox[o, 2] >= x[j] - r
                    and bbox[o, 1] <= y[j] + r and bbox[o, 3] >= y[j] - r):
                continue
            a0, m = offsets[o], offsets[o + 1] - offsets[o]
            for q in range(m):
                ex, ey = vx[a0 + q] - x[j], vy[a0 + q] - y[j]
                u[q] = ex * c + ey * s
                v[q] = ey * c - ex * s
            if cull and not (u[:m].min() < hl + gap and u[:m].max() > -hl - gap
                             and v[:m].min() < hw + gap and v[:m].max() > -hw - gap):
                continue
            out[j] = min(out[j], _rect_polygon_distance(u[:m], v[:m], hl, hw))
    return out


@njit(cache=True)
def _rect_polygon_distance(u: FloatArray, v: FloatArray, hl: float, hw: float
                           ) -> float:  # pragma: no cover - compiled
    """Distance [m] between the rectangle ``|u| <= hl``, ``|v| <= hw`` and a polygon given
    by its vertices ``u``, ``v`` ``(V,)`` in the rectangle's frame, 0 on overlap."""
    m = len(u)
    best = np.inf
    crosses = False
    winding = 0
    meet = u.min() <= hl and u.max() >= -hl and v.min() <= hw and v.max() >= -hw
    for a in range(m):
        b = a + 1 if a + 1 < m else 0
        # the vertex to the filled rectangle
        gu, gv = max(abs(u[a]) - hl, 0.0), max(abs(v[a]) - hw, 0.0)
        best = min(best, gu * gu + gv * gv)
        # the rectangle's corners to the edge a-b
        du, dv = u[b] - u[a], v[b] - v[a]
        seg2 = du * du + dv * dv
        inv = 1.0 / seg2 if seg2 > 0 else 1.0
        for cu, cv in ((-hl, -hw), (hl, -hw), (hl, hw), (-hl, hw)):
            wu, wv = cu - u[a], cv - v[a]
            t = min(max((wu * du + wv * dv) * inv, 0.0), 1.0)
            eu, ev = t * du - wu, t * dv - wv
            best = min(best, eu * eu + ev * ev)
        if not meet:
            continue
        # the edge crossing the rectangle (Liang-Barsky clipping)
        t_in, t_out, ok = 0.0, 1.0, True
        for p0, d, lim in ((u[a], du, hl), (v[a], dv, hw)):
            if abs(d) < 1e-15:
                ok = ok and abs(p0) <= lim
            else:
                t1, t2 = (-lim - p0) / d, (lim - p0) / d
                t_in = max(t_in, min(t1, t2))
                t_out = min(t_out, max(t1, t2))
        crosses = crosses or (ok and t_in <= t_out)
        # the rectangle's centre inside the polygon, by crossing number
        if (v[a] > 0) != (v[b] > 0) and u[a] - v[a] * du / dv > 0:
            winding += 1
    if meet and (crosses or winding % 2 == 1):
        return 0.0
    return float(np.sqrt(best))
