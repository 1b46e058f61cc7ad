"""The vehicle's footprint against obstacles and road edges, vectorised over curve samples.

Level 3 checks each sample of a curve: the vehicle's rectangle, centred on the curve and
oriented along it, keeps the safety margin from every obstacle polygon (exact
rectangle-polygon distance, culled by bounding box) and from the road edges (its corners
and long-side midpoints in the frames of the corridor's reference segments, and the road
edges' inward vertices, which can come between those points, by exact rectangle-point
distance). A module of its own because both the repair of the first curve and the
optimiser's moves (:mod:`splineplan.optimiser`) and the final samples
(:mod:`splineplan.trajectory`) use it.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
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
    corners: tuple[FloatArray, ...] = field(init=False)  # stations, x, y, side (+1 left)

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
        to_left = (np.interp(f, st, left) - lat[:-1]).min(axis=0)
        to_right = (lat[:-1] - np.interp(f, st, right)).min(axis=0)
        # the edges' inward vertices, where the probes come within CORNER_BAND of an edge
        near = np.flatnonzero(np.minimum(to_left, to_right) < self.margin + CORNER_BAND)
        if len(near):
            vl, vr = self._corner_distance(xy[near], c[near], s[near], along[-1, near])
            to_left[near] = np.minimum(to_left[near], vl)
            to_right[near] = np.minimum(to_right[near], vr)
        if sides:
            return to_left, to_right
        return np.minimum(to_left, to_right), along[-1]

    def _corner_distance(self, xy: FloatArray, c: FloatArray, s: FloatArray,
                         station: FloatArray) -> tuple[FloatArray, FloatArray]:
        """Distance [m] from the footprints (centres ``xy``, headings' cosines and sines
        ``c``, ``s``, centres' stations) to the inward vertices of the left and of the
        right road edge, negative inside; ``inf`` where none is near."""
        left = np.full(len(xy), np.inf)
        right = np.full(len(xy), np.inf)
        cs, cx, cy, cside = self.corners
        reach = np.hypot(self.half_length, self.half_width) + self.margin + CORNER_BAND
        lo = np.searchsorted(cs, station - reach, side="left")
        hi = np.searchsorted(cs, station + reach, side="right")
        count = hi - lo
        if not count.any():
            return left, right
        js = np.repeat(np.arange(len(xy)), count)
        ks = np.arange(int(count.sum())) + np.repeat(lo - np.cumsum(count) + count, count)
        dx, dy = cx[ks] - xy[js, 0], cy[ks] - xy[js, 1]
        gu = np.abs(dx * c[js] + dy * s[js]) - self.half_length
        gv = np.abs(dy * c[js] - dx * s[js]) - self.half_width
        d = np.where((gu <= 0) & (gv <= 0), np.maximum(gu, gv),
                     np.hypot(np.maximum(gu, 0.0), np.maximum(gv, 0.0)))
        # js is sorted: the minimum over each sample's run, per side
        run = np.flatnonzero(np.concatenate(([True], js[1:] != js[:-1])))
        is_left = cside[ks] > 0
        left[js[run]] = np.minimum.reduceat(np.where(is_left, d, np.inf), run)
        right[js[run]] = np.minimum.reduceat(np.where(is_left, np.inf, d), run)
        return left, right

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
        # (flat edges' quotients, inf or nan or overflowing, are replaced just below)
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            t1 = (-h - a) / d
            t2 = (h - a) / d
        lo = np.where(flat, -np.inf, np.minimum(t1, t2))
        hi = np.where(flat, np.inf, np.maximum(t1, t2))
        np.maximum(t_in, lo, out=t_in)
        np.minimum(t_out, hi, out=t_out)
    crosses = (ok & (t_in <= t_out)).any(axis=0)
    # rectangle inside the polygon: its centre (the origin) by crossing number
    straddle = (v > 0) != (vb > 0)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        ucross = u - v * du / dv
    inside = (straddle & (ucross > 0)).sum(axis=0) % 2 == 1
    return np.asarray(crosses | inside)
