"""Corridor: a stretch of drivable road with a reference line and a Frenet frame.

A point of the corridor is (s, l): station s [m] along the reference line and lateral
offset l [m], positive to the left of the direction of travel. The drivable area at
station s is ``right(s) <= l <= left(s)``. No SUMO here: the SUMO adapter
(:mod:`splineplan.network`) builds corridors from routes with :meth:`Corridor.from_reference`.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numba import njit
from numpy.typing import ArrayLike, NDArray
from scipy.spatial import cKDTree

from splineplan.errors import GeometryError
from splineplan.geometry import (
    FloatArray,
    dedupe_polyline,
    kernel_floats,
    polyline_stations,
    resample_polyline,
)

#: Spacing [m] at which reference lines are resampled.
REFERENCE_SPACING = 0.5


#: Smallest cell [m] of the bucket grid that finds a point's nearest reference vertex.
GRID_CELL = 2.0
#: Rings of cells searched around a point before a k-d tree takes over (far points).
GRID_RINGS = 8

#: Offset [m] that stands for "no bound" in a corridor's keep offsets.
UNBOUNDED = 1e9


#: Room [m] beyond a corridor's sides below which its paved offsets count as none
#: (:meth:`Corridor.paved`).
PAVED_MIN = 0.05
#: Room [m] the car's front keeps from the end of a road that ends (a dead end, or a
#: scenario's last lanelet), where a plan stops there (:meth:`Corridor.short_of_end`).
ROAD_END_GAP = 0.3


@dataclass(frozen=True, eq=False)
class Corridor:
    """Drivable road stretch in a Frenet frame.

    Attributes
    ----------
    reference
        Reference line ``(n, 2)`` [m], resampled evenly.
    s
        Station of each reference vertex ``(n,)`` [m], from 0.
    left, right
        Lateral offsets ``(n,)`` [m] of the left and right road boundary at each station
        (``right < left``; usually ``right < 0 < left``).
    edges
        SUMO edge ids along the corridor, in order (empty where unknown).
    edge_starts
        Station ``(len(edges),)`` [m] at which each edge begins.
    offset
        Station [m] of this corridor's start on the whole route, for messages.
    keep_left, keep_right
        Lateral offsets ``(n,)`` [m] between which the vehicle's centre keeps (the lanes
        that lead on along the route, before a junction), :data:`UNBOUNDED` where the
        whole road will do; ``None``: nowhere bounded. Level 2 releases them around
        where they leave no passage. The footprint keeps to ``left``
        and ``right``.
    edge_ends
        Station ``(len(edges),)`` [m] at which each edge's own stretch ends: from there to
        the next edge's start the corridor crosses a junction (empty: unknown, no
        junctions).
    paved_left, paved_right
        Lateral offsets ``(n,)`` [m] of the paved area around the junctions where it
        reaches beyond ``left`` and ``right`` (SUMO's junction outline beside a turn's
        lanes), elsewhere equal to them; ``None``: none known. A plan keeps to ``left`` and
        ``right``, and takes this room only where no feasible curve does
        (:meth:`paved`).
    """

    reference: FloatArray
    s: FloatArray
    left: FloatArray
    right: FloatArray
    edges: tuple[str, ...] = ()
    edge_starts: FloatArray = field(default_factory=lambda: np.zeros(0))
    offset: float = 0.0
    keep_left: FloatArray | None = None
    keep_right: FloatArray | None = None
    edge_ends: FloatArray = field(default_factory=lambda: np.zeros(0))
    paved_left: FloatArray | None = None
    paved_right: FloatArray | None = None
    _grid: tuple[Any, ...] = field(init=False, repr=False)
    _heading: FloatArray = field(init=False, repr=False)
    _cos: FloatArray = field(init=False, repr=False)
    _sin: FloatArray = field(init=False, repr=False)
    _ref_x: FloatArray = field(init=False, repr=False)
    _ref_y: FloatArray = field(init=False, repr=False)
    _s: FloatArray = field(init=False, repr=False)
    #: what other modules derive from the corridor alone (see :meth:`derived`)
    _memo: dict[Any, Any] = field(init=False, repr=False)

    def __post_init__(self) -> None:
        if len(self.reference) < 2 or self.s[-1] <= 0:
            raise GeometryError("corridor needs a reference line of positive length")
        if np.any(self.left <= self.right):
            raise GeometryError(_no_width(self.s + self.offset, self.left, self.right))
        if len(self.edges) != len(self.edge_starts):
            raise GeometryError("corridor needs one start station per edge")
        if len(self.edge_ends) not in (0, len(self.edges)):
            raise GeometryError("corridor needs one end station per edge, or none")
        keeps = (self.keep_left, self.keep_right)
        if (keeps[0] is None) != (keeps[1] is None) or any(
                k is not None and k.shape != self.s.shape for k in keeps):
            raise GeometryError("corridor needs both keep offsets, one per station, or none")
        paved = (self.paved_left, self.paved_right)
        if (paved[0] is None) != (paved[1] is None) or any(
                p is not None and p.shape != self.s.shape for p in paved):
            raise GeometryError("corridor needs both paved offsets, one per station, or none")
        for name in ("reference", "s", "left", "right", "edge_starts", "keep_left",
                     "keep_right", "edge_ends", "paved_left", "paved_right"):
            if getattr(self, name) is not None:
                getattr(self, name).setflags(write=False)
        d = np.diff(self.reference, axis=0)
        object.__setattr__(self, "_heading", np.arctan2(d[:, 1], d[:, 0]))
        object.__setattr__(self, "_cos", np.cos(self._heading))
        object.__setattr__(self, "_sin", np.sin(self._heading))
        # writable contiguous copies for the compiled projection (one array type)
        object.__setattr__(self, "_ref_x", np.array(self.reference[:, 0], dtype=float))
        object.__setattr__(self, "_ref_y", np.array(self.reference[:, 1], dtype=float))
        object.__setattr__(self, "_s", np.array(self.s, dtype=float))
        # a bucket grid of the reference's vertices for nearest-vertex queries
        area = float(np.ptp(self._ref_x) * np.ptp(self._ref_y))
        cell = max(GRID_CELL, float(np.sqrt(area / (4.0 * len(self.reference)))))
        object.__setattr__(self, "_grid", (cell, *_grid_build(self._ref_x, self._ref_y, cell)))
        object.__setattr__(self, "_memo", {})

    def derived(self, key: Any, make: Callable[[], Any]) -> Any:
        """What ``make()`` derives from the corridor alone, made once per ``key`` and kept
        with the corridor (which is immutable); callers must not change it."""
        if key not in self._memo:
            self._memo[key] = make()
        return self._memo[key]

    # -- construction -------------------------------------------------------------------
    @classmethod
    def from_boundaries(
        cls,
        left: ArrayLike,
        right: ArrayLike,
        *,
        edges: tuple[str, ...] = (),
        edge_starts: ArrayLike = (),
        offset: float = 0.0,
        reference: ArrayLike | None = None,
    ) -> Corridor:
        """Corridor between a left and a right boundary polyline, each ``(n, 2)`` [m].

        Both run in the direction of travel. The reference line is their midline, or
        ``reference`` ``(k, 2)`` where given; the boundaries' offsets are measured from it.
        """
        lb = _as_polyline(left, "left boundary")
        rb = _as_polyline(right, "right boundary")
        if reference is not None:
            mid = resample_polyline(_as_polyline(reference, "reference"), REFERENCE_SPACING)
        else:
            n = max(len(resample_polyline(lb, REFERENCE_SPACING)),
                    len(resample_polyline(rb, REFERENCE_SPACING)))
            lr = _resample_n(lb, n)
            rr = _resample_n(rb, n)
            mid = resample_polyline((lr + rr) / 2.0, REFERENCE_SPACING)
        ref_s = polyline_stations(mid)
        probe = cls(mid, ref_s, np.full(len(mid), 1e9), np.full(len(mid), -1e9))
        left_off = probe._offsets_of(resample_polyline(lb, REFERENCE_SPACING / 2))
        right_off = probe._offsets_of(resample_polyline(rb, REFERENCE_SPACING / 2))
        return cls(mid, ref_s, left_off, right_off, tuple(edges),
                   np.asarray(edge_starts, dtype=float).reshape(-1), offset)

    @classmethod
    def from_reference(
        cls,
        reference: ArrayLike,
        left: ArrayLike,
        right: ArrayLike,
        *,
        edges: tuple[str, ...] = (),
        edge_starts: ArrayLike = (),
        offset: float = 0.0,
    ) -> Corridor:
        """Corridor from a reference polyline ``(n, 2)`` and boundary offsets ``(n,)`` [m].

        ``left`` and ``right`` are the lateral offsets of the boundaries at the reference's
        vertices; they are interpolated when the line is resampled.
        """
        ref = np.asarray(reference, dtype=float)
        lo, ro = np.asarray(left, dtype=float), np.asarray(right, dtype=float)
        if ref.ndim != 2 or ref.shape[1] != 2 or lo.shape != (len(ref),) or ro.shape != lo.shape:
            raise GeometryError("reference must be (n, 2) and offsets (n,)")
        keep = np.concatenate(([True], np.hypot(*np.diff(ref, axis=0).T) > 1e-9))
        ref, lo, ro = ref[keep], lo[keep], ro[keep]
        s0 = polyline_stations(ref)
        mid = resample_polyline(ref, REFERENCE_SPACING)
        s = polyline_stations(mid)
        return cls(mid, s, np.interp(s, s0, lo), np.interp(s, s0, ro), tuple(edges),
                   np.asarray(edge_starts, dtype=float).reshape(-1), offset)

    # -- queries ------------------------------------------------------------------------
    @property
    def length(self) -> float:
        """Length [m] of the reference line."""
        return float(self.s[-1])

    def bounds_at(self, s: ArrayLike) -> tuple[FloatArray, FloatArray]:
        """Right and left boundary offsets [m] at stations ``s``."""
        s = np.asarray(s, dtype=float)
        return np.interp(s, self.s, self.right), np.interp(s, self.s, self.left)

    def keep_at(self, s: ArrayLike) -> tuple[FloatArray, FloatArray]:
        """Right and left offsets [m] between which the vehicle's centre keeps at stations
        ``s`` (:data:`UNBOUNDED` where unbounded)."""
        s = np.asarray(s, dtype=float)
        if self.keep_left is None or self.keep_right is None:
            return np.full(s.shape, -UNBOUNDED), np.full(s.shape, UNBOUNDED)
        return np.interp(s, self.s, self.keep_right), np.interp(s, self.s, self.keep_left)

    def heading_at(self, s: ArrayLike) -> FloatArray:
        """Heading [rad] of the reference line at stations ``s``."""
        i = self._segment_index(np.asarray(s, dtype=float))
        return self._heading[i]

    def to_xy(self, s: ArrayLike, l: ArrayLike) -> FloatArray:  # noqa: E741
        """Points ``(n, 2)`` [m] at stations ``s`` and lateral offsets ``l``."""
        s_arr, l_arr = np.broadcast_arrays(np.asarray(s, dtype=float), np.asarray(l, dtype=float))
        i = self._segment_index(s_arr)
        c, sn = self._cos[i], self._sin[i]
        t = s_arr - self.s[i]
        base = self.reference[i]
        x = base[..., 0] + t * c - l_arr * sn
        y = base[..., 1] + t * sn + l_arr * c
        return np.stack((x, y), axis=-1)

    def to_sl(self, xy: ArrayLike) -> FloatArray:
        """Stations and lateral offsets ``(n, 2)`` of points ``(n, 2)`` [m].

        Projects each point onto the nearest segment of the reference line; points beyond
        the ends are extrapolated along the end segments.
        """
        pts = np.atleast_2d(np.asarray(xy, dtype=float))
        px, py = kernel_floats(pts[:, 0]), kernel_floats(pts[:, 1])
        k = _grid_nearest(px, py, self._ref_x, self._ref_y, *self._grid, GRID_RINGS)
        far = np.flatnonzero(k < 0)
        if len(far):  # far from the road (or not a number): a k-d tree
            k[far] = cKDTree(self.reference).query(pts[far])[1]
        return _project_kernel(px, py, k, self._ref_x, self._ref_y, self._cos, self._sin,
                               self._s)

    def contains(self, xy: ArrayLike, margin: float = 0.0) -> np.ndarray:
        """Whether points ``(n, 2)`` lie on the road, at least ``margin`` [m] inside."""
        sl = self.to_sl(xy)
        r, lft = self.bounds_at(sl[:, 0])
        inside = (sl[:, 0] >= 0) & (sl[:, 0] <= self.length)
        return np.asarray(inside & (sl[:, 1] >= r + margin) & (sl[:, 1] <= lft - margin))

    def left_xy(self) -> FloatArray:
        """Left boundary polyline ``(n, 2)`` [m]."""
        return self.to_xy(self.s, self.left)

    def right_xy(self) -> FloatArray:
        """Right boundary polyline ``(n, 2)`` [m]."""
        return self.to_xy(self.s, self.right)

    def polygon(self) -> FloatArray:
        """Outline of the drivable area ``(k, 2)`` [m], counter-clockwise, not closed."""
        return np.concatenate((self.right_xy(), self.left_xy()[::-1]))

    def edge_at(self, s: float) -> str | None:
        """Id of the SUMO edge at station ``s`` [m] of this corridor, if known."""
        if not self.edges:
            return None
        i = int(np.searchsorted(self.edge_starts, s, side="right")) - 1
        return self.edges[max(i, 0)]

    def junction_at(self, s: float) -> tuple[str, str] | None:
        """The route edges ``(from, to)`` whose junction holds station ``s`` [m] (between
        the end of one edge's own stretch and the start of the next), else ``None``."""
        if len(self.edge_ends) == 0:
            return None
        i = int(np.searchsorted(self.edge_starts, s, side="right")) - 1
        if i < 0 or i + 1 >= len(self.edges) or s <= self.edge_ends[i]:
            return None
        return self.edges[i], self.edges[i + 1]

    def slice(self, s0: float, s1: float) -> Corridor:
        """Sub-corridor between stations ``s0`` and ``s1`` [m], stations restarting at 0."""
        s0, s1 = max(0.0, float(s0)), min(self.length, float(s1))
        if s1 - s0 <= 1e-6:
            raise GeometryError(f"empty corridor slice [{s0:.1f}, {s1:.1f}] m")
        inner = (self.s > s0) & (self.s < s1)
        ss = np.concatenate(([s0], self.s[inner], [s1]))
        ref = self.to_xy(ss, np.zeros_like(ss))
        r, lft = self.bounds_at(ss)
        keep = self.edge_starts < s1
        starts = np.maximum(self.edge_starts[keep] - s0, 0.0)
        ends = self.edge_ends[keep] - s0 if len(self.edge_ends) else self.edge_ends
        edges = tuple(e for e, k in zip(self.edges, keep, strict=True) if k)
        if len(starts) > 1:  # drop edges that ended before s0
            last_before = np.searchsorted(starts, 0.0, side="right") - 1
            starts, edges = starts[last_before:], edges[last_before:]
            ends = ends[last_before:] if len(ends) else ends
        kr, kl = ((None, None) if self.keep_left is None else self.keep_at(ss))
        pl = pr = None
        if self.paved_left is not None and self.paved_right is not None:
            pl, pr = np.interp(ss, self.s, self.paved_left), np.interp(ss, self.s, self.paved_right)
        return Corridor(ref, ss - s0, lft, r, edges, starts, self.offset + s0, kl, kr, ends,
                        pl, pr)

    def stop_before_end(self, front: float, least: float, gap: float = ROAD_END_GAP
                        ) -> float:
        """Station [m] at which a car whose front is ``front`` [m] ahead of its centre
        stops to keep its front ``gap`` [m] inside a road that ends with the corridor; the
        corridor's length where that would come at station ``least`` [m] or before (a
        car that close to the end gets the road up to it)."""
        cut = self.length - front - gap
        return cut if cut > least else self.length

    def short_of_end(self, front: float, least: float, gap: float = ROAD_END_GAP
                     ) -> Corridor:
        """The corridor of a road that ends, cut at :meth:`stop_before_end`."""
        cut = self.stop_before_end(front, least, gap)
        return self.slice(0.0, cut) if cut < self.length else self

    def extend_back(self, length: float) -> Corridor:
        """The corridor with ``length`` [m] more before its start, straight along its first
        segment with its first boundaries (stations restarting at 0 there; the first edge
        covers the extension): for a vehicle whose centre lies behind the start, as one
        that SUMO inserts on an edge shorter than itself."""
        if length <= 0.0:
            return self
        d = self.reference[1] - self.reference[0]
        back = self.reference[0] - float(length) * d / float(np.hypot(*d))
        ref = np.vstack((back[None], self.reference))
        ss = np.concatenate(([0.0], self.s + length))

        def ahead(a: FloatArray) -> FloatArray:  # the first value over the extension
            return np.concatenate((a[:1], a))

        kl = None if self.keep_left is None else ahead(self.keep_left)
        kr = None if self.keep_right is None else ahead(self.keep_right)
        starts = self.edge_starts + length
        if len(starts):
            starts[0] = 0.0
        ends = self.edge_ends + length if len(self.edge_ends) else self.edge_ends
        pl = None if self.paved_left is None else ahead(self.paved_left)
        pr = None if self.paved_right is None else ahead(self.paved_right)
        return Corridor(ref, ss, ahead(self.left), ahead(self.right), self.edges, starts,
                        self.offset - length, kl, kr, ends, pl, pr)

    def paved(self) -> Corridor | None:
        """The corridor widened to its paved offsets (``paved_left``, ``paved_right``),
        ``None`` where they add no room (by more than :data:`PAVED_MIN` anywhere).

        A junction's lanes can leave a turn too tight for a car where SUMO's paving
        around them does not: a planner that finds no feasible curve between ``left``
        and ``right`` may try this one."""
        wide: Corridor | None = self.derived("paved", self._widened)
        return wide

    def _widened(self) -> Corridor | None:
        """:meth:`paved`, made once."""
        pl, pr = self.paved_left, self.paved_right
        if pl is None or pr is None:
            return None
        lft, rgt = np.maximum(self.left, pl), np.minimum(self.right, pr)
        if not (np.any(lft - self.left > PAVED_MIN) or np.any(self.right - rgt > PAVED_MIN)):
            return None
        return Corridor(self.reference, self.s, lft, rgt, self.edges, self.edge_starts,
                        self.offset, self.keep_left, self.keep_right, self.edge_ends)

    def segments(self, length: float, overlap: float = 0.0) -> list[Corridor]:
        """The corridor cut into pieces of at most ``length`` [m] (the last may be shorter).

        Consecutive pieces share ``overlap`` [m].
        """
        if length <= overlap:
            raise GeometryError("segment length must exceed the overlap")
        n = max(1, int(np.ceil((self.length - overlap) / (length - overlap) - 1e-9)))
        step = (self.length - overlap) / n if n > 1 else self.length
        return [self.slice(i * step, min(i * step + step + overlap, self.length))
                for i in range(n)]

    # -- helpers ------------------------------------------------------------------------
    def _segment_index(self, s: np.ndarray) -> np.ndarray:
        # the segment holding each station, the end segments beyond the ends (searching
        # the inner stations gives 0 .. len(s) - 2 directly)
        return np.searchsorted(self.s[1:-1], s, side="right")

    def _offsets_of(self, boundary: FloatArray) -> FloatArray:
        sl = self.to_sl(boundary)
        order = np.argsort(sl[:, 0], kind="stable")
        return np.interp(self.s, sl[order, 0], sl[order, 1])


@njit(cache=True)
def _grid_build(rx: FloatArray, ry: FloatArray, cell: float
                ) -> tuple[float, float, int, int, NDArray[np.int64],
                           NDArray[np.int64]]:  # pragma: no cover - compiled
    """A bucket grid of points ``rx``, ``ry`` with square cells of ``cell`` [m]: its
    origin, size in cells, and per cell (row-major) the start of its points in ``order``."""
    x0, y0 = rx.min(), ry.min()
    nx = int((rx.max() - x0) / cell) + 1
    ny = int((ry.max() - y0) / cell) + 1
    key = np.empty(len(rx), dtype=np.int64)
    for v in range(len(rx)):
        key[v] = int((rx[v] - x0) / cell) * ny + int((ry[v] - y0) / cell)
    # sorted as floats (exact: cell numbers are far below 2**53): the same compiled sort as
    # the other loops', not a second one for integers
    order = np.argsort(key.astype(np.float64), kind="mergesort")
    start = np.zeros(nx * ny + 1, dtype=np.int64)
    for v in range(len(rx)):
        start[key[v] + 1] += 1
    return x0, y0, nx, ny, np.cumsum(start), order


@njit(cache=True)
def _grid_nearest(px: FloatArray, py: FloatArray, rx: FloatArray, ry: FloatArray,
                  cell: float, x0: float, y0: float, nx: int, ny: int,
                  start: NDArray[np.int64], order: NDArray[np.int64], rings: int
                  ) -> NDArray[np.int64]:  # pragma: no cover - compiled
    """Index of the nearest of the points ``rx``, ``ry`` (the lowest among equals) to
    each point, from their bucket grid (:func:`_grid_build`), searched ring by ring of
    cells around the point's cell; -1 where ``rings`` rings found none provably nearest."""
    out = np.full(len(px), -1, dtype=np.int64)
    for j in range(len(px)):
        if not (np.isfinite(px[j]) and np.isfinite(py[j])):
            continue
        fx, fy = (px[j] - x0) / cell, (py[j] - y0) / cell
        if not (-rings <= fx <= nx + rings and -rings <= fy <= ny + rings):
            continue
        cx, cy = int(np.floor(fx)), int(np.floor(fy))
        best, pick = np.inf, -1
        for r in range(rings + 1):
            for ix in range(max(cx - r, 0), min(cx + r, nx - 1) + 1):
                edge = abs(ix - cx) == r
                step = 1 if edge else 2 * r
                iy = cy - r
                while iy <= cy + r:
                    if 0 <= iy < ny:
                        c = ix * ny + iy
                        for q in range(start[c], start[c + 1]):
                            v = order[q]
                            d = (rx[v] - px[j]) ** 2 + (ry[v] - py[j]) ** 2
                            if d < best or (d == best and v < pick):
                                best, pick = d, v
                    iy += step
            # every point of the rings beyond lies at least r cells away
            if pick >= 0 and np.sqrt(best) <= r * cell:
                out[j] = pick
                break
    return out


@njit(cache=True)
def _project_kernel(px: FloatArray, py: FloatArray, nearest: NDArray[np.int64],
                    rx: FloatArray, ry: FloatArray, cos: FloatArray, sin: FloatArray,
                    st: FloatArray) -> FloatArray:  # pragma: no cover - compiled
    """Stations and offsets ``(n, 2)`` of points on the reference line (vertices ``rx``,
    ``ry`` at stations ``st``, segment directions ``cos``, ``sin``): of the two segments
    at each point's nearest vertex, the nearer; the end segments extend past the ends."""
    n = len(px)
    nseg = len(rx) - 1
    out = np.full((n, 2), np.nan)  # nan for a point that is not a number
    for j in range(n):
        best = np.inf
        for cand in (nearest[j] - 1, nearest[j]):
            i = min(max(cand, 0), nseg - 1)
            dx, dy = px[j] - rx[i], py[j] - ry[i]
            along = dx * cos[i] + dy * sin[i]
            lat = -dx * sin[i] + dy * cos[i]
            lo = -np.inf if i == 0 else 0.0
            hi = np.inf if i == nseg - 1 else st[i + 1] - st[i]
            t = min(max(along, lo), hi)
            dist = np.hypot(along - t, lat)
            if dist < best:
                best = dist
                out[j, 0] = st[i] + along
                out[j, 1] = lat
    return out


def _no_width(s: FloatArray, left: FloatArray, right: FloatArray) -> str:
    """Why a corridor with ``left <= right`` somewhere has no room, and where."""
    bad = left <= right
    i = int(np.argmax(bad))
    if np.all(left < right):
        return ("the corridor's left and right sides are swapped: the left side lies "
                f"{right[i] - left[i]:.2f} m right of the right side at station {s[i]:.1f} m "
                "(give the left boundary as left, both in the direction of travel)")
    if np.any(left < right):
        j = i + int(np.argmax(~bad[i:])) if np.any(~bad[i:]) else len(s) - 1
        k = int(np.argmax(right - left))
        return (f"the corridor's left and right sides cross at station {s[i]:.1f} m: the "
                f"left side lies right of the right side from there to station {s[j]:.1f} m "
                f"(by {right[k] - left[k]:.2f} m at station {s[k]:.1f} m)")
    return f"the corridor has no width at station {s[i]:.1f} m (its sides meet there)"


def _as_polyline(points: ArrayLike, what: str) -> FloatArray:
    arr = np.asarray(points, dtype=float)
    if arr.ndim != 2 or arr.shape[1] != 2 or len(arr) < 2:
        raise GeometryError(f"{what} must be an (n, 2) array with n >= 2, got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise GeometryError(f"{what} has non-finite coordinates")
    arr = dedupe_polyline(arr)
    if len(arr) < 2:
        raise GeometryError(f"{what} has zero length")
    return arr


def _resample_n(points: FloatArray, n: int) -> FloatArray:
    s = polyline_stations(points)
    t = np.linspace(0.0, s[-1], n)
    return np.column_stack((np.interp(t, s, points[:, 0]), np.interp(t, s, points[:, 1])))
