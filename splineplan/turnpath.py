"""A path through a junction for a car that turns, where its lanes are too tight for it.

Level 1's turn test (:func:`splineplan.network.turn_fits`) tries a few Dubins paths of one
radius from a lane's end to the next lane's start. A driver makes some turns it refuses by
swinging wide into the junction first, or by changing radius on the way; and the corridor
of such a turn, built along its internal lanes, holds no curve the car can follow, since
its frame's normals cross on the inside of the tight lane before they reach the paving
the car would use.

This module searches the turn's paving for a path the car can drive: forward, its
curvature within a share of the turning limit, its rectangle on the paving.

- **The paving as a raster**: the turn's polygons (SUMO's junction outline, the lanes
  near it, the internal lanes) are filled into a grid of :data:`CELL` metres, closed
  across gaps of up to :data:`GAP` (pieces drawn a few centimetres apart), and each
  cell's distance to the unpaved ground is taken (a Euclidean distance transform).
- **The car as discs**: :data:`DISCS` discs along its length cover its rectangle; a pose
  is on the paving where each disc's centre is at least its radius, less :data:`SLACK`,
  from the unpaved ground.
- **The search** (hybrid A*): from poses on the incoming lanes, arcs of :data:`STEP`
  metres at five curvatures (straight, half and the whole of :data:`TURN_SHARE` of the
  limit, either way) to a pose on an outgoing lane heading along it; positions in cells
  of :data:`BOX` metres and headings in :data:`BINS` bins are visited once. The cost is
  the length, with a penalty for curvature and for changing it (a path level 3 can
  smooth); the heuristic is the distance to the goal, weighted by :data:`GREED`.

The path is what level 1 takes as proof that the turn can be made, and what the route
corridor takes as its reference through the junction
(:func:`splineplan.network.route_corridor`). The kinematic oracle of the benchmarks
judges it independently.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit
from numpy.typing import NDArray

from splineplan.geometry import FloatArray, kernel_floats

#: Raster cell [m] of the paving.
CELL = 0.1
#: Gaps [m] between paved pieces that count as paved.
GAP = 0.3
#: Discs that cover the car's rectangle.
DISCS = 6
#: How far [m] a disc may reach beyond the paving (the discs overreach the rectangle's
#: sides by about 8 cm).
SLACK = -0.06
#: Arc length [m] of a step of the search.
STEP = 0.5
#: Position cell [m] and heading bins of the search's visited set.
BOX = 0.25
BINS = 72
#: Shares of the turning limit the search's arcs use, tried in turn (a path below the
#: limit leaves level 3's curve room).
TURN_SHARES = (0.85, 1.0)
#: Weight of the heuristic (above 1: greedier, faster, a little longer paths).
GREED = 1.5
#: Cost per metre per unit of the curvature's share of the limit, and per change of it.
CURVE_COST = 0.3
CHANGE_COST = 0.6
#: Most poses the search expands.
MAX_EXPAND = 200_000
#: Largest heading error [rad] at the goal.
GOAL_HEADING = 0.12


def paving_raster(xs: FloatArray, ys: FloatArray, offsets: NDArray[np.int64],
                  bounds: tuple[float, float, float, float]
                  ) -> tuple[FloatArray, float, float]:
    """Clearance [m] of each cell centre of a grid over ``bounds`` (x0, y0, x1, y1) to the
    ground outside the packed polygons (``xs``, ``ys``, ``offsets``; see
    :func:`splineplan.network._packed`), and the grid's origin ``(x0, y0)``."""
    from scipy.ndimage import binary_closing, distance_transform_edt

    x0, y0, x1, y1 = bounds
    nx = max(math.ceil((x1 - x0) / CELL), 1)
    ny = max(math.ceil((y1 - y0) / CELL), 1)
    mask = _fill(kernel_floats(xs), kernel_floats(ys), offsets, x0, y0, nx, ny, CELL)
    r = max(math.ceil(GAP / 2.0 / CELL), 1)
    yy, xx = np.mgrid[-r:r + 1, -r:r + 1]
    mask = binary_closing(mask, structure=(xx * xx + yy * yy) <= r * r, border_value=0)
    clear = distance_transform_edt(mask) * CELL - CELL / 2.0
    return np.ascontiguousarray(clear, dtype=float), x0, y0


