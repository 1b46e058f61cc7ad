"""Independent kinematic oracle: can a car drive from a start pose to a goal region, and
with how much clearance at best.

Written without the planner's code, as a judge of it. The car is its exact rectangle
(``length`` x ``width``, centred on the pose) moving forward on arcs of bounded curvature
(``|kappa| <= 1 / min_turn_radius`` for the path of its centre): a hybrid A* search over
(x, y, heading) with arcs of a few curvatures from each pose, in the manner of the
hybrid A* of Dolgov et al. (2008). The drivable area is a shapely polygon and the
obstacles are polygons; both are rasterised (cell centres tested with shapely), and the
distances of the footprint to them are read from Euclidean distance transforms:

- the footprint's boundary, sampled every ``step`` [m], keeps ``margin`` [m] from every
  obstacle cell and ``road_margin`` [m] from every cell off the road;
- points inside the footprint, every ``2 step`` [m], lie in no obstacle (so that a small
  obstacle cannot hide inside the rectangle).

Distances between cell centres are within ``step * sqrt(2)`` of the exact ones between
the points, and the boundary's samples within ``step / 2`` of its points: the verdicts are
exact to about ``2 step`` [m] of clearance (:func:`error`), and to the arcs' sampling
(every 0.25 m). :func:`best_clearance` bisects over the margin.
"""

from __future__ import annotations

import heapq
import math
from dataclasses import dataclass

import numpy as np
import shapely
from scipy import ndimage
from shapely.geometry import Polygon


@dataclass(frozen=True)
class Car:
    """The vehicle: footprint [m] and the turning radius [m] of its centre."""

    length: float = 4.5
    width: float = 1.8
    min_turn_radius: float = 4.2


@dataclass(frozen=True)
class Search:
    """Resolution of the search: raster cell [m], arc length of one move [m], the
    curvatures tried per move, and the closed set's cell [m] and heading bins."""

    step: float = 0.03
    move: float = 1.0
    curvatures: int = 7
    cell: float = 0.3
    headings: int = 72
    max_nodes: int = 400_000


def error(search: Search | None = None) -> float:
    """How far [m] the oracle's clearances may be off the exact ones."""
    return 2.0 * (search or Search()).step


