"""The ego's surroundings at each step of the closed loop: the road and the other vehicles.

Pure geometry and kinematics on plain floats and numpy arrays, no SUMO: whether the ego's
footprint is on a lane or junction area (:class:`RoadCheck`, built once from the
:class:`~splineplan.network.RoadNetwork`, then on its own arrays), the vehicles around the
ego as arrays (:class:`Others`), which of them is in the ego's path (:func:`probe_points`,
:func:`next_in_circle`, :func:`first_in_box_reach`) and the speed that keeps a safe gap to it
(:func:`safe_speed`). They run many times per simulated second, hence the plain-float
variants where a few points meet a few segments. Kept apart from :mod:`splineplan.sim`,
which drives SUMO, so that they can be read and tested without a simulation.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from splineplan.geometry import FloatArray, heading_from_sumo_angle
from splineplan.obstacles import Obstacles

#: How far [m] a footprint point may stick out of the lane bands and junction areas before it
#: counts as off the road (lane bands are a model of the drawn road: curbs at junction corners
#: are cut by a few centimetres).
OFF_ROAD_TOLERANCE = 0.1
#: Radius [m] of the neighbourhood whose lane segments the road check keeps at hand.
_ROAD_CACHE = 20.0


class RoadCheck:
    """Whether points lie on a lane (normal or junction) that a vehicle class may use."""

    def __init__(self, net: Any, vclass: str, tol: float = OFF_ROAD_TOLERANCE) -> None:
        from scipy.spatial import cKDTree

        lanes = [ln for edge in net.lanes for ln in edge if ln.allows(vclass)]
        lanes += [ln for ln in net.internal_lanes.values() if ln.allows(vclass)]
        a, b, hw = [], [], []
        for ln in lanes:
            sh = np.asarray(ln.shape, dtype=float)
            if len(sh) < 2:
                continue
            a.append(sh[:-1])
            b.append(sh[1:])
            hw.append(np.full(len(sh) - 1, ln.width / 2.0))
        self.a = np.concatenate(a) if a else np.zeros((0, 2))
        self.b = np.concatenate(b) if b else np.zeros((0, 2))
        self.hw = np.concatenate(hw) if hw else np.zeros(0)
        self.tol = tol
        mid = (self.a + self.b) / 2.0
        half = np.hypot(*(self.b - self.a).T) / 2.0 if len(self.a) else np.zeros(0)
        self.radius = float(half.max() + self.hw.max() + tol) if len(self.a) else 0.0
        self.tree = cKDTree(mid if len(mid) else np.zeros((1, 2)))
        self.junctions = Obstacles.empty()
        self._cache_at: FloatArray | None = None
        self._cache = np.zeros(0, dtype=np.int64)
        self._near_at: tuple[float, float] | None = None
        self._near: tuple[FloatArray, ...] = ()
        self._hot: tuple[FloatArray, ...] | None = None
        # the same segments as rows (start x, y, direction x, y, 1 / squared length,
        # squared reach) of plain floats
        self._hot_rows: list[tuple[float, ...]] = []

    def add_junctions(self, shapes: list[FloatArray]) -> None:
        """Junction areas (SUMO's junction polygons) count as road too."""
        good = []
        for sh in shapes:
            p = np.asarray(sh, dtype=float)
            area2 = np.sum(p[:, 0] * np.roll(p[:, 1], -1) - np.roll(p[:, 0], -1) * p[:, 1])
            if abs(area2) > 1e-9:
                good.append(p)
        self.junctions = Obstacles.from_polygons(good) if good else Obstacles.empty()

    def contains_all(self, points: FloatArray | list[tuple[float, float]], *,
                     centre: tuple[float, float] | None = None,
                     radius: float | None = None) -> bool:
        """Whether every point ``(n, 2)`` of a small group (a footprint) is on the road,
        as :meth:`contains`.

        Keeps the lane segments that can reach any point within :data:`_ROAD_CACHE` / 2 of
        where it last gathered them (by their exact distance to that place), and among
        them the few that held the points last time: a footprint moving along a lane is
        measured against those first, and against all gathered ones only when they do not
        hold every point. ``centre`` [m] and ``radius`` [m]: a disc that holds the points,
        if known (else their mean and largest distance from it). ``points`` may be a list
        of ``(x, y)`` pairs.
        """
        if not len(self.a):
            return False
        tried = False
        if centre is not None and radius is not None and radius <= _ROAD_CACHE / 2.0:
            cx, cy = centre
            if (self._near_at is not None and self._hot_rows
                    and math.hypot(cx - self._near_at[0], cy - self._near_at[1])
                    <= _ROAD_CACHE / 2.0):
                if _in_rows(points, self._hot_rows):
                    return True  # as below, the common case without arrays
                tried = True
        pts = np.asarray(points, dtype=float).reshape(-1, 2)
        if centre is None or radius is None:
            cx, cy = pts.mean(axis=0).tolist()
            spread = float(np.sqrt(((pts[:, 0] - cx) ** 2 + (pts[:, 1] - cy) ** 2).max()))
        else:
            (cx, cy), spread = centre, radius
        if spread > _ROAD_CACHE / 2.0:
            return bool(self.contains(pts).all())
        if (self._near_at is None
                or math.hypot(cx - self._near_at[0], cy - self._near_at[1]) > _ROAD_CACHE / 2.0):
            self._gather(cx, cy)
        if not tried and self._hot is not None and _in_bands(pts, self._hot).all():
            return True
        near = self._near
        if len(near[0]):
            within = _in_bands(pts, near, per_segment=True)  # (n, k)
            on = within.any(axis=1)
            hot = within.any(axis=0)
            self._hot = tuple(v[hot] for v in near) if hot.any() else None
            self._hot_rows = (list(zip(*(v.tolist() for v in self._hot), strict=True))
                              if self._hot is not None else [])
            if on.all():
                return True
        else:
            on = np.zeros(len(pts), dtype=bool)
        if not len(self.junctions):
            return False
        rest = pts[~on]
        near_j = self.junctions.near(rest, 1.0)
        return bool(len(near_j) and (near_j.distance(rest) <= self.tol).all())

    def _gather(self, cx: float, cy: float) -> None:
        """Lane segments within reach (half width plus tolerance) of any point within
        :data:`_ROAD_CACHE` of ``(cx, cy)``."""
        from splineplan.geometry import point_segment_distance

        centre = np.array([cx, cy])
        idx = np.asarray(self.tree.query_ball_point(centre, self.radius + _ROAD_CACHE),
                         dtype=np.int64)
        if len(idx):
            d = point_segment_distance(centre, self.a[idx], self.b[idx])
            idx = idx[d - self.hw[idx] - self.tol <= _ROAD_CACHE]
        a, ab, hw = self.a[idx], self.b[idx] - self.a[idx], self.hw[idx]
        ln2 = ab[:, 0] ** 2 + ab[:, 1] ** 2
        self._near = (a[:, 0].copy(), a[:, 1].copy(), ab[:, 0].copy(), ab[:, 1].copy(),
                      1.0 / np.where(ln2 > 0, ln2, 1.0), (hw + self.tol) ** 2)
        self._near_at = (cx, cy)
        self._hot = None
        self._hot_rows = []

    def contains(self, points: FloatArray) -> np.ndarray:
        """``(n,)`` booleans: the point is within a lane's half width of its centre line."""
        from splineplan.geometry import point_segment_distance

        pts = np.asarray(points, dtype=float).reshape(-1, 2)
        if not len(self.a):
            return np.zeros(len(pts), dtype=bool)
        centre = pts.mean(axis=0)
        spread = float(np.hypot(*(pts - centre).T).max())
        if (self._cache_at is None or spread > _ROAD_CACHE / 2.0
                or float(np.hypot(*(centre - self._cache_at))) > _ROAD_CACHE / 2.0):
            # segments that can reach any point within _ROAD_CACHE of this centre
            self._cache_at = centre
            self._cache = np.asarray(self.tree.query_ball_point(
                centre, self.radius + _ROAD_CACHE + spread), dtype=np.int64)
        idx = self._cache
        if not len(idx):
            return np.zeros(len(pts), dtype=bool)
        a, b, hw = self.a[idx], self.b[idx], self.hw[idx]
        d = point_segment_distance(pts[:, None, :], a[None], b[None])
        on: np.ndarray = np.asarray(((d - hw[None]) <= self.tol).any(axis=1))
        if not on.all() and len(self.junctions):
            near_j = self.junctions.near(pts[~on], 1.0)
            if len(near_j):
                on[~on] = near_j.distance(pts[~on]) <= self.tol
        return np.asarray(on)


def _in_bands(pts: FloatArray, segs: tuple[FloatArray, ...], *, per_segment: bool = False
              ) -> np.ndarray:
    """Whether points ``(n, 2)`` lie within the bands of lane segments ``segs`` (start x, y,
    direction x, y, 1 / squared length, squared reach): ``(n,)``, or ``(n, k)`` per segment."""
    ax, ay, abx, aby, inv, lim2 = segs
    dx = pts[:, 0, None] - ax  # (n, k)
    dy = pts[:, 1, None] - ay
    t = np.minimum(np.maximum((dx * abx + dy * aby) * inv, 0.0), 1.0)
    ex = dx - t * abx
    ey = dy - t * aby
    within: np.ndarray = np.asarray((ex * ex + ey * ey) <= lim2)
    return within if per_segment else np.asarray(within.any(axis=1))


def _in_rows(pts: Any, rows: list[tuple[float, ...]]) -> bool:
    """Whether every point ``(x, y)`` lies within the band of some lane segment of ``rows``
    (as :func:`_in_bands`, with plain floats: a few points against a few segments)."""
    for px, py in pts:
        for ax, ay, abx, aby, inv, lim2 in rows:
            dx, dy = px - ax, py - ay
            t = (dx * abx + dy * aby) * inv
            t = 0.0 if t < 0.0 else 1.0 if t > 1.0 else t
            ex, ey = dx - t * abx, dy - t * aby
            if ex * ex + ey * ey <= lim2:
                break
        else:
            return False
    return True


class Others:
    """The vehicles around the ego at one step, as arrays.

    ``front`` ``(k, 2)`` [m] is SUMO's position (middle of the front bumper), ``head``
    ``(k,)`` [rad] the heading, ``centre`` ``(k, 2)`` [m] the centre (``cx``, ``cy`` its
    columns), ``radius`` ``(k,)`` [m] the bounding circle's.
    """

    __slots__ = (
        "centre",
        "cos",
        "cx",
        "cy",
        "front",
        "head",
        "ids",
        "length",
        "n",
        "n_stopped",
        "radius",
        "sin",
        "speed",
        "stopped",
        "width",
    )

    def __init__(self, ids: list[str], a: FloatArray, stopped_speed: float) -> None:
        """``a`` ``(k, 7)``: x, y, SUMO angle [deg], length, width, speed, stop state."""
        self.ids = ids
        self.n = len(ids)
        self.front = a[:, :2]
        self.head = heading_from_sumo_angle(a[:, 2])
        self.cos = np.cos(self.head)
        self.sin = np.sin(self.head)
        self.length = a[:, 3]
        self.width = a[:, 4]
        self.speed = a[:, 5]
        state = a[:, 6]
        if state.any():  # at a stop or parked (bits 1, 2) and standing
            self.stopped = ((state.astype(np.int64) & 3) > 0) & (self.speed < stopped_speed)
            self.n_stopped = int(np.count_nonzero(self.stopped))
        else:
            self.stopped = np.zeros(self.n, dtype=bool)
            self.n_stopped = 0
        half = 0.5 * self.length
        self.cx = a[:, 0] - half * self.cos  # contiguous, as the compiled loops take them
        self.cy = a[:, 1] - half * self.sin
        self.centre = np.column_stack((self.cx, self.cy))
        self.radius = 0.5 * np.hypot(self.length, self.width)


NO_OTHERS = Others([], np.zeros((0, 7)), 0.0)


def probe_points(cx: float, cy: float, c: float, s: float, hl: float, hw: float
                  ) -> list[tuple[float, float]]:
    """Corners, centre and edge midpoints (9 points x, y) of a rectangle [m] from its
    centre, heading's cosine and sine, half length and half width."""
    fx, fy, lx, ly = c * hl, s * hl, -s * hw, c * hw
    return [(cx - fx - lx, cy - fy - ly), (cx + fx - lx, cy + fy - ly),
            (cx + fx + lx, cy + fy + ly), (cx - fx + lx, cy - fy + ly), (cx, cy),
            (cx + fx, cy + fy), (cx + lx, cy + ly), (cx - fx, cy - fy), (cx - lx, cy - ly)]


def next_in_circle(xs: list[float], ys: list[float], i: int, cx: float, cy: float,
                    r: float, step: float) -> int:
    """The first index from ``i`` on of the path samples (``xs``, ``ys``) [m] within ``r``
    [m] of ``(cx, cy)``; -1 if none is.

    Consecutive samples are at most ``step`` [m] apart, so a sample at distance ``d > r``
    rules out the next ``(d - r) / step`` ones: the walk jumps over them (plain floats, a
    few jumps along a path of hundreds of samples)."""
    n = len(xs)
    r2 = r * r
    while i < n:
        dx, dy = xs[i] - cx, ys[i] - cy
        d2 = dx * dx + dy * dy
        if d2 <= r2:
            return i
        if step <= 0.0:  # all samples at one point
            return -1
        i += max(int((math.sqrt(d2) - r) / step), 1)
    return -1


def first_in_box_reach(lo: int, circle: tuple[float, float, float, float],
                       box: tuple[float, float, float, float], xs: list[float],
                       ys: list[float], reach: float) -> int:
    """The first path sample index from ``lo`` on whose point (``xs``, ``ys``) [m] is within
    ``reach`` [m] of a rectangle, the body of a vehicle; -1 if none is.

    ``circle``: the rectangle's centre x, y [m], the radius [m] of a circle round it that
    holds every point within reach of it (half its diagonal plus ``reach``), and the
    largest distance [m] between consecutive samples; only the samples in it are tried
    (:func:`next_in_circle`). ``box``: the heading's cosine and sine, half length and half
    width [m]. The distance is to the whole outline, so that a path crossing a long
    vehicle's side between its corners counts. Plain floats: a handful of samples,
    stopping at the first hit, costs less than arrays."""
    cx, cy, r, step = circle
    c, s, hl, hw = box
    reach2 = reach * reach
    i = next_in_circle(xs, ys, lo, cx, cy, r, step)
    while i >= 0:
        ex, ey = xs[i] - cx, ys[i] - cy
        along = abs(ex * c + ey * s) - hl
        side = abs(ey * c - ex * s) - hw
        along = along if along > 0.0 else 0.0
        side = side if side > 0.0 else 0.0
        if along * along + side * side <= reach2:
            return i
        i = next_in_circle(xs, ys, i + 1, cx, cy, r, step)
    return -1


def safe_speed(gap: float, v_leader: float, b: float, tau: float) -> float:
    """Krauss's safe speed [m/s]: stop behind a leader braking at ``b`` after a gap [m]."""
    disc = (b * tau) ** 2 + v_leader**2 + 2.0 * b * gap
    if disc <= 0.0:
        return 0.0
    return max(-b * tau + math.sqrt(disc), 0.0)
