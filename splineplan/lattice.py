"""A passage for a car that turns, where level 2's stretched obstacles close the road.

Level 2 models the vehicle as a disc of its width among obstacles stretched along the road
for its corners (:func:`splineplan.planner.elongate_for_roadmap`): exact for a car parallel
to the road. Between obstacles staggered in neighbouring lanes, a car driving diagonally
passes where those stretched obstacles overlap, and level 2 finds the road blocked. This
search looks for such a passage with the car's own rectangle and turning limit:

- nodes stand on sweep lines every ``RoadmapParams.d`` [m] from the vehicle's station, at
  lateral steps of :data:`STEP` [m] through the vehicle's offset; each is reached with the
  heading of the step into it (at most :data:`MAX_ANGLE` off the road's);
- each node's footprint, the rectangle at that heading, keeps the safety margin from the
  obstacles (level 3's exact check, :class:`splineplan.footprint._Checker`) and the road
  margin from the road's edges (at its corners, in the road's frame at their stations);
- from step to step the heading turns by no more than the turning limit allows over the
  step, the road's own bend counted.

The path is the widest (the footprint's clearance beyond the margins, counted up to
``wmax / 2`` as level 2 counts widths up to ``wmax``), then the shortest: two dynamic
programmes over the lines, which form a layered acyclic graph. Level 3 then smooths it and
checks every sample's footprint, as it does level 2's path.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Iterator

import numpy as np
from numba import njit
from numpy.typing import ArrayLike, NDArray

from splineplan.corridor import Corridor
from splineplan.footprint import _Checker
from splineplan.geometry import FloatArray, kernel_floats, polyline_stations, wrap_angle
from splineplan.obstacles import Obstacles
from splineplan.roadmap import Roadmap, RoadmapParams

log = logging.getLogger(__name__)

#: Lateral step [m] of the nodes on a sweep line.
STEP = 0.05
#: Largest angle [rad] between the car's heading and the road's at a node.
MAX_ANGLE = 0.8
#: Shares of the turning limit that the heading's change between steps may use, each
#: giving a passage (see :func:`turning_passages`).
TURN_SHARES = (0.9, 0.75, 1.0)
#: Distance [m] either side of where level 2 found the road closed within which the
#: lines are looked at first (see :func:`turning_passages`).
NEAR_CLOSURE = 4.5


def turning_passages(corridor: Corridor, obstacles: Obstacles, start_xy: ArrayLike,
                     start_heading: float | None, params: RoadmapParams, kappa_max: float,
                     road_margin: float | None = None, blocked_at: float | None = None
                     ) -> Iterator[Roadmap]:
    """The widest, then shortest, paths of a car with the turning limit ``kappa_max``
    [1/m] from ``start_xy`` (heading ``start_heading`` [rad], ``None``: any) to the
    corridor's end among the ``obstacles`` (not grown), each as a :class:`Roadmap` whose
    graph is the path itself: one per share of :data:`TURN_SHARES` of the limit that the
    steps may use, the widest first (a curve through the nodes turns a little harder
    than the steps, and smooths their corners; which share leaves level 3 a feasible
    curve differs from passage to passage). Nothing where no node of the corridor's end
    is reached.

    ``road_margin`` [m]: what the footprint keeps from the road's edges (default
    ``params.road_margin``). ``blocked_at`` [m]: the corridor station where level 2
    found the road closed; the lines within :data:`NEAR_CLOSURE` of it are looked at
    first, and where one of them has no node that keeps the margins at any heading,
    there is no passage.
    """
    start = np.asarray(start_xy, dtype=float).reshape(2)
    s0, l0 = (float(v) for v in corridor.to_sl(start[None])[0])
    end = corridor.length
    if end - s0 < params.d:
        return
    st = np.arange(s0, end - 1e-6, params.d)
    if end - st[-1] > 1e-6:
        st = np.append(st, end)
    lo, hi = corridor.bounds_at(st)
    hw = params.vehicle_width / 2.0
    j_lo = math.floor((float(lo.min()) + hw - l0) / STEP)
    j_hi = math.ceil((float(hi.max()) - hw - l0) / STEP)
    lat = l0 + STEP * np.arange(min(j_lo, 0), max(j_hi, 0) + 1, dtype=float)
    j0 = int(np.argmin(np.abs(lat - l0)))
    ds = np.diff(st)
    reach = math.floor(math.tan(MAX_ANGLE) * float(ds.max()) / STEP)
    moves = np.arange(-reach, reach + 1)
    # the angle of each move off the road's heading, per step: (lines - 1, moves)
    angle = np.arctan2(moves[None, :] * STEP, ds[:, None])
    road_head = np.asarray(corridor.heading_at(st), dtype=float)
    cap = params.wmax / 2.0
    rm = params.road_margin if road_margin is None else road_margin
    # from the move a into line i, the moves into line i + 1 whose change of heading,
    # with the road's own turn, keeps within a share of the turning limit
    a_in = np.vstack((angle[:1], angle[:-1]))
    aim = a_in - wrap_angle(np.diff(road_head))[:, None]

    def spans(share: float) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
        turn = share * kappa_max * ds[:, None]
        low = np.tan(np.clip(aim - turn, -1.5, 1.5)) * ds[:, None] / STEP
        high = np.tan(np.clip(aim + turn, -1.5, 1.5)) * ds[:, None] / STEP
        return (np.clip(np.ceil(low - 1e-9), -reach, reach + 1).astype(np.int64) + reach,
                np.clip(np.floor(high + 1e-9), -reach - 1, reach).astype(np.int64) + reach)

    length = kernel_floats(np.hypot(ds[:, None], moves[None, :] * STEP))
    if blocked_at is not None:
        # the lines round the closure: one without a node that keeps the margins at any
        # heading closes the road
        k0, k1 = np.searchsorted(st, [blocked_at - NEAR_CLOSURE, blocked_at + NEAR_CLOSURE])
        k0, k1 = max(int(k0), 1), min(int(k1), len(st) - 1)
        if k1 >= k0:
            near = _clearances(corridor, obstacles, params, st[k0 - 1:k1 + 1], lat,
                               road_head[k0 - 1:k1 + 1], angle[k0 - 1:k1], cap, rm)
            if np.any(near.max(axis=(1, 2)) < 0.0):
                return
    clear = _clearances(corridor, obstacles, params, st, lat, road_head, angle, cap, rm)
    # the start: the vehicle's node, with the move nearest its heading
    first = np.full((len(lat), len(moves)), -np.inf)
    if start_heading is None:
        first[j0, :] = cap
    else:
        off = float(wrap_angle(start_heading - road_head[0]))
        first[j0, int(np.argmin(np.abs(angle[0] - off)))] = cap
    found: dict[bytes, tuple[float, float, NDArray[np.int64]]] = {}
    for share in TURN_SHARES:
        idx = np.zeros(len(st), dtype=np.int64)
        best = _search(first, clear, *spans(share), length, reach, cap, idx)
        if best >= 0.0 and idx.tobytes() not in found:
            found[idx.tobytes()] = (best, share, idx)
    # the widest first (a tie keeps the shares' order)
    for best, share, idx in sorted(found.values(), key=lambda f: -f[0]):
        lats = lat[idx]
        mv = np.diff(idx) + reach
        width = np.concatenate(([cap], clear[np.arange(len(ds)), idx[1:], mv]))
        log.debug("turning passage (%.2f of the turning limit): %d lines, clearance %.2f m "
                  "beyond the margins", share, len(st), best)
        yield _as_roadmap(corridor.to_xy(st, lats), st, lats, width, start, params)


def _clearances(corridor: Corridor, obstacles: Obstacles, params: RoadmapParams,
                st: FloatArray, lat: FloatArray, road_head: FloatArray, angle: FloatArray,
                cap: float, road_margin: float) -> FloatArray:
    """``(lines - 1, offsets, moves)``: the clearance [m] beyond the margins of the
    footprint at node ``(line + 1, offset)`` reached by each move (``-inf``: beyond
    :data:`MAX_ANGLE`), at most ``cap``. The road's edges are measured at the
    footprint's corners, in the road's frame at their stations (level 3 then checks the
    curve exactly); the obstacles exactly, where one is near."""
    n_steps, n_lat, n_mv = len(st) - 1, len(lat), angle.shape[1]
    hl, hw = params.vehicle_length / 2.0, params.vehicle_width / 2.0
    c, s_ = np.cos(angle), np.sin(angle)
    road = np.full((n_steps, n_lat, n_mv), np.inf)
    for fx, fy in ((hl, hw), (hl, -hw), (-hl, hw), (-hl, -hw)):
        ds_c = fx * c - fy * s_  # (steps, moves): the corner's station and offset
        dl_c = fx * s_ + fy * c  # change from the node's
        sc = st[1:, None] + ds_c
        right, left = corridor.bounds_at(sc.ravel())
        lc = lat[None, :, None] + dl_c[:, None, :]
        road = np.minimum(road, np.minimum(left.reshape(sc.shape)[:, None, :] - lc,
                                           lc - right.reshape(sc.shape)[:, None, :]))
    out = np.minimum(road - road_margin, cap)
    out[~(np.abs(angle) <= MAX_ANGLE + 1e-9)[:, None, :].repeat(n_lat, axis=1)] = -np.inf
    if len(obstacles):
        # the lines an obstacle's footprint check can reach
        so = corridor.to_sl(obstacles.vertices)[:, 0]
        first = obstacles.offsets[:-1]
        o_lo = np.minimum.reduceat(so, first)
        o_hi = np.maximum.reduceat(so, first)
        near = np.hypot(hl, hw) + params.safety_margin + cap
        lines = np.flatnonzero(np.any((st[1:, None] >= o_lo[None, :] - near)
                                      & (st[1:, None] <= o_hi[None, :] + near), axis=1))
        cand = np.zeros(out.shape, dtype=bool)
        cand[lines] = out[lines] >= 0.0
        ii, jj, mm = np.nonzero(cand)
        if len(ii):
            s = st[ii + 1]
            xy = corridor.to_xy(s, lat[jj])
            head = road_head[ii + 1] + angle[ii, mm]
            checker = _Checker.build(corridor, obstacles, params, xy, road_margin)
            obs = checker.obstacles(xy, head, horizon=cap) - params.safety_margin
            out[ii, jj, mm] = np.minimum(out[ii, jj, mm], obs)
    return kernel_floats(out)


@njit(cache=True)
def _search(first: FloatArray, clear: FloatArray, m_lo: NDArray[np.int64],
            m_hi: NDArray[np.int64], length: FloatArray, reach: int, cap: float,
            idx: NDArray[np.int64]) -> float:  # pragma: no cover
    """The two dynamic programmes over the lines: the largest bottleneck clearance of a
    path from the start's nodes (``first``: their values, ``-inf`` elsewhere) to the
    last line, then the shortest path through the nodes that keep it (up to ``cap``),
    whose offset indices go to ``idx``. From the move ``a`` into line ``i``, the moves
    ``m_lo[i, a] .. m_hi[i, a]`` go on. Returns the bottleneck (``-inf``: no path)."""
    n_steps, n_lat, n_mv = clear.shape
    value = first.copy()
    nxt = np.empty_like(value)
    for i in range(n_steps):
        nxt[:, :] = -np.inf
        for j in range(n_lat):
            for a in range(n_mv):
                v = value[j, a]
                if v == -np.inf:
                    continue
                for m in range(m_lo[i, a], m_hi[i, a] + 1):
                    jn = j + m - reach
                    if jn < 0 or jn >= n_lat:
                        continue
                    w = min(v, clear[i, jn, m])
                    if w > nxt[jn, m]:
                        nxt[jn, m] = w
        value[:, :] = nxt
    best = value.max()
    if not best >= 0.0:
        return best
    keep = min(best, cap) - 1e-9
    cost = np.where(first > -np.inf, 0.0, np.inf)
    back = np.full((n_steps, n_lat, n_mv), -1, dtype=np.int64)
    for i in range(n_steps):
        nxt[:, :] = np.inf
        for j in range(n_lat):
            for a in range(n_mv):
                c0 = cost[j, a]
                if c0 == np.inf:
                    continue
                for m in range(m_lo[i, a], m_hi[i, a] + 1):
                    jn = j + m - reach
                    if jn < 0 or jn >= n_lat or clear[i, jn, m] < keep:
                        continue
                    c1 = c0 + length[i, m]
                    if c1 < nxt[jn, m]:
                        nxt[jn, m] = c1
                        back[i, jn, m] = a
        cost[:, :] = nxt
    k = np.argmin(cost)
    j, m = k // n_mv, k % n_mv
    idx[n_steps] = j
    for i in range(n_steps - 1, -1, -1):
        a = back[i, j, m]
        j = j - (m - reach)
        idx[i] = j
        m = a
    return best


def _as_roadmap(xy: FloatArray, st: FloatArray, lats: FloatArray, width: FloatArray,
                start: FloatArray, params: RoadmapParams) -> Roadmap:
    """The path as a roadmap whose graph is the path: one vertex per line, its interval
    the node itself, so that level 3's control polygon keeps to the passage (through
    intervals as wide as the nodes' clearance, its curves cut the passage's corners
    towards the obstacles: on staggered obstacles 3.5-4.5 m apart they kept 0.31-0.37 m
    instead of 0.45-0.83). Placed (``params.place``), the nodes are level 3's bands too,
    and their clearance (up to :attr:`RoadmapParams.enough_separation`) the separation
    its smoothing keeps."""
    m = len(st)
    j = int(np.argmin(width))
    line = np.arange(m, dtype=np.int64)
    lo, hi = lats.copy(), lats.copy()
    placed = {}
    if params.place:
        placed = {"band_lo": lo.copy(), "band_hi": hi.copy(),
                  "separation": np.minimum(width, params.enough_separation)}
    return Roadmap(
        xy=xy, s=st.copy(), l=lats.copy(), width=width.copy(),
        bottleneck_width=float(width[j]), bottleneck_index=j,
        length=float(polyline_stations(xy)[-1]),
        graph_xy=xy.copy(), graph_s=st.copy(), graph_l=lats.copy(), graph_width=width.copy(),
        graph_line=line, graph_lo=lo, graph_hi=hi,
        arcs=np.column_stack((line[:-1], line[1:])), path=line.copy(),
        start_xy=start.copy(), params=params, arc_direct=np.ones(m - 1, dtype=bool),
        **placed)
