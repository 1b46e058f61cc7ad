"""Compiled inner loops: level 3's footprint check and equation (3)'s rounds, and the
rectangle distances of the closed loop (bodies, plans, pairs of vehicles).

Level 3 checks the vehicle's footprint a few thousand times per route on tens to hundreds
of curve samples each, and the closed loop measures rectangles against a path at every
step of every planned vehicle; as array code they spent most of their time in the overhead
of small numpy calls. These loops run over the samples one at a time, compiled with numba
and cached on disk after the first run. The thin callers are
:class:`splineplan.footprint._Checker`, :class:`splineplan.optimiser._Optimiser`,
:func:`splineplan.spacetime.box_gap` and :func:`splineplan.closedloop.bodies.meetings`.

The kernels that call one another live in this one file on purpose: numba's on-disk cache
is invalidated per file, so a kernel calling a kernel of another file would keep running
the old code after that file changed.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numba import njit
from numpy.typing import NDArray

from splineplan.geometry import FloatArray


@njit(cache=True)
def upper(a: FloatArray, x: float) -> int:  # pragma: no cover - compiled
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
def lower(a: FloatArray, x: float) -> int:  # pragma: no cover - compiled
    """``np.searchsorted(a, x, side="left")`` for a sorted ``a``."""
    lo, hi = 0, len(a)
    while lo < hi:
        mid = (lo + hi) // 2
        if a[mid] < x:
            lo = mid + 1
        else:
            hi = mid
    return lo


@njit(cache=True, inline="always")
def segment(st: FloatArray, s: float, guess: int = -1) -> int:  # pragma: no cover
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
    return upper(st[1:-1], s)


@njit(cache=True, inline="always")
def interp_near(x: float, xp: FloatArray, fp: FloatArray, guess: int) -> float:
    """``np.interp`` at one point, searching from the interval ``guess`` nearby."""
    n = len(xp)
    if x <= xp[0]:
        return float(fp[0])
    if x >= xp[n - 1]:
        return float(fp[n - 1])
    k = segment(xp, x, guess)
    return float((fp[k + 1] - fp[k]) / (xp[k + 1] - xp[k]) * (x - xp[k]) + fp[k])


@njit(cache=True)
def road_one(x: float, y: float, h: float, sc: float, st: FloatArray, rx: FloatArray,
             ry: FloatArray, hc: FloatArray, hs: FloatArray, left: FloatArray,
             right: FloatArray, bu: FloatArray, bv: FloatArray, cs: FloatArray,
             cx: FloatArray, cy: FloatArray, cside: FloatArray, hl: float, hw: float,
             band: float, reach: float, guess: int
             ) -> tuple[float, float, float]:  # pragma: no cover - compiled
    """Footprint of one pose to the left and right road edges [m], and its station [m]
    (see :meth:`splineplan.footprint._Checker.road`; ``guess``: a reference segment near
    station ``sc``)."""
    c, s = np.cos(h), np.sin(h)
    i0 = segment(st, sc, guess)
    to_left = to_right = np.inf
    station = sc
    for p in range(len(bu)):
        px = (x + c * bu[p]) - s * bv[p]
        py = (y + s * bu[p]) + c * bv[p]
        est = st[i0] + ((px - rx[i0]) * hc[i0] + (py - ry[i0]) * hs[i0])
        i = segment(st, est, i0)
        dx, dy = px - rx[i], py - ry[i]
        along = st[i] + dx * hc[i] + dy * hs[i]
        lat = dy * hc[i] - dx * hs[i]
        if p == len(bu) - 1:  # the centre
            station = along
        else:
            if st[i] <= along < st[i + 1]:  # np.interp's interval is i: no search
                ds = st[i + 1] - st[i]
                lv = (left[i + 1] - left[i]) / ds * (along - st[i]) + left[i]
                rv = (right[i + 1] - right[i]) / ds * (along - st[i]) + right[i]
            else:
                lv = interp_near(along, st, left, i)
                rv = interp_near(along, st, right, i)
            to_left = min(to_left, lv - lat)
            to_right = min(to_right, lat - rv)
    if min(to_left, to_right) < band:
        # the edges' inward vertices near the centre's station, by rectangle-point distance
        for k in range(lower(cs, station - reach), upper(cs, station + reach)):
            dx, dy = cx[k] - x, cy[k] - y
            gu = abs(dx * c + dy * s) - hl
            gv = abs(dy * c - dx * s) - hw
            now = to_left if cside[k] > 0 else to_right
            if max(gu, gv) >= now:  # the distance is at least max(gu, gv): no lower
                continue
            inside = gu <= 0 and gv <= 0
            d = max(gu, gv) if inside else np.hypot(max(gu, 0.0), max(gv, 0.0))
            if cside[k] > 0:
                to_left = min(to_left, d)
            else:
                to_right = min(to_right, d)
    return to_left, to_right, station


@njit(cache=True)
def road_clearance(x: FloatArray, y: FloatArray, h: FloatArray, sc: FloatArray, st: FloatArray,
                   rx: FloatArray, ry: FloatArray, hc: FloatArray, hs: FloatArray,
                   left: FloatArray, right: FloatArray, bu: FloatArray, bv: FloatArray,
                   cs: FloatArray, cx: FloatArray, cy: FloatArray, cside: FloatArray,
                   hl: float, hw: float, road_margin: float, band: float, reach: float
                   ) -> tuple[FloatArray, FloatArray, FloatArray]:  # pragma: no cover
    """:meth:`splineplan.footprint._Checker.road` for each pose: to the left edge [m], to
    the right [m], stations [m]."""
    n = len(x)
    to_left, to_right, station = np.empty(n), np.empty(n), np.empty(n)
    # the previous sample's segment (samples run along the curve); typed int64 from the
    # start: a literal -1 would compile road_one once more for it
    i = np.int64(-1)
    for j in range(n):
        i = segment(st, sc[j], i)
        to_left[j], to_right[j], station[j] = road_one(
            x[j], y[j], h[j], sc[j], st, rx, ry, hc, hs, left, right, bu, bv, cs, cx, cy,
            cside, hl, hw, band, reach, i)
    return to_left, to_right, station


@njit(cache=True)
def footprint_slack(x: FloatArray, y: FloatArray, h: FloatArray, sc: FloatArray,
                    st: FloatArray, rx: FloatArray, ry: FloatArray, hc: FloatArray,
                    hs: FloatArray, left: FloatArray, right: FloatArray, bu: FloatArray,
                    bv: FloatArray, cs: FloatArray, cx: FloatArray, cy: FloatArray,
                    cside: FloatArray, hl: float, hw: float, road_margin: float, band: float,
                    reach: float, lmin: FloatArray, rmax: FloatArray, turn: FloatArray,
                    seg_heading: FloatArray, vx: FloatArray, vy: FloatArray,
                    offsets: NDArray[np.int64], bbox: FloatArray, obs_margin: float
                    ) -> tuple[FloatArray, FloatArray]:  # pragma: no cover - compiled
    """:meth:`splineplan.footprint._Checker.slack`: clearance beyond the margins [m]
    (``road_margin`` from the road edges, ``obs_margin`` from the obstacles) and stations
    [m]."""
    n = len(x)
    road = np.empty(n)
    station = np.empty(n)
    i = np.int64(-1)  # the previous sample's segment, as in road_clearance
    for j in range(n):
        # the centre in the frame of the reference segment at its station (from the
        # estimate, one step of refinement)
        s_new = sc[j]
        dx = dy = 0.0
        for _ in range(2):
            i = segment(st, s_new, i)
            dx, dy = x[j] - rx[i], y[j] - ry[i]
            s_new = st[i] + dx * hc[i] + dy * hs[i]
        lat = dy * hc[i] - dx * hs[i]
        # clearly on the road (a lower bound of the clearance is above the margin): no
        # exact check of the footprint
        dh = h[j] - seg_heading[i]
        ext = (hl * abs(np.sin(dh)) + hw * abs(np.cos(dh))
               + (abs(lat) + hl + hw) * turn[i] + 0.05)
        r = min(lmin[i] - lat, lat - rmax[i]) - ext
        if r < road_margin + 1e-6:
            tl, tr, s_new = road_one(x[j], y[j], h[j], sc[j], st, rx, ry, hc, hs, left,
                                      right, bu, bv, cs, cx, cy, cside, hl, hw, band, reach,
                                      i)
            r = min(tl, tr)
        road[j] = r
        station[j] = s_new
    # np.bool_: a literal True would compile obstacle_clearance once more beside the bool
    # that Python calls pass
    near = obstacle_clearance(x, y, h, vx, vy, offsets, bbox, hl, hw, obs_margin, 0.0,
                              np.bool_(True))
    return np.minimum(near - obs_margin, road - road_margin), station


@njit(cache=True)
def obstacle_clearance(x: FloatArray, y: FloatArray, h: FloatArray, vx: FloatArray,
                       vy: FloatArray, offsets: NDArray[np.int64], bbox: FloatArray,
                       hl: float, hw: float, margin: float, horizon: float, cull: bool
                       ) -> FloatArray:  # pragma: no cover - compiled
    """:meth:`splineplan.footprint._Checker.obstacles`: each pose's footprint to the
    nearest obstacle [m]."""
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
            out[j] = min(out[j], rect_polygon_distance(u[:m], v[:m], hl, hw))
    return out


@njit(cache=True)
def rect_polygon_distance(u: FloatArray, v: FloatArray, hl: float, hw: float
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


@njit(cache=True)
def optimise(ctrl: FloatArray, pos: FloatArray, d1: FloatArray, d2: FloatArray,
             kappa: FloatArray, slack: FloatArray, station: FloatArray,
             first: NDArray[np.int64], basis: FloatArray, lo: NDArray[np.int64],
             hi: NDArray[np.int64], cand: NDArray[np.int64], movable: NDArray[np.bool_],
             refused: NDArray[np.bool_], k: int, kappa_smax: float, kappa_max: float,
             max_iterations: int, patience: int, floor: FloatArray,
             checker: tuple[Any, ...]
             ) -> tuple[int, int, int, int]:  # pragma: no cover - compiled
    """:meth:`splineplan.optimiser._Optimiser.run` on the optimiser's arrays, changed in
    place (the best curve seen at the end); ``floor`` ``(m,)`` [m]: the clearance from
    the obstacles beyond the safety margin below which no move brings a sample that kept
    it (:func:`separation_kept`); ``checker``: the footprint check's arrays and sizes, as
    :func:`footprint_slack` takes them after the samples."""
    n = len(ctrl)
    tried = accepted = refused_count = rounds = 0
    best_worst = kappa.max()
    best = (ctrl.copy(), pos.copy(), d1.copy(), d2.copy(), kappa.copy(), slack.copy(),
            station.copy())
    idle = 0
    bad = np.zeros(n)
    while tried < max_iterations and idle < patience:
        # for each slow sample, the first of its shaping control points (by Greville
        # distance) that may move: not fixed, not refused since the last accepted move
        # nearby, not already at its neighbours' mean; the worst sample per control point
        eligible = movable & ~refused
        for i in range(1, n - 1):
            mx = ctrl[i, 0] - 0.5 * (ctrl[i - 1, 0] + ctrl[i + 1, 0])
            my = ctrl[i, 1] - 0.5 * (ctrl[i - 1, 1] + ctrl[i + 1, 1])
            if np.hypot(mx, my) < 1e-9:
                eligible[i] = False
        for i in range(n):  # loops, not slice assignments: those compile slowly
            bad[i] = 0.0
        any_slow = False
        for j in range(len(kappa)):
            if kappa[j] > kappa_smax * (1.0 + 1e-9):
                any_slow = True
                for c in cand[j]:
                    if eligible[c]:
                        bad[c] = max(bad[c], kappa[j])
                        break
        if not any_slow or not (bad > 0).any():
            break
        chosen = independent_moves(bad, k, max_iterations - tried)
        rounds += 1
        tried += len(chosen)
        acc = try_moves(chosen, ctrl, pos, d1, d2, kappa, slack, station, first, basis, lo,
                         hi, kappa_max, floor, checker)
        n_acc = int(acc.sum())
        accepted += n_acc
        refused_count += len(chosen) - n_acc
        for m in range(len(chosen)):
            if not acc[m]:
                refused[chosen[m]] = True
        for m in range(len(chosen)):
            if acc[m]:
                for i in range(max(chosen[m] - k, 0), min(chosen[m] + k + 1, n)):
                    refused[i] = False
        worst = kappa.max()
        if worst < best_worst - 1e-12 and n_acc > 0:
            best_worst = worst
            best = (ctrl.copy(), pos.copy(), d1.copy(), d2.copy(), kappa.copy(), slack.copy(),
                    station.copy())
            idle = 0
        else:
            idle += 1
    if kappa.max() > best_worst + 1e-12:
        b_ctrl, b_pos, b_d1, b_d2, b_kappa, b_slack, b_station = best
        for i in range(n):
            ctrl[i, 0], ctrl[i, 1] = b_ctrl[i, 0], b_ctrl[i, 1]
        for j in range(len(kappa)):
            pos[j, 0], pos[j, 1] = b_pos[j, 0], b_pos[j, 1]
            d1[j, 0], d1[j, 1] = b_d1[j, 0], b_d1[j, 1]
            d2[j, 0], d2[j, 1] = b_d2[j, 0], b_d2[j, 1]
            kappa[j], slack[j], station[j] = b_kappa[j], b_slack[j], b_station[j]
    return tried, accepted, refused_count, rounds


# inlined: compiled once, inside optimise (its only caller)
@njit(cache=True, inline="always")
def try_moves(moves: NDArray[np.int64], ctrl: FloatArray, pos: FloatArray, d1: FloatArray,
              d2: FloatArray, kappa: FloatArray, slack: FloatArray, station: FloatArray,
              first: NDArray[np.int64], basis: FloatArray, lo: NDArray[np.int64],
              hi: NDArray[np.int64], kappa_max: float, floor: FloatArray,
              checker: tuple[Any, ...]
              ) -> NDArray[np.bool_]:  # pragma: no cover - compiled
    """Try moving each control point in ``moves`` to its neighbours' mean; a move changes
    the samples linearly (new = old + basis column * delta), so only its stretch is
    re-evaluated. Kept, in place, if no clear sample of the stretch loses its clearance,
    none comes below its separation ``floor`` from the obstacles where it kept it
    (:func:`separation_kept`), and the stretch's worst curvature (beyond the limit) and
    footprint violation do not grow. Returns which moves were kept."""
    acc = np.zeros(len(moves), dtype=np.bool_)
    for m in range(len(moves)):
        i = moves[m]
        dx = 0.5 * (ctrl[i - 1, 0] + ctrl[i + 1, 0]) - ctrl[i, 0]
        dy = 0.5 * (ctrl[i - 1, 1] + ctrl[i + 1, 1]) - ctrl[i, 1]
        a, b = lo[i], hi[i]
        q = b - a
        px, py = np.empty(q), np.empty(q)
        e1, e2 = np.empty((q, 2)), np.empty((q, 2))
        kap, head = np.empty(q), np.empty(q)
        for t in range(q):
            j = a + t
            r = i - first[j]  # column of the moved point in the sample's row
            px[t] = pos[j, 0] + basis[0, r, j] * dx
            py[t] = pos[j, 1] + basis[0, r, j] * dy
            e1[t, 0] = d1[j, 0] + basis[1, r, j] * dx
            e1[t, 1] = d1[j, 1] + basis[1, r, j] * dy
            e2[t, 0] = d2[j, 0] + basis[2, r, j] * dx
            e2[t, 1] = d2[j, 1] + basis[2, r, j] * dy
            kap[t] = abs(curvature(e1[t, 0], e1[t, 1], e2[t, 0], e2[t, 1]))
            head[t] = np.arctan2(e1[t, 1], e1[t, 0])
        # the curvature first: where it refuses the move, no footprint check is needed
        new_k = old_k = kappa_max
        for t in range(q):
            new_k, old_k = max(new_k, kap[t]), max(old_k, kappa[a + t])
        if new_k > old_k + 1e-12:
            continue
        sl, sc = footprint_slack(px, py, head, station[a:b].copy(), *checker)
        if not footprint_kept(slack, sl, a, 0.0):
            continue
        if not separation_kept(pos, d1, a, px, py, head, floor, checker):
            continue
        acc[m] = True
        apply_move(i, dx, dy, a, ctrl, pos, d1, d2, kappa, slack, station, px, py, e1, e2,
                   kap, sl, sc)
    return acc


@njit(cache=True, inline="always")  # as try_moves
def footprint_kept(slack: FloatArray, sl: FloatArray, a: int, room: float
                   ) -> bool:  # pragma: no cover - compiled
    """Whether a move's new clearances beyond the margins ``sl`` of samples ``a ..`` keep
    the footprint: no sample that was clear comes closer than ``min(its clearance,
    room)`` [m], and the worst violation does not grow."""
    new_v = old_v = 0.0
    for t in range(len(sl)):
        j = a + t
        if slack[j] >= 0 and sl[t] < min(slack[j], room):
            return False
        new_v, old_v = max(new_v, -sl[t]), max(old_v, -slack[j])
    return new_v <= old_v + 1e-12


@njit(cache=True, inline="always")  # as try_moves
def separation_kept(pos: FloatArray, d1: FloatArray, a: int, px: FloatArray,
                    py: FloatArray, head: FloatArray, floor: FloatArray,
                    checker: tuple[Any, ...]) -> bool:  # pragma: no cover - compiled
    """Whether the new poses ``px, py, head`` of samples ``a ..`` keep the separation
    from the obstacles: none whose footprint kept ``floor[j]`` [m] beyond the safety
    margin from every obstacle comes below it (the obstacles alone: a sample beside the
    road's edge keeps little from the road and may still keep its separation)."""
    q = len(px)
    top = 0.0
    for t in range(q):
        top = max(top, floor[a + t])
    if top <= 0.0:
        return True
    # the checker's obstacle part and the footprint's half sizes (footprint_slack's order)
    vx, vy, offsets, bbox, margin = checker[-5], checker[-4], checker[-3], checker[-2], \
        checker[-1]
    hl, hw = checker[13], checker[14]
    ox, oy, oh = np.empty(q), np.empty(q), np.empty(q)
    for t in range(q):
        ox[t], oy[t] = pos[a + t, 0], pos[a + t, 1]
        oh[t] = np.arctan2(d1[a + t, 1], d1[a + t, 0])
    old = obstacle_clearance(ox, oy, oh, vx, vy, offsets, bbox, hl, hw, margin, top,
                             np.bool_(True))
    new = obstacle_clearance(px, py, head, vx, vy, offsets, bbox, hl, hw, margin, top,
                             np.bool_(True))
    for t in range(q):
        need = floor[a + t] + margin
        if floor[a + t] > 0.0 and old[t] >= need and new[t] < need:
            return False
    return True


@njit(cache=True, inline="always")  # as try_moves
def apply_move(i: int, dx: float, dy: float, a: int, ctrl: FloatArray, pos: FloatArray,
               d1: FloatArray, d2: FloatArray, kappa: FloatArray, slack: FloatArray,
               station: FloatArray, px: FloatArray, py: FloatArray, e1: FloatArray,
               e2: FloatArray, kap: FloatArray, sl: FloatArray, sc: FloatArray
               ) -> None:  # pragma: no cover - compiled
    """Keep a move of control point ``i`` by ``(dx, dy)``: its samples ``a ..`` take the
    new positions, derivatives, curvatures, clearances and stations."""
    for t in range(len(px)):
        j = a + t
        pos[j, 0], pos[j, 1] = px[t], py[t]
        d1[j, 0], d1[j, 1] = e1[t, 0], e1[t, 1]
        d2[j, 0], d2[j, 1] = e2[t, 0], e2[t, 1]
        kappa[j], slack[j], station[j] = kap[t], sl[t], sc[t]
    ctrl[i, 0] += dx
    ctrl[i, 1] += dy


@njit(cache=True)
def curvature(ax: float, ay: float, bx: float, by: float) -> float:  # pragma: no cover
    """:func:`splineplan.curvature.curvature_from_derivatives` of one sample."""
    speed2 = ax * ax + ay * ay
    if speed2 > 0:
        return float((ax * by - ay * bx) / speed2**1.5)
    return np.inf


@njit(cache=True, inline="always")  # as try_moves
def independent_moves(bad: FloatArray, k: int, budget: int
                      ) -> NDArray[np.int64]:  # pragma: no cover - compiled
    """Control points to move this round: the worst first, then others ``k + 1`` apart."""
    order = np.argsort(-bad, kind="mergesort")  # stable: ties by index
    taken = np.zeros(len(bad) + 2 * k + 2, dtype=np.bool_)  # offset by k: i - k >= 0
    chosen = np.empty(min(len(bad), max(budget, 0)), dtype=np.int64)
    count = 0
    for i in order:
        if bad[i] <= 0 or count >= budget:
            break
        if taken[i:i + 2 * k + 1].any():
            continue
        taken[i + k] = True
        chosen[count] = i
        count += 1
    return chosen[:count]


#: Room [m] beyond the margins that a smoothing move leaves the footprint where it had it:
#: the check runs on the optimiser's samples, and the curve between them comes a few
#: millimetres closer on a bend.
SMOOTH_ROOM = 0.02
#: Share of the speed below which the steering rate must hold the car for
#: :func:`smooth_steering` to smooth there.
SMOOTH_GAIN = 0.05
#: Rounds without a kept move after which :func:`smooth_steering` stops.
SMOOTH_PATIENCE = 3
#: The moves :func:`_smooth_move` tries, in order: (target of :func:`_smooth_targets`,
#: share of the way there).
SMOOTH_STEPS = ((0.0, 1.0), (0.0, 0.5), (2.0, 0.5), (0.0, 0.25), (2.0, 0.25), (1.0, 0.5),
                (2.0, 1.0))


@njit(cache=True)
def steering_angle(kappa: float, wheelbase: float) -> float:  # pragma: no cover - compiled
    """:func:`splineplan.speed.steering_angle` of one sample."""
    half = 0.5 * wheelbase * kappa
    return float(np.arctan(wheelbase * kappa / np.sqrt(max(1.0 - half * half, 1e-12))))


@njit(cache=True, inline="always")  # as try_moves
def corner_speed(kappa: float, mu_g: float, s_max: float) -> float:  # pragma: no cover
    """:func:`splineplan.speed.allowed_speed` (equation (1)) of one sample."""
    return min(s_max, np.sqrt(mu_g / abs(kappa))) if kappa != 0.0 else s_max


@njit(cache=True)
def allowed_speeds(pos: FloatArray, d1: FloatArray, d2: FloatArray, a: int, b: int,
                   wheelbase: float, rate: float, mu_g: float, s_max: float
                   ) -> tuple[FloatArray, FloatArray]:  # pragma: no cover - compiled
    """Speed limits [m/s] of samples ``a .. b - 1``: the cornering speed of equation (1)
    (``s_max`` at most) and the steering rate's, which a step between two samples whose
    wheel angles differ by ``d`` gives both its ends: ``rate * chord / |d|``, as
    :func:`splineplan.speed.steering_speed_limit` does."""
    q = b - a
    corner, steer = np.empty(q), np.full(q, np.inf)
    prev = 0.0
    for t in range(q):
        j = a + t
        kap = curvature(d1[j, 0], d1[j, 1], d2[j, 0], d2[j, 1])
        corner[t] = corner_speed(kap, mu_g, s_max)
        delta = steering_angle(kap, wheelbase)
        if t > 0:
            turn = abs(delta - prev)
            if turn > 0.0:
                lim = rate * np.hypot(pos[j, 0] - pos[j - 1, 0], pos[j, 1] - pos[j - 1, 1]) / turn
                steer[t - 1] = min(steer[t - 1], lim)
                steer[t] = min(steer[t], lim)
        prev = delta
    return corner, steer


@njit(cache=True)
def smooth_steering(ctrl: FloatArray, pos: FloatArray, d1: FloatArray, d2: FloatArray,
                    kappa: FloatArray, slack: FloatArray, station: FloatArray,
                    first: NDArray[np.int64], basis: FloatArray, lo: NDArray[np.int64],
                    hi: NDArray[np.int64], cand: NDArray[np.int64],
                    movable: NDArray[np.bool_], k: int, wheelbase: float, rate: float,
                    mu_g: float, s_max: float, kappa_cap: float, a_max: float,
                    b_max: float, start_speed: float, max_moves: int, floor: FloatArray,
                    checker: tuple[Any, ...]
                    ) -> tuple[int, int]:  # pragma: no cover - compiled
    """Smooth the curve where the steering rate, not the curvature, sets its speed: rounds
    of moves of the control points that shape such samples (the worst first, then others
    of independent stretches) towards where the polygon's higher differences vanish
    (:func:`_smooth_targets`), which spreads a change of curvature over more of the curve
    without undoing the turn (:func:`_smooth_move`: a move is kept if the lowest speed limit
    of its stretch rises and neither its curvature beyond the limit nor its footprint's
    clearance gets worse, nor comes within :data:`SMOOTH_ROOM` of the margins where it was
    not, nor below ``floor`` where it kept it, as in :func:`optimise`). ``kappa_cap``
    [1/m]: the curvature that no move may raise a sample beyond unless it was there
    already (the worst bend's, at most the turning limit's, at least the one that still
    allows ``s_max``: smoothing never sharpens the worst bend). Returns the moves tried
    and accepted."""
    n, m = len(ctrl), len(kappa)
    tried = accepted = 0
    refused = np.zeros(n, dtype=np.bool_)
    bad = np.zeros(n)
    v, ds = np.empty(m), np.zeros(m)  # ds[j]: chord from sample j - 1 to j
    for j in range(1, m):
        ds[j] = np.hypot(pos[j, 0] - pos[j - 1, 0], pos[j, 1] - pos[j - 1, 1])
    corner, steer = allowed_speeds(pos, d1, d2, 0, m, wheelbase, rate, mu_g, s_max)
    changed = True
    idle = 0  # rounds since a move was kept
    while tried < max_moves and idle < SMOOTH_PATIENCE:
        if changed:
            # the speed the car would drive without the steering's limit (accelerating
            # from the start, braking for the curves ahead): only where the steering holds
            # it below that is the curve worth smoothing
            v[0] = min(start_speed, corner[0])
            for j in range(1, m):
                v[j] = min(corner[j], np.sqrt(v[j - 1] ** 2 + 2.0 * a_max * ds[j]))
            for j in range(m - 2, -1, -1):
                v[j] = min(v[j], np.sqrt(v[j + 1] ** 2 + 2.0 * b_max * ds[j + 1]))
            changed = False
        for i in range(n):
            bad[i] = 0.0
        for j in range(m):
            if steer[j] < v[j] * (1.0 - SMOOTH_GAIN):
                short = 1.0 - steer[j] / v[j]
                for c in cand[j]:
                    if movable[c] and not refused[c] and 1 <= c <= n - 2:
                        bad[c] = max(bad[c], short)
                        break
        if not (bad > 0).any():
            break
        chosen = independent_moves(bad, k, max_moves - tried)
        if len(chosen) == 0:
            break
        tried += len(chosen)
        idle += 1
        for i in chosen:
            if _smooth_move(i, ctrl, pos, d1, d2, kappa, slack, station, first, basis, lo,
                            hi, wheelbase, rate, mu_g, s_max, kappa_cap, floor, checker):
                accepted += 1
                changed = True
                idle = 0
                # the limits of the changed samples, with a step each side
                a0, b0 = max(lo[i] - 2, 0), min(hi[i] + 2, m)
                lc, ls = allowed_speeds(pos, d1, d2, a0, b0, wheelbase, rate, mu_g, s_max)
                for t in range(1 if a0 > 0 else 0, b0 - a0 - (1 if b0 < m else 0)):
                    corner[a0 + t], steer[a0 + t] = lc[t], ls[t]
                for j in range(max(a0, 1), b0):
                    ds[j] = np.hypot(pos[j, 0] - pos[j - 1, 0], pos[j, 1] - pos[j - 1, 1])
                for r in range(max(i - k, 0), min(i + k + 1, n)):
                    refused[r] = False
            else:
                refused[i] = True
    return tried, accepted


@njit(cache=True)
def _smooth_targets(ctrl: FloatArray, i: int) -> FloatArray:  # pragma: no cover - compiled
    """Where :func:`smooth_steering` may move control point ``i`` ``(3, 2)``: where the
    polygon's sixth difference vanishes (least change of its third differences, which set
    the curvature's rate), where its fourth vanishes, and its neighbours' mean (equation
    (3)); a point too near an end takes the mean."""
    n = len(ctrl)
    out = np.empty((3, 2))
    for d in range(2):
        mean = 0.5 * (ctrl[i - 1, d] + ctrl[i + 1, d])
        out[0, d] = out[1, d] = out[2, d] = mean
        if 2 <= i <= n - 3:
            out[1, d] = (-ctrl[i - 2, d] + 4.0 * (ctrl[i - 1, d] + ctrl[i + 1, d])
                         - ctrl[i + 2, d]) / 6.0
            out[0, d] = out[1, d]
        if 3 <= i <= n - 4:
            out[0, d] = (15.0 * (ctrl[i - 1, d] + ctrl[i + 1, d])
                         - 6.0 * (ctrl[i - 2, d] + ctrl[i + 2, d])
                         + ctrl[i - 3, d] + ctrl[i + 3, d]) / 20.0
    return out


@njit(cache=True)
def _smooth_move(i: int, ctrl: FloatArray, pos: FloatArray, d1: FloatArray,
                 d2: FloatArray, kappa: FloatArray, slack: FloatArray, station: FloatArray,
                 first: NDArray[np.int64], basis: FloatArray, lo: NDArray[np.int64],
                 hi: NDArray[np.int64], wheelbase: float, rate: float, mu_g: float,
                 s_max: float, kappa_cap: float, floor: FloatArray,
                 checker: tuple[Any, ...]) -> bool:  # pragma: no cover - compiled
    """One move of :func:`smooth_steering`: towards one of :func:`_smooth_targets`, the
    whole way or part of it (in the order of :data:`SMOOTH_STEPS`), the first that raises
    the lowest speed limit of the stretch, keeps its curvature and keeps its footprint
    clear is applied in place. Returns whether one was."""
    m = len(kappa)
    targets = _smooth_targets(ctrl, i)
    a, b = lo[i], hi[i]
    q = b - a
    # the stretch with one unchanged sample each side: the steps into it count too
    a0, b0 = max(a - 1, 0), min(b + 1, m)
    c0, s0 = allowed_speeds(pos, d1, d2, a0, b0, wheelbase, rate, mu_g, s_max)
    old_v = np.inf
    for t in range(b0 - a0):
        old_v = min(old_v, c0[t], s0[t])
    old_k = kappa_cap
    for t in range(q):
        old_k = max(old_k, kappa[a + t])
    npos, ne1, ne2 = pos[a0:b0].copy(), d1[a0:b0].copy(), d2[a0:b0].copy()
    kap, head = np.empty(q), np.empty(q)
    px, py = np.empty(q), np.empty(q)
    for step in SMOOTH_STEPS:
        target, frac = int(step[0]), step[1]
        dx = frac * (targets[target, 0] - ctrl[i, 0])
        dy = frac * (targets[target, 1] - ctrl[i, 1])
        if np.hypot(dx, dy) < 1e-6:
            continue
        # the stretch's samples in order, each refusing the move as soon as its curvature
        # or its speed limit (cornering, or the steering's over the step from the sample
        # before) is no better than the stretch's lowest before the move
        good = True
        prev = limit_prev = np.inf
        for u in range(b0 - a0):
            j = a0 + u
            if a <= j < b:
                r = i - first[j]
                npos[u, 0] = pos[j, 0] + basis[0, r, j] * dx
                npos[u, 1] = pos[j, 1] + basis[0, r, j] * dy
                ne1[u, 0] = d1[j, 0] + basis[1, r, j] * dx
                ne1[u, 1] = d1[j, 1] + basis[1, r, j] * dy
                ne2[u, 0] = d2[j, 0] + basis[2, r, j] * dx
                ne2[u, 1] = d2[j, 1] + basis[2, r, j] * dy
            kap_u = curvature(ne1[u, 0], ne1[u, 1], ne2[u, 0], ne2[u, 1])
            if a <= j < b:
                kap[j - a] = abs(kap_u)
                if kap[j - a] > old_k + 1e-12:
                    good = False
                    break
            delta = steering_angle(kap_u, wheelbase)
            limit = corner_speed(kap_u, mu_g, s_max)
            if u > 0:
                turn = abs(delta - prev)
                if turn > 0.0:
                    step_limit = rate * np.hypot(npos[u, 0] - npos[u - 1, 0],
                                                 npos[u, 1] - npos[u - 1, 1]) / turn
                    limit = min(limit, step_limit)
                    limit_prev = min(limit_prev, step_limit)
                if not limit_prev > old_v * (1.0 + 1e-6):
                    good = False
                    break
            prev, limit_prev = delta, limit
        if not good or not limit_prev > old_v * (1.0 + 1e-6):
            continue
        for t in range(q):
            u = a + t - a0
            px[t], py[t] = npos[u, 0], npos[u, 1]
            head[t] = np.arctan2(ne1[u, 1], ne1[u, 0])
        sl, sc = footprint_slack(px, py, head, station[a:b].copy(), *checker)
        if not footprint_kept(slack, sl, a, SMOOTH_ROOM):
            continue
        if not separation_kept(pos, d1, a, px, py, head, floor, checker):
            continue
        apply_move(i, dx, dy, a, ctrl, pos, d1, d2, kappa, slack, station, px, py,
                   ne1[a - a0:b - a0], ne2[a - a0:b - a0], kap, sl, sc)
        return True
    return False


@njit(cache=True, inline="always")
def _corner_gap_one(dx: float, dy: float, cf: float, sf: float, ct: float, st: float,
                    lt: float, wt: float, lf: float, wf: float) -> float:  # pragma: no cover
    """Smallest distance [m] from the corners of a rectangle (heading ``cf``, ``sf``, half
    sizes ``lf``, ``wf``) centred at (``dx``, ``dy``) from another (heading ``ct``,
    ``st``, half sizes ``lt``, ``wt``) to that other."""
    best = np.inf
    for sx, sy in ((1.0, 1.0), (1.0, -1.0), (-1.0, 1.0), (-1.0, -1.0)):
        px = dx + (sx * lf) * cf - (sy * wf) * sf
        py = dy + (sx * lf) * sf + (sy * wf) * cf
        qx = max(abs(px * ct + py * st) - lt, 0.0)
        qy = max(abs(py * ct - px * st) - wt, 0.0)
        best = min(best, np.hypot(qx, qy))
    return best


@njit(cache=True)
def box_gap_one(x1: float, y1: float, h1: float, l1: float, w1: float, x2: float,
                y2: float, h2: float, l2: float, w2: float) -> float:  # pragma: no cover
    """:func:`splineplan.spacetime.box_gap` of one pair of rectangles (centre, heading
    [rad], length and width [m] each): their distance [m], 0 where they overlap."""
    c1x, s1x = np.cos(h1), np.sin(h1)
    c2x, s2x = np.cos(h2), np.sin(h2)
    l1, w1, l2, w2 = l1 / 2.0, w1 / 2.0, l2 / 2.0, w2 / 2.0
    dx, dy = x2 - x1, y2 - y1
    cos = abs(c1x * c2x + s1x * s2x)
    sin = abs(c1x * s2x - s1x * c2x)
    if (abs(dx * c1x + dy * s1x) <= l1 + l2 * cos + w2 * sin
            and abs(dy * c1x - dx * s1x) <= w1 + l2 * sin + w2 * cos
            and abs(dx * c2x + dy * s2x) <= l2 + l1 * cos + w1 * sin
            and abs(dy * c2x - dx * s2x) <= w2 + l1 * sin + w1 * cos):
        return 0.0
    return min(_corner_gap_one(-dx, -dy, c2x, s2x, c1x, s1x, l1, w1, l2, w2),
               _corner_gap_one(dx, dy, c1x, s1x, c2x, s2x, l2, w2, l1, w1))


@njit(cache=True)
def body_meetings(body: NDArray[np.int64], n_bodies: int, times: FloatArray,
                  centres: FloatArray, heads: FloatArray, lengths: FloatArray,
                  widths: FloatArray, margins: FloatArray, path_s: FloatArray,
                  path_xy: FloatArray, path_h: FloatArray, ego_l: float, ego_w: float
                  ) -> FloatArray:  # pragma: no cover - compiled
    """:func:`splineplan.closedloop.bodies.meetings`: for each body, the first and last
    path station [m] its rectangles come within their margin of the ego's footprint, and
    the first and last time [s] they do (NaN where never)."""
    out = np.full((n_bodies, 4), np.nan)
    ego_d = np.hypot(ego_l, ego_w)
    for k in range(len(times)):
        reach = 0.5 * (np.hypot(lengths[k], widths[k]) + ego_d) + margins[k]
        r2 = reach * reach
        cx, cy = centres[k, 0], centres[k, 1]
        b = body[k]
        for n in range(len(path_s)):
            ex, ey = path_xy[n, 0] - cx, path_xy[n, 1] - cy
            if ex * ex + ey * ey > r2:
                continue
            if box_gap_one(cx, cy, heads[k], lengths[k], widths[k], path_xy[n, 0],
                           path_xy[n, 1], path_h[n], ego_l, ego_w) > margins[k]:
                continue
            if np.isnan(out[b, 0]):
                out[b, 0], out[b, 1] = path_s[n], path_s[n]
                out[b, 2], out[b, 3] = times[k], times[k]
            else:
                out[b, 0] = min(out[b, 0], path_s[n])
                out[b, 1] = max(out[b, 1], path_s[n])
                out[b, 2] = min(out[b, 2], times[k])
                out[b, 3] = max(out[b, 3], times[k])
    return out


@njit(cache=True)
def crosses(pxy: FloatArray, ph: FloatArray, inside: NDArray[np.bool_], xy: FloatArray,
            heading: FloatArray, lo_x: float, lo_y: float, hi_x: float, hi_y: float,
            near: float, angle: float) -> bool:  # pragma: no cover - compiled
    """:func:`splineplan.closedloop.cooperate._crosses`: whether a plan's point ``inside``
    the path's box comes within ``near`` [m] of a path point inside the box (``lo``,
    ``hi``) at more than ``angle`` [rad] from the path's heading there."""
    for j in range(len(xy)):
        x, y = xy[j, 0], xy[j, 1]
        if not (lo_x <= x <= hi_x and lo_y <= y <= hi_y):
            continue
        for i in range(len(pxy)):
            if not inside[i]:
                continue
            if np.hypot(pxy[i, 0] - x, pxy[i, 1] - y) >= near:
                continue
            d = ph[i] - heading[j]
            if abs(np.arctan2(np.sin(d), np.cos(d))) > angle:
                return True
    return False


@njit(cache=True)
def box_gaps(c1: FloatArray, h1: FloatArray, l1: FloatArray, w1: FloatArray, c2: FloatArray,
             h2: FloatArray, l2: FloatArray, w2: FloatArray
             ) -> FloatArray:  # pragma: no cover - compiled
    """:func:`box_gap_one` of each pair of rectangles: centres ``(N, 2)`` [m], headings
    ``(N,)`` [rad], lengths and widths ``(N,)`` [m] of each side."""
    n = len(h1)
    out = np.empty(n)
    for i in range(n):
        out[i] = box_gap_one(c1[i, 0], c1[i, 1], h1[i], l1[i], w1[i], c2[i, 0], c2[i, 1],
                             h2[i], l2[i], w2[i])
    return out


@njit(cache=True)
def towed_slip(s: FloatArray, kappa: FloatArray, half: float, slip0: float
               ) -> FloatArray:  # pragma: no cover - compiled
    """Slip angle ``(n,)`` [rad] at stations ``s`` of a rear axle towed ``half`` [m]
    behind a point that runs on curvature ``kappa`` (linear between samples):
    ``d beta / ds = kappa - sin(beta) / half`` from ``slip0``, a step of the classical
    Runge-Kutta method per sample (:func:`splineplan.speed.towed_steering`)."""
    n = len(s)
    beta = np.empty(n)
    if n == 0:
        return beta
    b = slip0
    beta[0] = b
    for j in range(n - 1):
        d = s[j + 1] - s[j]
        k0, k1 = kappa[j], kappa[j + 1]
        km = 0.5 * (k0 + k1)
        a1 = k0 - np.sin(b) / half
        a2 = km - np.sin(b + 0.5 * d * a1) / half
        a3 = km - np.sin(b + 0.5 * d * a2) / half
        a4 = k1 - np.sin(b + d * a3) / half
        b += d * (a1 + 2.0 * a2 + 2.0 * a3 + a4) / 6.0
        beta[j + 1] = b
    return beta


@njit(cache=True)
def first_touch(c1: FloatArray, h1: FloatArray, l1: FloatArray, w1: FloatArray,
                v1: FloatArray, c2: FloatArray, h2: FloatArray, l2: FloatArray,
                w2: FloatArray, v2: FloatArray, taus: FloatArray
                ) -> FloatArray:  # pragma: no cover - compiled
    """For each pair of rectangles (as :func:`box_gaps`) moving at constant velocities
    ``v1``, ``v2`` ``(N, 2)`` [m/s], the first of the times ``taus`` [s] (increasing) at
    which they touch (:func:`box_gap_one` at most 0), ``inf`` where none is."""
    n = len(h1)
    out = np.full(n, np.inf)
    for p in range(n):
        for tau in taus:
            if box_gap_one(c1[p, 0] + v1[p, 0] * tau, c1[p, 1] + v1[p, 1] * tau, h1[p], l1[p],
                           w1[p], c2[p, 0] + v2[p, 0] * tau, c2[p, 1] + v2[p, 1] * tau,
                           h2[p], l2[p], w2[p]) <= 0.0:
                out[p] = tau
                break
    return out


@njit(cache=True)
def first_in_circles(xy: FloatArray, i0: int, box: FloatArray, cx: FloatArray,
                     cy: FloatArray, r: FloatArray) -> NDArray[np.int64]:  # pragma: no cover
    """For each circle (centre ``cx``, ``cy``, radius ``r`` ``(k,)`` [m]), the first path
    sample from ``i0`` on of ``xy`` ``(n, 2)`` [m] inside it, -1 where none is or where
    the circle misses ``box`` (lowest x, highest x, lowest y, highest y of the samples
    from ``i0`` on)."""
    k = len(cx)
    out = np.full(k, -1, dtype=np.int64)
    for j in range(k):
        if (cx[j] + r[j] < box[0] or cx[j] - r[j] > box[1] or cy[j] + r[j] < box[2]
                or cy[j] - r[j] > box[3]):
            continue
        r2 = r[j] * r[j]
        for i in range(i0, len(xy)):
            dx, dy = xy[i, 0] - cx[j], xy[i, 1] - cy[j]
            if dx * dx + dy * dy <= r2:
                out[j] = i
                break
    return out


@njit(cache=True)
def blocked_samples(pts: FloatArray, head: FloatArray, length: float, width: float,
                    oxy: FloatArray, ohead: FloatArray, js: NDArray[np.int64],
                    o_length: float, o_width: float, reach: float, margin: float
                    ) -> tuple[NDArray[np.int64], NDArray[np.int64]]:  # pragma: no cover
    """:func:`splineplan.spacetime.occupancy` of one obstacle: at each of its times ``js``
    (its centres ``oxy`` and headings ``ohead``, one row per time), the first and last
    path sample (``pts``, ``head``) where a rectangle of ``length`` x ``width`` [m] comes
    closer than ``margin`` [m] to it (``len(pts)`` and -1 where none does). Only samples
    within ``reach`` [m] of its centre are measured."""
    n, m = len(pts), len(oxy)
    lo = np.full(m, n, dtype=np.int64)
    hi = np.full(m, -1, dtype=np.int64)
    r2 = reach * reach
    for j in js:
        ox, oy = oxy[j, 0], oxy[j, 1]
        for i in range(n):
            dx, dy = pts[i, 0] - ox, pts[i, 1] - oy
            if dx * dx + dy * dy > r2:
                continue
            if box_gap_one(pts[i, 0], pts[i, 1], head[i], length, width, ox, oy, ohead[j],
                           o_length, o_width) < margin:
                lo[j] = min(lo[j], i)
                hi[j] = max(hi[j], i)
    return lo, hi