@njit(cache=True)
def _fill(xs: FloatArray, ys: FloatArray, offsets: NDArray[np.int64], x0: float, y0: float,
          nx: int, ny: int, cell: float) -> NDArray[np.bool_]:
    """Cells ``(ny, nx)`` whose centre lies in some polygon (even-odd, per polygon)."""
    mask = np.zeros((ny, nx), dtype=np.bool_)
    xc = np.empty(64)
    for p in range(len(offsets) - 1):
        a, b = offsets[p], offsets[p + 1]
        n = b - a
        if n < 3:
            continue
        lo = ys[a:b].min()
        hi = ys[a:b].max()
        j0 = max(math.floor((lo - y0) / cell - 0.5), 0)
        j1 = min(math.ceil((hi - y0) / cell - 0.5), ny - 1)
        if n > len(xc):
            xc = np.empty(n)
        for j in range(j0, j1 + 1):
            yc = y0 + (j + 0.5) * cell
            m = 0
            for k in range(n):
                xa, ya = xs[a + k], ys[a + k]
                xb, yb = xs[a + (k + 1) % n], ys[a + (k + 1) % n]
                if (ya <= yc < yb) or (yb <= yc < ya):
                    xc[m] = xa + (yc - ya) * (xb - xa) / (yb - ya)
                    m += 1
            for q in range(1, m):  # insertion sort: a few crossings a row
                v = xc[q]
                r = q - 1
                while r >= 0 and xc[r] > v:
                    xc[r + 1] = xc[r]
                    r -= 1
                xc[r + 1] = v
            for q in range(0, m - 1, 2):
                i0 = max(math.ceil((xc[q] - x0) / cell - 0.5), 0)
                i1 = min(math.floor((xc[q + 1] - x0) / cell - 0.5), nx - 1)
                for i in range(i0, i1 + 1):
                    mask[j, i] = True
    return mask


@njit(cache=True, inline="always")
def _pose_clear(clear: FloatArray, x0: float, y0: float, x: float, y: float, th: float,
                fr: FloatArray, need: float) -> bool:
    """Whether every disc of the car at pose (x, y, th) keeps ``need`` [m] of clearance."""
    ny, nx = clear.shape
    c, s = math.cos(th), math.sin(th)
    for k in range(len(fr)):
        px = x + fr[k] * c
        py = y + fr[k] * s
        i = int((px - x0) / CELL)
        j = int((py - y0) / CELL)
        if i < 0 or j < 0 or i >= nx or j >= ny:
            return False
        if clear[j, i] < need:
            return False
    return True


@njit(cache=True)
def _search(clear: FloatArray, x0: float, y0: float, starts: FloatArray, goals: FloatArray,
            goal_tol: FloatArray, fr: FloatArray, need: float, kappa: float,
            max_expand: int) -> FloatArray:
    """Hybrid A* over the raster (see :func:`search`): the path's poses ``(n, 3)``,
    start first; none where no goal is reached."""
    ny, nx = clear.shape
    bx = int(nx * CELL / BOX) + 1
    by = int(ny * CELL / BOX) + 1
    seen = np.zeros((by, bx, BINS), dtype=np.bool_)
    cap = max_expand * 5 + len(starts) + 1
    X = np.empty(cap)
    Y = np.empty(cap)
    T = np.empty(cap)
    G = np.empty(cap)
    K = np.empty(cap, dtype=np.int64)
    P = np.empty(cap, dtype=np.int64)
    heap_f = np.empty(cap)
    heap_n = np.empty(cap, dtype=np.int64)
    size = 0
    count = 0
    curv = np.array([-1.0, -0.5, 0.0, 0.5, 1.0])
    for q in range(len(starts)):
        X[count], Y[count], T[count] = starts[q, 0], starts[q, 1], starts[q, 2]
        G[count], K[count], P[count] = 0.0, 2, -1
        h = _heuristic(goals, X[count], Y[count])
        # push
        heap_f[size], heap_n[size] = GREED * h, count
        _sift_up(heap_f, heap_n, size)
        size += 1
        count += 1
    expanded = 0
    while size > 0 and expanded < max_expand:
        node = heap_n[0]
        size -= 1
        heap_f[0], heap_n[0] = heap_f[size], heap_n[size]
        _sift_down(heap_f, heap_n, size)
        x, y, th = X[node], Y[node], T[node]
        ci = int((x - x0) / BOX)
        cj = int((y - y0) / BOX)
        ck = int(((th % (2.0 * math.pi)) / (2.0 * math.pi)) * BINS) % BINS
        if ci < 0 or cj < 0 or ci >= bx or cj >= by or seen[cj, ci, ck]:
            continue
        seen[cj, ci, ck] = True
        expanded += 1
        # at a goal?
        for g in range(len(goals)):
            dx, dy = x - goals[g, 0], y - goals[g, 1]
            if dx * dx + dy * dy <= goal_tol[g] * goal_tol[g]:
                dh = (th - goals[g, 2] + math.pi) % (2.0 * math.pi) - math.pi
                if abs(dh) <= GOAL_HEADING:
                    m = 0
                    at = node
                    while at >= 0:
                        m += 1
                        at = P[at]
                    out = np.empty(m, dtype=np.int64)
                    at = node
                    for q in range(m - 1, -1, -1):
                        out[q] = at
                        at = P[at]
                    path = np.empty((m, 3))
                    for q in range(m):
                        path[q, 0], path[q, 1], path[q, 2] = X[out[q]], Y[out[q]], T[out[q]]
                    return path
        for a in range(5):
            k = curv[a] * kappa
            if abs(k) > 1e-12:
                nth = th + k * STEP
                nxp = x + (math.sin(nth) - math.sin(th)) / k
                nyp = y - (math.cos(nth) - math.cos(th)) / k
                mth = th + k * STEP / 2.0
                mx = x + (math.sin(mth) - math.sin(th)) / k
                my = y - (math.cos(mth) - math.cos(th)) / k
            else:
                nth = th
                nxp = x + STEP * math.cos(th)
                nyp = y + STEP * math.sin(th)
                mth = th
                mx = x + STEP / 2.0 * math.cos(th)
                my = y + STEP / 2.0 * math.sin(th)
            if not _pose_clear(clear, x0, y0, nxp, nyp, nth, fr, need):
                continue
            if not _pose_clear(clear, x0, y0, mx, my, mth, fr, need):
                continue
            ni = int((nxp - x0) / BOX)
            nj = int((nyp - y0) / BOX)
            nk = int(((nth % (2.0 * math.pi)) / (2.0 * math.pi)) * BINS) % BINS
            if ni < 0 or nj < 0 or ni >= bx or nj >= by or seen[nj, ni, nk]:
                continue
            if count >= cap:
                break
            g = (G[node] + STEP * (1.0 + CURVE_COST * abs(curv[a]))
                 + CHANGE_COST * abs(curv[a] - curv[K[node]]))
            X[count], Y[count], T[count] = nxp, nyp, nth
            G[count], K[count], P[count] = g, a, node
            heap_f[size] = g + GREED * _heuristic(goals, nxp, nyp)
            heap_n[size] = count
            _sift_up(heap_f, heap_n, size)
            size += 1
            count += 1
    return np.empty((0, 3))


