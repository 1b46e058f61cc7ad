"""Maps as images: a road segment drawn in an image becomes a corridor and obstacles.

Light pixels are road, dark pixels are obstacles or off-road (luminance below a threshold;
transparent pixels count as dark). Coordinates are in metres, x to the right and y up from
the image's bottom-left corner; pixel ``(row, col)`` (row 0 at the top) covers
``x in [col, col + 1] * scale`` and ``y in [H - 1 - row, H - row] * scale``.

The road runs from the left edge to the right edge: it is the largest 4-connected light
area that touches both, and it must meet every column once (an x-monotone road; a road that
turns back on itself is not supported). Its top and bottom in each column, bridged over
notches and smoothed, give the left and right boundaries (left of the direction of travel
is up; the corridor lies ``BOUNDARY_INSET`` inside them). Every dark pixel between them is
an obstacle; obstacles are unions of axis-aligned rectangles that cover their pixels
exactly (or, with ``merge_tolerance``, a few road pixels more, never fewer).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from os import PathLike
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import ndimage

from splineplan.corridor import Corridor
from splineplan.errors import GeometryError, ParameterError, ScenarioError
from splineplan.geometry import FloatArray
from splineplan.obstacles import Obstacles

log = logging.getLogger(__name__)

BoolArray = NDArray[np.bool_]

#: 4-connectivity: the ego cannot squeeze between two diagonal dark pixels.
_FOUR = ndimage.generate_binary_structure(2, 1)
_EIGHT = ndimage.generate_binary_structure(2, 2)


@dataclass(frozen=True, eq=False)
class ImageMap:
    """A road segment read from an image.

    Attributes
    ----------
    free
        Light pixels ``(H, W)``, row 0 at the top of the image.
    road
        The road area ``(H, W)``: the light component joining the left and right edges.
    scale
        Size [m] of a pixel.
    corridor
        The road as a corridor, travelled from left to right.
    obstacles
        Dark pixels between the road's boundaries, as rectangles [m].
    blob_of
        For each obstacle rectangle, the index of the dark blob (8-connected) it belongs to.
    """

    free: BoolArray
    road: BoolArray
    scale: float
    corridor: Corridor
    obstacles: Obstacles
    blob_of: NDArray[np.int64]

    @property
    def shape(self) -> tuple[int, int]:
        """Image size in pixels: rows, columns."""
        return (int(self.free.shape[0]), int(self.free.shape[1]))

    @property
    def extent(self) -> tuple[float, float, float, float]:
        """Image extent [m] as (xmin, xmax, ymin, ymax), for ``imshow``."""
        h, w = self.shape
        return (0.0, w * self.scale, 0.0, h * self.scale)

    @property
    def n_blobs(self) -> int:
        """Number of dark blobs on the road."""
        return int(self.blob_of.max()) + 1 if len(self.blob_of) else 0

    def to_pixel(self, xy: ArrayLike) -> NDArray[np.int64]:
        """Pixel ``(n, 2)`` as (row, col) holding points ``(n, 2)`` [m]; may lie outside."""
        pts = np.atleast_2d(np.asarray(xy, dtype=float))
        col = np.floor(pts[:, 0] / self.scale).astype(np.int64)
        row = self.shape[0] - 1 - np.floor(pts[:, 1] / self.scale).astype(np.int64)
        return np.column_stack((row, col))

    def to_xy(self, rows: ArrayLike, cols: ArrayLike) -> FloatArray:
        """Centres ``(n, 2)`` [m] of pixels given by row and column."""
        r = np.asarray(rows, dtype=float).reshape(-1)
        c = np.asarray(cols, dtype=float).reshape(-1)
        return np.column_stack(((c + 0.5) * self.scale, (self.shape[0] - 0.5 - r) * self.scale))

    def on_road(self, xy: ArrayLike) -> NDArray[np.bool_]:
        """Whether points ``(n, 2)`` [m] fall on a road pixel (False outside the image)."""
        rc = self.to_pixel(xy)
        h, w = self.shape
        inside = (rc[:, 0] >= 0) & (rc[:, 0] < h) & (rc[:, 1] >= 0) & (rc[:, 1] < w)
        out = np.zeros(len(rc), dtype=bool)
        out[inside] = self.road[rc[inside, 0], rc[inside, 1]]
        return out

    def default_start(self) -> FloatArray:
        """Start ``(2,)`` [m]: the middle of the widest road run on the left edge."""
        col = self.road[:, 0]
        runs = _runs(col)
        r0, r1 = max(runs, key=lambda r: (r[1] - r[0], -r[0]))
        y = (self.shape[0] - (r0 + r1 + 1) / 2.0) * self.scale
        return np.array([0.5 * self.scale, y])

    def check_point(self, xy: ArrayLike, *, what: str = "start") -> FloatArray:
        """The point ``(2,)`` [m], or a GeometryError if it is off the road or on an obstacle.

        ``what`` names the point in the message ("start", "goal").
        """
        p = np.asarray(xy, dtype=float).reshape(-1)
        if p.shape != (2,) or not np.all(np.isfinite(p)):
            raise GeometryError(f"{what} must be two finite coordinates, got {xy!r}")
        x0, x1, y0, y1 = self.extent
        if not (x0 <= p[0] < x1 and y0 <= p[1] < y1):
            raise GeometryError(
                f"{what} ({p[0]:.2f}, {p[1]:.2f}) m lies outside the map "
                f"[0, {x1:.2f}] x [0, {y1:.2f}] m"
            )
        if not self.on_road(p)[0]:
            row, col = self.to_pixel(p)[0]
            where = "on an obstacle" if self._between_boundaries(row, col) else "off the road"
            raise GeometryError(
                f"{what} ({p[0]:.2f}, {p[1]:.2f}) m is {where} (pixel row {row}, column {col})"
            )
        return p

    def _between_boundaries(self, row: int, col: int) -> bool:
        rows = np.flatnonzero(self.road[:, col])
        return bool(rows.size and rows[0] <= row <= rows[-1])


def read_image(source: str | PathLike[str]) -> FloatArray:
    """Luminance ``(H, W)`` in [0, 1] of an image file; transparent pixels count as black.

    Raises ScenarioError when the file is missing, unreadable or not an image.
    """
    from PIL import Image, UnidentifiedImageError

    path = Path(source)
    try:
        with Image.open(path) as im:
            im.load()
            rgba = np.asarray(im.convert("RGBA"), dtype=float) / 255.0
    except FileNotFoundError as err:
        raise ScenarioError(f"map image {path} not found") from err
    except (UnidentifiedImageError, OSError, SyntaxError, ValueError,
            Image.DecompressionBombError) as err:
        raise ScenarioError(f"map image {path} is not a readable image: {err}") from err
    lum = rgba[..., :3] @ np.array([0.2126, 0.7152, 0.0722])
    return np.asarray(lum * rgba[..., 3], dtype=float)


def image_map(
    source: str | PathLike[str] | ArrayLike,
    *,
    scale: float,
    threshold: float = 0.5,
    merge_tolerance: int = 0,
) -> ImageMap:
    """Read a road segment from an image file or array.

    Parameters
    ----------
    source
        Path of an image (any format Pillow reads), or a luminance array ``(H, W)`` in [0, 1]
        (or booleans, True = road), row 0 at the top.
    scale
        Size [m] of a pixel, positive.
    threshold
        Luminance in (0, 1) at or above which a pixel is road.
    merge_tolerance
        Rows of a blob are merged into one rectangle while its left and right ends vary by
        at most this many pixels; the rectangle then also covers those few road pixels.
        0 keeps obstacles pixel-exact. Larger values mean fewer polygons, hence faster
        planning.

    Raises
    ------
    ParameterError
        A bad scale, threshold or tolerance.
    ScenarioError
        The file cannot be read as an image.
    GeometryError
        No light area joins the left and right edges, or the road turns back on itself.
    """
    if not (isinstance(scale, int | float) and np.isfinite(scale) and scale > 0):
        raise ParameterError(f"map scale must be a positive number of metres per pixel, "
                             f"got {scale!r}")
    if not (0.0 < threshold < 1.0):
        raise ParameterError(f"map threshold must lie in (0, 1), got {threshold!r}")
    if int(merge_tolerance) != merge_tolerance or merge_tolerance < 0:
        raise ParameterError(f"merge_tolerance must be a whole number >= 0, "
                             f"got {merge_tolerance!r}")
    if isinstance(source, str | PathLike):
        free = read_image(source) >= threshold
        name = str(source)
    else:
        arr = np.asarray(source)
        if arr.ndim != 2:
            raise ParameterError(f"map array must be (H, W), got shape {arr.shape}")
        free = arr.astype(bool) if arr.dtype == bool else arr >= threshold
        name = "map array"
    if free.shape[0] < 2 or free.shape[1] < 2:
        raise GeometryError(f"{name} is too small ({free.shape[1]} x {free.shape[0]} pixels)")
    road = _road_component(free, name)
    top_e, bot_e = _envelope(road, float(scale), name)
    corridor = _corridor(top_e, bot_e, float(scale))
    obstacles, blob_of = _obstacles(free, top_e, bot_e, float(scale), int(merge_tolerance))
    log.info("%s: %d x %d pixels, road %.1f m long, %d obstacle rectangles in %d blobs",
             name, free.shape[1], free.shape[0], corridor.length, len(obstacles),
             int(blob_of.max()) + 1 if len(blob_of) else 0)
    return ImageMap(free, road, float(scale), corridor, obstacles, blob_of)


@dataclass(frozen=True, eq=False)
class ImagePlan:
    """Levels 2 and 3 planned across an image map.

    Attributes
    ----------
    map
        The map read from the image.
    corridor
        The part of the map's corridor planned across: from the start's station to the
        goal's (the whole road by default).
    start, goal
        Start ``(2,)`` [m] and goal ``(2,)`` [m] (the goal only fixes where the plan ends
        along the road; ``None``: the right edge).
    roadmaps
        One level-2 roadmap per road segment.
    trajectory
        The level-3 trajectory (:class:`splineplan.trajectory.Trajectory`).
    """

    map: ImageMap
    corridor: Corridor
    start: FloatArray
    goal: FloatArray | None
    roadmaps: tuple[Any, ...]
    trajectory: Any


def plan_image(
    source: ImageMap,
    *,
    start: ArrayLike | None = None,
    goal: ArrayLike | None = None,
    roadmap_params: Any = None,
    params: Any = None,
    start_speed: float = 0.0,
) -> ImagePlan:
    """Plan levels 2 and 3 across an image map, from the start to the goal's station.

    The start defaults to :meth:`ImageMap.default_start` (the left edge); its heading is the
    road's. The plan ends on the sweep line through the goal (the right edge by default),
    at the lateral position the widest path chooses.

    Raises
    ------
    GeometryError
        The start or goal is off the road, on an obstacle, or the goal is not ahead.
    RoadBlockedError
        The vehicle cannot pass between the obstacles.
    """
    from splineplan.planner import plan_corridor

    p0 = source.check_point(source.default_start() if start is None else start, what="start")
    corridor = source.corridor
    s0 = float(corridor.to_sl(p0)[0, 0])
    s1 = corridor.length
    p1 = None
    if goal is not None:
        p1 = source.check_point(goal, what="goal")
        s1 = float(corridor.to_sl(p1)[0, 0])
    if s1 - s0 < 1.0:
        raise GeometryError(
            f"the goal lies {s1 - s0:.2f} m along the road from the start; it must lie "
            "at least 1 m ahead (to the right along the road)"
        )
    part = corridor.slice(max(s0, 0.0), min(s1, corridor.length))
    heading = float(corridor.heading_at(s0))
    roadmaps, trajectory = plan_corridor(part, source.obstacles, p0, heading,
                                         roadmap_params=roadmap_params, params=params,
                                         start_speed=start_speed)
    return ImagePlan(source, part, p0, p1, tuple(roadmaps), trajectory)


# -- helpers --------------------------------------------------------------------------------
def _runs(mask: NDArray[np.bool_]) -> list[tuple[int, int]]:
    """Runs of True in a 1-D mask as (first, last) indices, inclusive."""
    padded = np.concatenate(([False], mask, [False])).astype(np.int8)
    d = np.diff(padded)
    starts = np.flatnonzero(d == 1)
    ends = np.flatnonzero(d == -1) - 1
    return list(zip(starts.tolist(), ends.tolist(), strict=True))


def _road_component(free: BoolArray, name: str) -> BoolArray:
    labels, _ = ndimage.label(free, structure=_FOUR)
    both = np.intersect1d(labels[:, 0], labels[:, -1])
    both = both[both > 0]
    if both.size == 0:
        reach = np.isin(labels, np.unique(labels[:, 0][labels[:, 0] > 0]))
        cols = np.flatnonzero(reach.any(axis=0))
        where = (f"the light area from the left edge ends at column {cols[-1]}"
                 if cols.size else "the left edge has no light pixel")
        raise GeometryError(f"{name} has no road joining its left and right edges ({where})")
    sizes = ndimage.sum_labels(np.ones_like(labels), labels, both)
    road = labels == both[int(np.argmax(sizes))]
    return np.asarray(road)


def _envelope(road: BoolArray, scale: float, name: str) -> tuple[FloatArray, FloatArray]:
    """Smooth top and bottom road boundaries y [m] at the ``W + 1`` column edges.

    The road's top and bottom in each column are bridged over notches narrower than the
    road (running maximum / minimum over a window as wide as the road) and then smoothed,
    so that the reference line is smooth. Dark pixels between the two are obstacles, so the
    envelope may safely overshoot the road.
    """
    h, w = road.shape
    top_row = np.argmax(road, axis=0)
    bottom_row = h - 1 - np.argmax(road[::-1], axis=0)
    top = (h - top_row) * scale  # y [m] of the top edge of the topmost road pixel
    bottom = (h - 1 - bottom_row) * scale
    k = int(max(3, min(w, np.median(bottom_row - top_row + 1))))
    top = ndimage.uniform_filter1d(ndimage.maximum_filter1d(top, k, mode="nearest"), k,
                                   mode="nearest")
    bottom = ndimage.uniform_filter1d(ndimage.minimum_filter1d(bottom, k, mode="nearest"), k,
                                      mode="nearest")
    top_e = np.minimum(np.interp(np.arange(w + 1) - 0.5, np.arange(w), top), h * scale)
    bot_e = np.maximum(np.interp(np.arange(w + 1) - 0.5, np.arange(w), bottom), 0.0)
    if np.any(top_e - bot_e < 2 * scale):
        c = int(np.argmax(top_e - bot_e < 2 * scale))
        raise GeometryError(
            f"{name}: the road turns back or pinches at x = {c * scale:.2f} m; "
            "only roads running from the left edge to the right edge are supported"
        )
    return top_e, bot_e


#: How far [m] the corridor's boundaries are drawn inside the road's envelope: on a bend the
#: corridor's Frenet boundaries deviate from the envelope polyline by about a centimetre.
BOUNDARY_INSET = 0.05


def _corridor(top_e: FloatArray, bot_e: FloatArray, scale: float) -> Corridor:
    x = np.arange(len(top_e)) * scale
    inset = min(BOUNDARY_INSET, float(np.min(top_e - bot_e)) / 4.0)
    return Corridor.from_boundaries(np.column_stack((x, top_e - inset)),
                                    np.column_stack((x, bot_e + inset)))


def _obstacles(
    free: BoolArray, top_e: FloatArray, bot_e: FloatArray, scale: float, tol: int
) -> tuple[Obstacles, NDArray[np.int64]]:
    h = free.shape[0]
    # pixels whose square meets the band between the envelopes, widened where the envelope
    # slopes by the neighbouring columns' rise: the corridor's Frenet boundary deviates a
    # little from the polyline on a bend
    y_hi = ndimage.maximum_filter1d(top_e, 4, origin=-1, mode="nearest")[:-1] - 1e-6 * scale
    y_lo = ndimage.minimum_filter1d(bot_e, 4, origin=-1, mode="nearest")[:-1] + 1e-6 * scale
    y_pix_top = (h - np.arange(h))[:, None] * scale
    dark = ~free & (y_pix_top > y_lo[None, :]) & (y_pix_top - scale < y_hi[None, :])
    labels, _ = ndimage.label(dark, structure=_EIGHT)
    polygons: list[FloatArray] = []
    ids: list[str] = []
    owner: list[int] = []
    for b, sl in enumerate(ndimage.find_objects(labels)):
        if sl is None:
            continue
        sub = labels[sl] == b + 1
        for k, (r0, r1, c0, c1) in enumerate(_rectangles(sub, tol)):
            r0 += sl[0].start
            r1 += sl[0].start
            c0 += sl[1].start
            c1 += sl[1].start
            x0, x1 = c0 * scale, (c1 + 1) * scale
            y0, y1 = (h - 1 - r1) * scale, (h - r0) * scale
            polygons.append(np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1]]))
            ids.append(f"blob{b}_{k}")
            owner.append(b)
    obstacles = Obstacles.from_polygons(polygons, ids) if polygons else Obstacles.empty()
    return obstacles, np.asarray(owner, dtype=np.int64)


def _rectangles(mask: BoolArray, tol: int) -> list[tuple[int, int, int, int]]:
    """Rectangles (row0, row1, col0, col1), inclusive, whose union covers a mask's pixels.

    Each row's runs are stacked onto a rectangle of the row above while both ends stay
    within ``tol`` pixels of every stacked run; with ``tol = 0`` the union is exact.
    """
    done: list[tuple[int, int, int, int]] = []
    # open rectangles: [row0, lo0, hi0, lo1, hi1] = first row, range of left ends, of right ends
    open_: list[list[int]] = []
    for r in range(mask.shape[0]):
        still: list[list[int]] = []
        for c0, c1 in _runs(mask[r]):
            for i, o in enumerate(open_):
                lo0, hi0 = min(o[1], c0), max(o[2], c0)
                lo1, hi1 = min(o[3], c1), max(o[4], c1)
                if hi0 - lo0 <= tol and hi1 - lo1 <= tol and hi0 <= lo1:
                    still.append([o[0], lo0, hi0, lo1, hi1])
                    open_.pop(i)
                    break
            else:
                still.append([r, c0, c0, c1, c1])
        done.extend((o[0], r - 1, o[1], o[4]) for o in open_)
        open_ = still
    done.extend((o[0], mask.shape[0] - 1, o[1], o[4]) for o in open_)
    return done
