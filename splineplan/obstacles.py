"""Obstacles: static polygons on the road, in one array form.

SUMO's stopped vehicles become oriented rectangles (:meth:`Obstacles.from_boxes`); anything
else is a polygon (:meth:`Obstacles.from_polygons`). All polygons are stored as one
``(m, 2)`` vertex array with ``(k + 1,)`` offsets, so that distance queries vectorise.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Literal

import numpy as np
from numba import njit
from numpy.typing import ArrayLike, NDArray

from splineplan.errors import GeometryError
from splineplan.geometry import (
    FloatArray,
    box_corners,
    distance_to_polygons,
    kernel_floats,
    kernel_ints,
)

#: Distance [m] from the line between its neighbours below which a point of a swept hull
#: (:meth:`Obstacles.elongated`) counts as on that line and is left out: the corners of
#: a box shifted along its own axis, which only rounding moves off the hull's sides.
HULL_TOLERANCE = 1e-9


@dataclass(frozen=True, eq=False)
class Obstacles:
    """A set of static polygonal obstacles.

    Attributes
    ----------
    vertices
        All polygons' vertices ``(m, 2)`` [m], concatenated, counter-clockwise.
    offsets
        ``(k + 1,)``: polygon ``i`` is ``vertices[offsets[i]:offsets[i + 1]]``.
    ids
        A name per polygon (SUMO vehicle id, or ``"obstacle<i>"``).
    """

    vertices: FloatArray
    offsets: NDArray[np.int64]
    ids: tuple[str, ...] = ()
    _bbox: FloatArray = field(init=False, repr=False)

    def __post_init__(self) -> None:
        k = len(self.offsets) - 1
        if k < 0 or self.offsets[0] != 0 or self.offsets[-1] != len(self.vertices):
            raise GeometryError("obstacle offsets do not match the vertices")
        if not self.ids:
            object.__setattr__(self, "ids", tuple(f"obstacle{i}" for i in range(k)))
        if len(self.ids) != k:
            raise GeometryError(f"{len(self.ids)} ids for {k} obstacles")
        self.vertices.setflags(write=False)
        self.offsets.setflags(write=False)
        bbox = np.empty((k, 4))
        if k and np.all(np.diff(self.offsets) > 0):
            starts = self.offsets[:-1]
            bbox[:, :2] = np.minimum.reduceat(self.vertices, starts, axis=0)
            bbox[:, 2:] = np.maximum.reduceat(self.vertices, starts, axis=0)
        else:
            for i in range(k):
                p = self.vertices[self.offsets[i]:self.offsets[i + 1]]
                bbox[i] = (*p.min(axis=0), *p.max(axis=0))
        bbox.setflags(write=False)
        object.__setattr__(self, "_bbox", bbox)

    @classmethod
    def empty(cls) -> Obstacles:
        """No obstacle."""
        return cls(np.zeros((0, 2)), np.zeros(1, dtype=np.int64))

    @classmethod
    def from_polygons(
        cls, polygons: Sequence[ArrayLike], ids: Sequence[str] | None = None
    ) -> Obstacles:
        """Obstacles from a list of polygons, each ``(k, 2)`` [m] with k >= 3, open or closed."""
        rings = []
        for i, poly in enumerate(polygons):
            name = f"'{ids[i]}'" if ids is not None and i < len(ids) else str(i)
            try:
                p = np.asarray(poly, dtype=float)
            except (TypeError, ValueError) as err:
                raise GeometryError(f"obstacle {name} is not an array of numbers") from err
            if p.ndim != 2 or p.shape[1] != 2:
                raise GeometryError(f"obstacle {name} must be a (k, 2) array, got {p.shape}")
            if not np.all(np.isfinite(p)):
                raise GeometryError(f"obstacle {name} has non-finite coordinates")
            if len(p) > 3 and np.allclose(p[0], p[-1]):
                p = p[:-1]
            if len(p) < 3:
                raise GeometryError(f"obstacle {name} needs at least 3 vertices, got {len(p)}")
            area2 = np.sum(p[:, 0] * np.roll(p[:, 1], -1) - np.roll(p[:, 0], -1) * p[:, 1])
            if abs(area2) < 1e-12:
                raise GeometryError(f"obstacle {name} has zero area")
            rings.append(p if area2 > 0 else p[::-1])
        if not rings:
            return cls.empty() if not ids else cls._fail_ids(ids)
        offsets = np.concatenate(([0], np.cumsum([len(r) for r in rings]))).astype(np.int64)
        return cls(np.concatenate(rings), offsets, tuple(ids) if ids is not None else ())

    @classmethod
    def from_boxes(
        cls,
        positions: ArrayLike,
        headings: ArrayLike,
        lengths: ArrayLike,
        widths: ArrayLike,
        *,
        reference: Literal["center", "front"] = "center",
        ids: Sequence[str] | None = None,
    ) -> Obstacles:
        """Oriented rectangles.

        Parameters
        ----------
        positions
            ``(k, 2)`` [m]: the centre, or with ``reference="front"`` the middle of the front
            bumper (SUMO's vehicle position).
        headings
            ``(k,)`` [rad], counter-clockwise from east (see
            :func:`splineplan.geometry.heading_from_sumo_angle`).
        lengths, widths
            ``(k,)`` [m], positive.
        """
        pos = np.asarray(positions, dtype=float).reshape(-1, 2)
        k = len(pos)
        head = np.broadcast_to(np.asarray(headings, dtype=float), (k,))
        lng = np.broadcast_to(np.asarray(lengths, dtype=float), (k,))
        wid = np.broadcast_to(np.asarray(widths, dtype=float), (k,))
        if not (np.all(np.isfinite(pos)) and np.all(np.isfinite(head))):
            raise GeometryError("box positions and headings must be finite")
        if np.any(lng <= 0) or np.any(wid <= 0):
            raise GeometryError("box lengths and widths must be positive")
        if reference == "front":
            pos = pos - (lng / 2.0)[:, None] * np.column_stack((np.cos(head), np.sin(head)))
        elif reference != "center":
            raise GeometryError(f"reference must be 'center' or 'front', not {reference!r}")
        if k == 0:
            return cls.empty()
        corners = box_corners(pos, head, lng, wid)
        offsets = np.arange(0, 4 * k + 1, 4, dtype=np.int64)
        return cls(corners.reshape(-1, 2), offsets, tuple(ids) if ids is not None else ())

    @staticmethod
    def _fail_ids(ids: Sequence[str]) -> Obstacles:
        raise GeometryError(f"{len(ids)} ids for 0 obstacles")

    def __len__(self) -> int:
        return len(self.offsets) - 1

    def __add__(self, other: Obstacles) -> Obstacles:
        offsets = np.concatenate((self.offsets, other.offsets[1:] + len(self.vertices)))
        return Obstacles(np.concatenate((self.vertices, other.vertices)), offsets,
                         self.ids + other.ids)

    def polygon(self, i: int) -> FloatArray:
        """Vertices ``(k, 2)`` of obstacle ``i``."""
        return self.vertices[self.offsets[i]:self.offsets[i + 1]]

    def polygons(self) -> list[FloatArray]:
        """Every obstacle's vertices, as a list of ``(k, 2)`` arrays."""
        return [self.polygon(i) for i in range(len(self))]

    @property
    def bbox(self) -> FloatArray:
        """Axis-aligned bounding boxes ``(k, 4)``: xmin, ymin, xmax, ymax [m]."""
        return self._bbox

    def subset(self, mask: ArrayLike) -> Obstacles:
        """The obstacles selected by a boolean mask or index array."""
        idx = np.arange(len(self))[np.asarray(mask)]
        start = self.offsets[idx]
        count = self.offsets[idx + 1] - start
        offsets = np.concatenate(([0], np.cumsum(count))).astype(np.int64)
        take = np.arange(int(offsets[-1])) + np.repeat(start - offsets[:-1], count)
        return Obstacles(self.vertices[take], offsets, tuple(self.ids[i] for i in idx))

    def near(self, xy: ArrayLike, radius: float) -> Obstacles:
        """The obstacles whose bounding box comes within ``radius`` [m] of any point."""
        if len(self) == 0:
            return self
        hit = self.near_mask(xy, radius)
        return self if hit.all() else self.subset(hit)

    def near_mask(self, xy: ArrayLike, radius: float) -> NDArray[np.bool_]:
        """Per obstacle: whether its bounding box meets that of the points ``(n, 2)``
        grown by ``radius`` [m] (the test of :meth:`near`)."""
        pts = np.atleast_2d(np.asarray(xy, dtype=float))
        lo, hi = pts.min(axis=0) - radius, pts.max(axis=0) + radius
        b = self._bbox
        return np.asarray((b[:, 0] <= hi[0]) & (b[:, 2] >= lo[0]) & (b[:, 1] <= hi[1])
                          & (b[:, 3] >= lo[1]))

    def elongated(self, directions: ArrayLike, extra: float) -> Obstacles:
        """Each obstacle swept ``extra`` [m] both ways along its direction ``(k,)`` [rad].

        The Minkowski sum with a segment of length ``2 extra`` centred on the origin: the
        convex hull of the polygon shifted both ways (exact for convex polygons, larger
        for others), counter-clockwise. Level 2 uses it to leave
        room for the corners of a rectangular vehicle that it models as a disc.
        """
        head = np.broadcast_to(np.asarray(directions, dtype=float), (len(self),))
        if not (np.isfinite(extra) and extra >= 0):
            raise GeometryError(f"elongation must be >= 0, got {extra!r}")
        if extra == 0 or len(self) == 0:
            return self
        if not np.all(np.isfinite(head)):
            raise GeometryError("elongation directions must be finite")
        vert, offsets = _swept_hulls(
            kernel_floats(self.vertices[:, 0]),
            kernel_floats(self.vertices[:, 1]),
            kernel_ints(self.offsets), extra * np.cos(head),
            extra * np.sin(head))
        return Obstacles(vert, offsets, self.ids)

    def distance(self, xy: ArrayLike) -> FloatArray:
        """Distance [m] from each point ``(n, 2)`` to the nearest obstacle, 0 inside."""
        pts = np.atleast_2d(np.asarray(xy, dtype=float))
        if len(self) == 0:
            return np.full(len(pts), np.inf)
        return np.asarray(distance_to_polygons(pts, self.vertices, self.offsets).min(axis=1))


@njit(cache=True)
def _swept_hulls(vx: FloatArray, vy: FloatArray, offsets: NDArray[np.int64], sx: FloatArray,
                 sy: FloatArray) -> tuple[FloatArray,
                                          NDArray[np.int64]]:  # pragma: no cover - compiled
    """Convex hull of each polygon's vertices shifted by ``+-(sx, sy)`` [m]: vertices
    ``(m, 2)`` counter-clockwise, and offsets ``(k + 1,)`` (monotone chain; then the
    vertices within :data:`HULL_TOLERANCE` of the chord between their neighbours are
    left out, as Qhull merges them)."""
    k = len(offsets) - 1
    out = np.empty((2 * len(vx), 2))
    out_off = np.zeros(k + 1, dtype=np.int64)
    m = 0
    for i in range(k):
        a, b = offsets[i], offsets[i + 1]
        n = 2 * (b - a)
        px = np.empty(n)
        py = np.empty(n)
        for j in range(b - a):
            px[2 * j], py[2 * j] = vx[a + j] + sx[i], vy[a + j] + sy[i]
            px[2 * j + 1], py[2 * j + 1] = vx[a + j] - sx[i], vy[a + j] - sy[i]
        for j in range(1, n):  # insertion sort by (x, y)
            x, y = px[j], py[j]
            t = j
            while t > 0 and (px[t - 1] > x or (px[t - 1] == x and py[t - 1] > y)):
                px[t], py[t] = px[t - 1], py[t - 1]
                t -= 1
            px[t], py[t] = x, y
        hx = np.empty(2 * n)
        hy = np.empty(2 * n)
        h = 0
        for sweep in range(2):  # the lower chain left to right, then the upper back
            base = h
            for jj in range(n):
                j = jj if sweep == 0 else n - 1 - jj
                while h >= base + 2 and ((hx[h - 1] - hx[h - 2]) * (py[j] - hy[h - 2])
                                         - (hy[h - 1] - hy[h - 2]) * (px[j] - hx[h - 2])) <= 0:
                    h -= 1
                hx[h], hy[h] = px[j], py[j]
                h += 1
            h -= 1  # each chain's last point starts the other
        # points that only rounding lifts off a side (a box shifted along its own axis)
        j = 0
        while j < h and h > 3:
            a, c = (j - 1) % h, (j + 1) % h
            ax, ay, dx, dy = hx[a], hy[a], hx[c] - hx[a], hy[c] - hy[a]
            turn = (hx[j] - ax) * dy - (hy[j] - ay) * dx
            along = (hx[j] - ax) * dx + (hy[j] - ay) * dy
            if (abs(turn) > HULL_TOLERANCE * np.hypot(dx, dy) or along <= 0
                    or along >= dx * dx + dy * dy):
                j += 1
                continue
            for t in range(j, h - 1):
                hx[t], hy[t] = hx[t + 1], hy[t + 1]
            h -= 1
            j = 0
        for j in range(h):
            out[m, 0], out[m, 1] = hx[j], hy[j]
            m += 1
        out_off[i + 1] = m
    return out[:m].copy(), out_off