@njit(cache=True, inline="always")
def _heuristic(goals: FloatArray, x: float, y: float) -> float:
    best = 1e18
    for g in range(len(goals)):
        dx, dy = x - goals[g, 0], y - goals[g, 1]
        d = dx * dx + dy * dy
        if d < best:
            best = d
    return math.sqrt(best)


@njit(cache=True, inline="always")
def _sift_up(f: FloatArray, n: NDArray[np.int64], i: int) -> None:
    while i > 0:
        p = (i - 1) // 2
        if f[p] <= f[i]:
            break
        f[p], f[i] = f[i], f[p]
        n[p], n[i] = n[i], n[p]
        i = p


@njit(cache=True, inline="always")
def _sift_down(f: FloatArray, n: NDArray[np.int64], size: int) -> None:
    i = 0
    while True:
        a = 2 * i + 1
        if a >= size:
            break
        b = a + 1
        c = b if b < size and f[b] < f[a] else a
        if f[i] <= f[c]:
            break
        f[c], f[i] = f[i], f[c]
        n[c], n[i] = n[i], n[c]
        i = c


def search(polygons: tuple[FloatArray, FloatArray, NDArray[np.int64]], starts: FloatArray,
           goals: FloatArray, goal_tol: FloatArray, *, length: float, width: float,
           kappa_max: float) -> FloatArray | None:
    """Poses ``(n, 3)`` (x, y [m], heading [rad]) every :data:`STEP` metres of a path on
    the paved ``polygons`` (packed) for a car ``length`` x ``width`` [m] whose centre turns
    at most at ``kappa_max`` [1/m], from one of the ``starts`` ``(k, 3)`` to within
    ``goal_tol`` ``(m,)`` [m] of one of the ``goals`` ``(m, 3)`` (position and heading,
    within :data:`GOAL_HEADING`); ``None`` where there is none."""
    starts = np.ascontiguousarray(np.asarray(starts, dtype=float).reshape(-1, 3))
    goals = np.ascontiguousarray(np.asarray(goals, dtype=float).reshape(-1, 3))
    tol = np.ascontiguousarray(goal_tol, dtype=float)
    pts = np.vstack((starts[:, :2], goals[:, :2]))
    reach = length + 12.0
    lo = pts.min(axis=0) - reach
    hi = pts.max(axis=0) + reach
    xs, ys, offs = polygons
    clear, x0, y0 = paving_raster(xs, ys, offs, (float(lo[0]), float(lo[1]),
                                                 float(hi[0]), float(hi[1])))
    a = length / (2.0 * DISCS)
    fr = (np.arange(DISCS) - (DISCS - 1) / 2.0) * 2.0 * a
    radius = math.hypot(a, width / 2.0)
    for share in TURN_SHARES:
        res = _search(clear, x0, y0, starts, goals, tol, fr,
                      radius - SLACK, share * kappa_max, MAX_EXPAND)
        if len(res):
            return res
    return None