class Field:
    """Distance transforms [m] of a drivable area and its obstacles on a raster."""

    def __init__(self, road: Polygon, obstacles: list[Polygon], step: float) -> None:
        x0, y0, x1, y1 = road.bounds
        pad = 5.0  # a footprint about a pose just off the road stays on the raster
        self.origin = np.array([x0 - pad, y0 - pad])
        self.step = step
        nx = int(np.ceil((x1 - x0 + 2 * pad) / step)) + 1
        ny = int(np.ceil((y1 - y0 + 2 * pad) / step)) + 1
        cx = self.origin[0] + (np.arange(nx) + 0.5) * step
        cy = self.origin[1] + (np.arange(ny) + 0.5) * step
        gx, gy = np.meshgrid(cx, cy)
        on_road = shapely.contains_xy(road, gx, gy)
        blocked = np.zeros_like(on_road)
        if obstacles:
            blocked = shapely.contains_xy(shapely.union_all(obstacles), gx, gy)
        #: distance [m] to the nearest cell off the road, and to the nearest obstacle cell
        self.to_edge = ndimage.distance_transform_edt(on_road) * step
        self.to_obstacle = (ndimage.distance_transform_edt(~blocked) * step
                            if blocked.any() else np.full(on_road.shape, np.inf))
        self.shape = on_road.shape

    def index(self, xy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Row and column of the cells holding points ``(..., 2)`` (clamped)."""
        ij = np.floor((xy - self.origin) / self.step).astype(np.int64)
        return (np.clip(ij[..., 1], 0, self.shape[0] - 1),
                np.clip(ij[..., 0], 0, self.shape[1] - 1))

    def flat(self, xy: np.ndarray) -> np.ndarray:
        """Index into the raveled raster of the cells holding points ``(..., 2)``."""
        ij = ((xy - self.origin) / self.step).astype(np.int64)
        return ij[..., 1] * self.shape[1] + ij[..., 0]


#: Spacing [m] of the points inside the footprint that look for an obstacle hidden in it,
#: and their inset from its boundary (obstacles nearer the boundary are the boundary's).
INSIDE = 0.3


def _outline(car: Car, step: float) -> tuple[np.ndarray, np.ndarray]:
    """Points ``(k, 2)`` of the footprint's boundary every ``step`` [m] and of its inside
    every :data:`INSIDE` [m], at least that far inside, in the car's frame (x forward)."""
    hl, hw = car.length / 2.0, car.width / 2.0
    xs = np.linspace(-hl, hl, int(np.ceil(car.length / step)) + 1)
    ys = np.linspace(-hw, hw, int(np.ceil(car.width / step)) + 1)
    edge = np.concatenate((np.column_stack((xs, np.full_like(xs, -hw))),
                           np.column_stack((xs, np.full_like(xs, hw))),
                           np.column_stack((np.full_like(ys, -hl), ys)),
                           np.column_stack((np.full_like(ys, hl), ys))))
    ix, iy = hl - INSIDE, hw - INSIDE
    gx, gy = np.meshgrid(np.linspace(-ix, ix, int(np.ceil(2 * ix / INSIDE)) + 1),
                         np.linspace(-iy, iy, int(np.ceil(2 * iy / INSIDE)) + 1))
    return edge, np.column_stack((gx.ravel(), gy.ravel()))


#: An inside point this close [m] to an obstacle cell (centre to centre) finds it.
def _hidden(step: float) -> float:
    return INSIDE / math.sqrt(2.0) + step


def clearance(field: Field, car: Car, poses: np.ndarray, *, road_margin: float = 0.0
              ) -> tuple[np.ndarray, np.ndarray]:
    """Per pose ``(n, 3)``: the footprint's distance [m] to the obstacles (0 where one
    lies inside it) and to the road's edge less ``road_margin`` (negative: off the
    road, or closer than the road margin)."""
    edge, inside = _outline(car, field.step)
    c, s = np.cos(poses[:, 2])[:, None], np.sin(poses[:, 2])[:, None]

    def world(pts: np.ndarray) -> np.ndarray:
        return np.stack((poses[:, 0:1] + c * pts[:, 0] - s * pts[:, 1],
                         poses[:, 1:2] + s * pts[:, 0] + c * pts[:, 1]), axis=-1)

    r, q = field.index(world(edge))
    obs = field.to_obstacle[r, q].min(axis=1)
    road = field.to_edge[r, q].min(axis=1) - road_margin
    # the edge cells' distance counts from their centres: a point in a road cell next to
    # the edge is on the road to within half a cell
    road = np.where(road > 0, road, road - field.step)
    r, q = field.index(world(inside))
    hidden = field.to_obstacle[r, q].min(axis=1) < _hidden(field.step)
    return np.where(hidden, 0.0, obs), road


@dataclass(frozen=True)
class Result:
    """Whether the goal was reached, the path of poses ``(n, 3)`` (x, y [m], heading
    [rad]) from the start to the goal, and the nodes expanded."""

    found: bool
    path: np.ndarray
    expanded: int


def drive(road: Polygon, obstacles: list[Polygon], start: tuple[float, float, float],
          goal: Polygon, *, car: Car | None = None, margin: float = 0.3,
          road_margin: float = 0.0, search: Search | None = None,
          field: Field | None = None) -> Result:
    """Hybrid A* from ``start`` (x, y [m], heading [rad]) until the car's centre is in
    ``goal``, forward only, on arcs within the turning limit, the footprint keeping
    ``margin`` [m] from the obstacles and ``road_margin`` [m] inside the road.

    The start pose itself is not checked (a vehicle is where it is)."""
    car, search = car or Car(), search or Search()
    field = field or Field(road, obstacles, search.step)
    kmax = 1.0 / car.min_turn_radius
    kappas = np.linspace(-kmax, kmax, search.curvatures)
    sub = max(int(np.ceil(search.move / 0.25)), 1)
    ts = np.arange(1, sub + 1) * (search.move / sub)
    # goal cells, and the distance to them as the heuristic
    gx, gy = np.meshgrid(field.origin[0] + (np.arange(field.shape[1]) + 0.5) * field.step,
                         field.origin[1] + (np.arange(field.shape[0]) + 0.5) * field.step)
    in_goal = shapely.contains_xy(goal, gx, gy)
    to_goal = ndimage.distance_transform_edt(~in_goal) * field.step
    # a quick "no": the disc inscribed in the footprint cannot pass either (its centre's
    # free cells, loosened by a cell, do not connect the start to the goal)
    loose = ((field.to_obstacle >= car.width / 2.0 + margin - 2 * field.step)
             & (field.to_edge >= car.width / 2.0 + road_margin - 2 * field.step))
    labels, _ = ndimage.label(loose)
    r0, c0 = field.index(np.asarray(start[:2], dtype=float))
    if labels[r0, c0] == 0 or not np.any(in_goal & (labels == labels[r0, c0])):
        return Result(False, np.zeros((0, 3)), 0)
    # what each point of the footprint may touch: boundary points keep the margins, inside
    # points find no obstacle (one raster, the points in one array)
    edge, inside = _outline(car, field.step)
    road_ok = np.where(field.to_edge > 0, field.to_edge, -field.step) - road_margin >= 0.0
    free = np.concatenate(((field.to_obstacle >= margin) & road_ok,
                           field.to_obstacle >= _hidden(field.step))).ravel()
    pts_car = np.concatenate((edge, inside))
    ex, ey = pts_car[:, 0][None, :], pts_car[:, 1][None, :]
    # inside points look in the second half of ``free``: shift their indices by one raster
    shift = np.concatenate((np.zeros(len(edge), dtype=np.int64),
                            np.full(len(inside), field.to_edge.size, dtype=np.int64)))

    def key(p: np.ndarray) -> tuple[int, int, int]:
        return (math.floor(p[0] / search.cell), math.floor(p[1] / search.cell),
                round(p[2] / (2 * math.pi / search.headings)) % search.headings)

    x0 = np.asarray(start, dtype=float)
    parents: dict[tuple[int, int, int], tuple[np.ndarray, tuple[int, int, int] | None]] = {}
    k0 = key(x0)
    parents[k0] = (x0, None)
    cost = {k0: 0.0}
    heap = [(0.0, 0.0, k0)]
    done: set[tuple[int, int, int]] = set()
    expanded = 0
    while heap and expanded < search.max_nodes:
        _, g, k = heapq.heappop(heap)
        if k in done:
            continue
        done.add(k)
        expanded += 1
        p = parents[k][0]
        # arcs: poses after each sub-step, for every curvature
        th = p[2] + np.outer(kappas, ts)
        with np.errstate(divide="ignore", invalid="ignore"):
            dx = np.where(np.abs(kappas)[:, None] > 1e-9,
                          (np.sin(th) - math.sin(p[2])) / kappas[:, None],
                          np.cos(p[2]) * ts[None, :])
            dy = np.where(np.abs(kappas)[:, None] > 1e-9,
                          (math.cos(p[2]) - np.cos(th)) / kappas[:, None],
                          math.sin(p[2]) * ts[None, :])
        arcs = np.stack((p[0] + dx, p[1] + dy, th), axis=-1)
        poses = arcs.reshape(-1, 3)
        c, s = np.cos(poses[:, 2])[:, None], np.sin(poses[:, 2])[:, None]
        pts = np.stack((poses[:, 0:1] + c * ex - s * ey, poses[:, 1:2] + s * ex + c * ey),
                       axis=-1)
        ok = np.take(free, field.flat(pts) + shift, mode="clip").all(axis=1).reshape(
            len(kappas), sub).all(axis=1)
        for a in np.flatnonzero(ok):
            q = arcs[a, -1].copy()
            kq = key(q)
            if kq in done:
                continue
            r, c = field.index(q[:2])
            if in_goal[r, c]:
                parents[kq] = (q, k)
                return Result(True, _trace(parents, kq), expanded)
            gq = g + search.move
            if gq < cost.get(kq, math.inf):  # each cell keeps its cheapest pose
                cost[kq] = gq
                parents[kq] = (q, k)
                heapq.heappush(heap, (gq + 1.5 * float(to_goal[r, c]), gq, kq))
    return Result(False, np.zeros((0, 3)), expanded)


def _trace(parents: dict, k: tuple[int, int, int]) -> np.ndarray:
    out = []
    while k is not None:
        p, k = parents[k]
        out.append(p)
    return np.array(out[::-1])


def best_clearance(road: Polygon, obstacles: list[Polygon], start: tuple[float, float, float],
                   goal: Polygon, *, car: Car | None = None, road_margin: float = 0.0,
                   search: Search | None = None, upper: float = 2.0, tol: float = 0.05
                   ) -> float:
    """The largest margin [m] (to ``tol``) with which :func:`drive` reaches the goal; -1
    where it cannot even touch the obstacles' edges (margin 0)."""
    search = search or Search()
    field = Field(road, obstacles, search.step)

    def ok(m: float) -> bool:
        return drive(road, obstacles, start, goal, car=car, margin=m, road_margin=road_margin,
                     search=search, field=field).found

    if not ok(0.0):
        return -1.0
    lo, hi = 0.0, upper
    if ok(hi):
        return hi
    while hi - lo > tol:
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if ok(mid) else (lo, mid)
    return lo
