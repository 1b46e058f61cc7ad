"""Independent raster oracle for level 2: passability and best clearance of a road.

Written without the planner's code: the road is a shapely polygon, obstacles are plain
polygons; both are rasterised (cell centres tested with shapely), the clearance of each
free cell is a Euclidean distance transform, and the best bottleneck clearance from the
start to the goal region is a widest path on the raster (thresholding plus connected
components, bisecting over the distinct clearance values).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import shapely
from scipy import ndimage
from shapely.geometry import Polygon


@dataclass(frozen=True)
class OracleResult:
    """Best clearance [m] over raster paths from start to goal (0 when the start cell is
    blocked), the clearance field ``(ny, nx)`` [m] and the raster's origin and step."""

    best_clearance: float
    clearance: np.ndarray
    origin: tuple[float, float]
    step: float

    def clearance_at(self, xy: np.ndarray) -> np.ndarray:
        """Clearance [m] of the cells holding points ``(n, 2)``."""
        ij = np.floor((np.asarray(xy) - self.origin) / self.step).astype(int)
        return self.clearance[ij[:, 1], ij[:, 0]]


def best_clearance(
    road: Polygon,
    obstacles: list[np.ndarray],
    start: np.ndarray,
    goal: Polygon,
    *,
    step: float = 0.1,
) -> OracleResult:
    """Widest passage on a raster of ``road`` among ``obstacles`` (polygons ``(k, 2)``).

    The clearance of a cell is the distance [m] from its centre to the nearest centre of
    a blocked cell (outside the road or inside an obstacle); this is within one cell
    diagonal of the exact distance to the blocked set. The result is the largest ``c``
    such that the cells of clearance ``>= c`` connect the start's cell (8-neighbours) to a
    cell whose centre lies in ``goal``.
    """
    x0, y0, x1, y1 = road.bounds
    x0, y0 = x0 - 2 * step, y0 - 2 * step
    nx = int(np.ceil((x1 - x0) / step)) + 3
    ny = int(np.ceil((y1 - y0) / step)) + 3
    cx = x0 + (np.arange(nx) + 0.5) * step
    cy = y0 + (np.arange(ny) + 0.5) * step
    gx, gy = np.meshgrid(cx, cy)
    free = shapely.contains_xy(road, gx, gy)
    for poly in obstacles:
        free &= ~shapely.contains_xy(Polygon(poly), gx, gy)
    clearance = ndimage.distance_transform_edt(free) * step
    in_goal = shapely.contains_xy(goal, gx, gy)
    i, j = int((start[1] - y0) // step), int((start[0] - x0) // step)
    levels = np.unique(clearance[clearance > 0])
    struct = np.ones((3, 3), dtype=bool)

    def passable(c: float) -> bool:
        labels, _ = ndimage.label(clearance >= c, structure=struct)
        k = labels[i, j]
        return bool(k and np.any(labels[in_goal] == k))

    if not len(levels) or not passable(levels[0]):
        return OracleResult(0.0, clearance, (x0, y0), step)
    lo, hi = 0, len(levels) - 1  # passable(levels[lo]) holds; bisect for the largest
    while lo < hi:
        mid = (lo + hi + 1) // 2
        if passable(levels[mid]):
            lo = mid
        else:
            hi = mid - 1
    return OracleResult(float(levels[lo]), clearance, (x0, y0), step)


def paved_area(net_path: str, within: Any = None) -> shapely.Geometry:
    """The paved area of a SUMO network by sumolib and shapely alone: every lane (normal
    and internal) as a band of its width around its centre line, and every junction
    outline (only those meeting the geometry ``within``, where given)."""
    import sumolib
    from shapely.geometry import LineString
    from shapely.ops import unary_union

    snet = sumolib.net.readNet(str(net_path), withInternal=True)
    parts = [LineString(ln.getShape()).buffer(ln.getWidth() / 2.0, cap_style=2)
             for e in snet.getEdges(withInternal=True) for ln in e.getLanes()
             if len(ln.getShape()) >= 2]
    parts += [Polygon(j.getShape()) for j in snet.getNodes() if len(j.getShape()) >= 3]
    if within is not None:
        parts = [p for p in parts if p.intersects(within)]
    return unary_union([p for p in parts if p.is_valid])


def corridor_excess(corridor: Any, paved: shapely.Geometry, *, step: float = 1.0,
                    gap: float = 0.3) -> tuple[np.ndarray, np.ndarray]:
    """How far [m] a corridor reaches beyond the paved area, station by station.

    At stations every ``step`` metres, the corridor's normal is cut with the paved area;
    the paved stretch holding the corridor's middle (stretches less than ``gap`` apart
    joined: neighbouring lanes drawn a few centimetres apart) is compared with the
    corridor's bounds there. ``inf`` where the middle is not paved. Unlike the area of the
    corridor's outline outside the pavement, this does not count the ground between the
    two legs of a hairpin, which the outline encloses. Returns the stations and excesses.
    """
    from shapely.geometry import LineString, Point

    shapely.prepare(paved)
    stations = np.arange(step / 2.0, corridor.length, step)
    out = np.empty(len(stations))
    right, left = corridor.bounds_at(stations)
    for k, (s, r, lft) in enumerate(zip(stations, right, left, strict=True)):
        lo, hi = float(r) - 4.0, float(lft) + 4.0
        line = LineString([corridor.to_xy(s, lo), corridor.to_xy(s, hi)])
        cut = line.intersection(paved)
        spans = sorted(
            sorted((lo + line.project(Point(g.coords[0])), lo + line.project(Point(g.coords[-1]))))
            for g in getattr(cut, "geoms", [cut])
            if not g.is_empty and g.geom_type == "LineString")
        merged: list[list[float]] = []
        for a, b in spans:
            if merged and a - merged[-1][1] < gap:
                merged[-1][1] = max(merged[-1][1], b)
            else:
                merged.append([a, b])
        mid = (float(r) + float(lft)) / 2.0
        hold = [m for m in merged if m[0] - 1e-6 <= mid <= m[1] + 1e-6]
        out[k] = (max(float(lft) - hold[0][1], hold[0][0] - float(r), 0.0) if hold
                  else np.inf)
    return stations, out
