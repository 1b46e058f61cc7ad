"""Level 3's first control polygon, from level 2's roadmap (steps 1, 2 and 8 of
:mod:`splineplan.trajectory`).

Band simplification (:func:`band_simplify`) keeps the roadmap vertices that string pulling
through lateral bands of the free intervals needs; at junction turns the vertices first move
within their bands to the polygon of least bending (:func:`min_bending_offsets`) and long
legs are split in gradually growing pieces; the vehicle's position and a heading point lead
in. Where the curve along level 2's path cannot be made feasible, :func:`detour_roadmap`
searches the same graph for a path of limited lateral rate. Pure geometry on the roadmap
and the corridor: no spline and no footprint here.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
from numpy.typing import ArrayLike, NDArray

from splineplan.corridor import Corridor
from splineplan.errors import TrajectoryError
from splineplan.geometry import FloatArray, polyline_stations
from splineplan.roadmap import Roadmap
from splineplan.trajectory_params import TrajectoryParams

#: Weight [1/m^2] that pulls the least-bending polygon towards level 2's path (its share of
#: the objective against the bending, so that straights among obstacles keep to the path).
SMOOTH_CENTRE_WEIGHT = 1e-4
#: Half width [m] of the bands within which band simplification drops vertices of the
#: least-bending polygon.
SMOOTH_TOLERANCE = 0.05
#: Largest ratio of two neighbouring legs of the smooth control polygon.
LEG_GROWTH = 2.0


#: Stretch [m] of the road over which :func:`_sharp_bend` measures the road's heading change.
_BEND_BASE = 4.0


def _sharp_bend(roadmap: Roadmap, corridor: Corridor, params: TrajectoryParams) -> bool:
    """Whether the road along the roadmap bends on a radius below twice the turning radius
    (a junction turn): there the first control polygon is the least-bending one."""
    s = np.asarray(roadmap.s, dtype=float)
    dh = (corridor.heading_at(s + _BEND_BASE / 2.0)
          - corridor.heading_at(s - _BEND_BASE / 2.0))
    turn = np.abs((dh + np.pi) % (2.0 * np.pi) - np.pi)
    return bool(np.any(turn > 0.5 * params.kappa_max * _BEND_BASE))


def _control_points(roadmap: Roadmap, corridor: Corridor, start_heading: float | None,
                    params: TrajectoryParams, start_speed: float, smooth: bool = False
                    ) -> tuple[FloatArray, NDArray[np.int64]]:
    """Candidate control points ``(c, 2)`` and how often the first curve uses each (0 or 1).

    The candidates are the vehicle's position, a heading point ahead of it and the roadmap
    vertices beyond the heading point. The first curve uses the first two, the last, and the
    vertices that band simplification (:func:`band_simplify`) keeps, beginning at the
    farthest vertex that the vehicle's position reaches within the bands (at least the
    lead-in distance ahead).

    With ``smooth``, the vertices beyond the lead-in first move within their bands to the
    polygon of least bending (:func:`min_bending_offsets`), band simplification then drops
    those that stand in line, and long legs are split in pieces that grow gradually from
    the short legs beside them (:func:`_leg_splits`): the first curve then turns as gently
    as the bands allow, which a junction turn needs.
    """
    rp = roadmap.params
    raw = np.asarray(roadmap.xy, dtype=float)
    if raw.ndim != 2 or raw.shape[1] != 2 or len(raw) < 2:
        raise TrajectoryError(f"a trajectory needs at least 2 roadmap points, got {len(raw)}")
    distinct = np.concatenate(([True], np.hypot(*np.diff(raw, axis=0).T) > 1e-6))
    pts = raw[distinct]
    if len(pts) < 2:
        raise TrajectoryError(f"a trajectory needs at least 2 roadmap points, got {len(pts)}")
    start = np.asarray(roadmap.start_xy, dtype=float).reshape(2)
    sl = corridor.to_sl(np.vstack((start, pts)))
    if not corridor.contains(start[None])[0]:
        raise TrajectoryError(
            f"start ({start[0]:.2f}, {start[1]:.2f}) is off the road "
            f"(station {corridor.offset + sl[0, 0]:.1f} m, lateral offset {sl[0, 1]:.2f} m)")
    if start_heading is not None and not np.isfinite(start_heading):
        raise TrajectoryError(f"start heading must be finite, got {start_heading!r}")
    s0, vs = float(sl[0, 0]), sl[1:, 0]
    reach = float(vs[-1] - s0)
    if reach <= 1e-6:
        raise TrajectoryError("the roadmap ends at or behind the vehicle: no curve to follow")
    lines = _vertex_lines(roadmap, corridor, distinct, sl[1:], params.band_fraction,
                          params.band_reserve)
    # the control points stand at the bands' centres (the roadmap vertices, except where
    # the band reserve moved them off an interval's end)
    moved = np.abs(lines[3] - sl[1:, 1]) > 1e-9
    pts = pts.copy()
    pts[moved] = lines[0][moved] + lines[3][moved, None] * lines[2][moved]
    lead = max(params.lead_in_lengths * rp.vehicle_length, params.lead_in_time * start_speed)
    lead = min(lead, 0.5 * reach)
    head_len = max(min(lead / 2.0, reach / 3.0), 1e-3)
    ahead = vs > s0 + head_len + rp.d / 2.0
    ahead[-1] = True
    verts = pts[ahead]
    lines = tuple(a[ahead] for a in lines)  # type: ignore[assignment]
    first = int(np.searchsorted(vs[ahead], s0 + lead - 1e-9))
    first = min(first, len(verts) - 1)
    if not smooth:
        # from the vehicle's position as far as the bands allow
        cap = int(np.searchsorted(polyline_stations(verts), params.max_control_spacing
                                  - float(np.hypot(*(verts[0] - start))), side="right")) - 1
        if cap >= 0:
            first = max(first, _farthest(start, -1, cap, verts, *lines))
    if start_heading is None:
        direction = verts[first] - start
    else:
        direction = np.array([np.cos(start_heading), np.sin(start_heading)])
    norm = float(np.hypot(*direction))
    if norm <= 1e-12:
        raise TrajectoryError("the roadmap's points coincide with the start: no curve")
    heading_point = start + head_len * direction / norm
    origin, tangent, normal, centre, half = (a[first:] for a in lines)
    if smooth:
        # the vehicle's position and heading point are fixed (bands of zero width)
        fixed = np.zeros(2)
        lat = min_bending_offsets(
            np.vstack((start, heading_point, origin)), np.vstack((np.zeros((2, 2)), normal)),
            np.concatenate((fixed, centre - half)), np.concatenate((fixed, centre + half)),
            np.concatenate((fixed, centre)), SMOOTH_CENTRE_WEIGHT)[2:]
        verts = verts.copy()
        verts[first:] = origin + lat[:, None] * normal
        centre, half = lat, np.minimum(half, SMOOTH_TOLERANCE)
    kept = first + band_simplify(verts[first:], origin, tangent, normal, centre, half)
    # long legs get extra control points on them (they stay within the bands)
    vst = vs[ahead]
    legs = np.column_stack((np.concatenate(([first], kept[:-1])), kept))
    leg_len = np.hypot(*(verts[legs[:, 1]] - verts[legs[:, 0]]).T)
    extra_xy, extra_s = [], []
    for j, (a, b) in enumerate(legs.tolist()):
        if a == b:
            continue
        if smooth:
            f = _leg_splits(float(leg_len[j]), float(leg_len[j - 1]) if j > 0 else np.inf,
                            float(leg_len[j + 1]) if j + 1 < len(legs) else np.inf,
                            params.max_control_spacing, LEG_GROWTH)
        else:
            pieces = int(np.ceil(leg_len[j] / params.max_control_spacing - 1e-9))
            f = np.arange(1, pieces) / max(pieces, 1)
        if len(f) == 0:
            continue
        extra_xy.append(verts[a] + f[:, None] * (verts[b] - verts[a]))
        extra_s.append(vst[a] + f * (vst[b] - vst[a]))
    counts = np.zeros(len(verts), dtype=np.int64)
    counts[kept] = 1
    if extra_xy:
        ex = np.concatenate(extra_xy)
        es = np.concatenate(extra_s)
        at = np.searchsorted(vst, es, side="right")
        verts = np.insert(verts, at, ex, axis=0)
        counts = np.insert(counts, at, 1)
    pool = np.vstack((start, heading_point, verts))
    return pool, np.concatenate(([1, 1], counts)).astype(np.int64)


# ---- least bending ---------------------------------------------------------------------
def min_bending_offsets(origin: FloatArray, normal: FloatArray, lo: FloatArray,
                           hi: FloatArray, centre: FloatArray, weight: float,
                           max_rounds: int = 30) -> FloatArray:
    """Lateral offsets ``(m,)`` [m] of the points ``origin + l * normal`` that minimise the
    sum of squared second differences of the points (the discrete bending of the polyline)
    plus ``weight`` times the squared distance of ``l`` to ``centre``, within ``lo <= l <=
    hi``.

    Equation (3) moves a point to its neighbours' mean, which drives exactly this sum down;
    this is its fixed point within the bands, found at once: the Hessian is banded
    (pentadiagonal), solved by banded Cholesky, first in a primal-dual active-set loop
    (fast, usually exact), then in a primal active-set loop that ends at the optimum.
    """
    from scipy.linalg import solveh_banded

    m = len(origin)
    if m < 3:
        return np.clip(centre, lo, hi)
    # second differences D (m - 2, m) for uneven spacing (curvature-like, weighted by the
    # length each one stands for); M = D^T D is pentadiagonal
    h = np.maximum(np.hypot(*np.diff(origin, axis=0).T), 1e-3)
    w = np.sqrt(2.0 / (h[:-1] + h[1:]))  # 2 / (h0 + h1) * sqrt((h0 + h1) / 2)
    coef = np.column_stack((w / h[:-1], -w * (1.0 / h[:-1] + 1.0 / h[1:]), w / h[1:]))
    m0 = np.zeros(m)
    m1 = np.zeros(m - 1)
    for a in range(3):
        m0[a:m - 2 + a] += coef[:, a] ** 2
    for a in range(2):
        m1[a:m - 2 + a] += coef[:, a] * coef[:, a + 1]
    m2 = coef[:, 0] * coef[:, 2]
    nn1 = np.einsum("ij,ij->i", normal[:-1], normal[1:])
    nn2 = np.einsum("ij,ij->i", normal[:-2], normal[2:])
    n0 = np.einsum("ij,ij->i", normal, normal)
    # (a tiny ridge keeps the system definite where nothing else pins the offsets down)
    h0, h1, h2 = m0 * n0 + weight + 1e-9, m1 * nn1, m2 * nn2
    second = (coef[:, 0, None] * origin[:-2] + coef[:, 1, None] * origin[1:-1]
              + coef[:, 2, None] * origin[2:])  # D @ origin
    dt = np.zeros((m, 2))  # D^T @ second
    dt[:-2] += coef[:, 0, None] * second
    dt[1:-1] += coef[:, 1, None] * second
    dt[2:] += coef[:, 2, None] * second
    g = np.einsum("ij,ij->i", normal, dt) - weight * centre

    def hess(x: FloatArray) -> FloatArray:
        y = h0 * x
        y[:-1] += h1 * x[1:]
        y[1:] += h1 * x[:-1]
        y[:-2] += h2 * x[2:]
        y[2:] += h2 * x[:-2]
        return y

    fixed = lo >= hi

    def solve(at_lo: NDArray[np.bool_], at_hi: NDArray[np.bool_]) -> FloatArray:
        """Minimum with the offsets in ``at_lo`` / ``at_hi`` held at those bounds (by a
        stiff penalty, which keeps the system banded)."""
        act = at_lo | at_hi
        ab = np.zeros((3, m))
        ab[2] = h0 + _PIN * act
        ab[1, 1:] = h1
        ab[0, 2:] = h2
        rhs = -g + _PIN * np.where(at_lo, lo, np.where(at_hi, hi, 0.0))
        return solveh_banded(ab, rhs, lower=False, check_finite=False)

    # primal-dual active set: fast, usually exact, but not guaranteed to settle
    at_lo = np.zeros(m, dtype=bool)
    at_hi = fixed.copy()
    for _ in range(max_rounds):
        x = solve(at_lo, at_hi)
        grad = hess(x) + g
        new_lo = ((at_lo & (grad >= 0)) | (x < lo - 1e-9)) & ~fixed
        new_hi = ((at_hi & (grad <= 0)) | (x > hi + 1e-9)) & ~new_lo | fixed
        if np.array_equal(new_lo, at_lo) and np.array_equal(new_hi, at_hi):
            break
        at_lo, at_hi = new_lo, new_hi
    # primal active set from there: each step stays within the bounds and lowers the
    # objective, so it ends at the optimum
    x = np.clip(x, lo, hi)
    at_lo = (x <= lo) & ~fixed
    at_hi = (x >= hi) | fixed
    for _ in range(4 * m + 10):
        y = solve(at_lo, at_hi)
        free = ~(at_lo | at_hi)
        out = free & ((y < lo) | (y > hi))
        if not out.any():
            x = np.where(free, y, x)
            grad = hess(x) + g
            wrong = np.where(at_lo, -grad, 0.0) + np.where(at_hi & ~fixed, grad, 0.0)
            i = int(np.argmax(wrong))
            if wrong[i] <= 1e-9 * (1.0 + float(np.abs(grad).max())):
                break
            at_lo[i] = at_hi[i] = False
            continue
        d = y - x
        with np.errstate(divide="ignore", invalid="ignore"):
            room = np.where(d < 0, (lo - x) / d, np.where(d > 0, (hi - x) / d, np.inf))
        room = np.where(free, np.clip(room, 0.0, None), np.inf)
        j = int(np.argmin(room))
        x = np.where(free, x + min(float(room[j]), 1.0) * d, x)
        at_lo[j], at_hi[j] = d[j] < 0, d[j] > 0
    return np.clip(x, lo, hi)


#: Stiffness that holds an offset at its bound in :func:`min_bending_offsets`.
_PIN = 1e8


def _leg_splits(length: float, before: float, after: float, cap: float, ratio: float
                ) -> FloatArray:
    """Fractions ``(k,)`` of a control-polygon leg of ``length`` [m] at which to split it so
    that no piece is longer than ``cap`` [m] nor ``ratio`` times its neighbour: pieces grow
    geometrically from the legs ``before`` and ``after`` it (their lengths [m]).

    A uniform B-spline turns within its shortest legs, so a short leg beside a long one
    gives a sharp bend that the control polygon does not have.
    """
    cuts_a, cuts_b = [], []
    pos, step = 0.0, min(max(ratio * before, 0.5), cap)
    while pos + step < length / 2.0:
        pos += step
        cuts_a.append(pos)
        step = min(step * ratio, cap)
    pos, step = length, min(max(ratio * after, 0.5), cap)
    while pos - step > length / 2.0:
        pos -= step
        cuts_b.append(pos)
        step = min(step * ratio, cap)
    lo = cuts_a[-1] if cuts_a else 0.0
    hi = cuts_b[-1] if cuts_b else length
    mid = int(np.ceil((hi - lo) / cap - 1e-9))
    cuts = np.concatenate((cuts_a, lo + (hi - lo) * np.arange(1, mid) / max(mid, 1),
                           cuts_b[::-1]))
    return np.asarray(cuts, dtype=float) / length


# ---- band simplification ---------------------------------------------------------------
def _vertex_lines(roadmap: Roadmap, corridor: Corridor, distinct: NDArray[np.bool_],
                  sl: FloatArray, band_fraction: float, band_reserve: float = 0.0
                  ) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray, FloatArray]:
    """Each roadmap vertex's sweep line and band: origin ``(m, 2)`` (lateral offset 0),
    tangent ``(m, 2)``, normal ``(m, 2)``, band centre ``(m,)`` [m] and half width ``(m,)`` [m].

    Each vertex moves ``band_reserve`` [m] off its free interval's ends (where the interval
    is wide enough), which is where the band is centred; the band spans ``band_fraction``
    of the free interval, within the interval less ``band_reserve`` [m] on each side
    (room for the footprint's turn away from the road's heading). Without free
    intervals (a roadmap without its graph) the bands are empty and centred on the vertices.
    """
    s = sl[:, 0]
    h = corridor.heading_at(s)
    tangent = np.column_stack((np.cos(h), np.sin(h)))
    normal = np.column_stack((-tangent[:, 1], tangent[:, 0]))
    origin = corridor.to_xy(s, np.zeros_like(s))
    path = np.asarray(roadmap.path)
    if len(path) == len(distinct) and len(roadmap.graph_lo) and len(roadmap.graph_hi):
        lo = np.asarray(roadmap.graph_lo, dtype=float)[path][distinct]
        hi = np.asarray(roadmap.graph_hi, dtype=float)[path][distinct]
        # the vertex, moved off its interval's ends by the reserve where it can
        q = np.minimum(band_reserve, (hi - lo) / 2.0)
        centre = np.clip(sl[:, 1], lo + q, hi - q)
        room = np.minimum(centre - lo, hi - centre)
        half = np.clip(np.minimum(band_fraction * np.maximum(hi - lo, 0.0) / 2.0,
                                  room - band_reserve), 0.0, None)
    else:
        centre, half = sl[:, 1], np.zeros(len(s))
    return origin, tangent, normal, centre, half


def band_simplify(points: ArrayLike, origin: ArrayLike, tangent: ArrayLike, normal: ArrayLike,
                  centre: ArrayLike, half: ArrayLike) -> NDArray[np.int64]:
    """Vertices kept by greedy string pulling through lateral bands.

    Vertex ``k`` of the polyline ``points`` ``(m, 2)`` [m] stands on a line through
    ``origin[k]`` ``(m, 2)`` along ``normal[k]`` ``(m, 2)`` (unit; ``tangent[k]`` is the unit
    direction across it, along the road). Its band is the part of that line at lateral
    offsets ``centre[k] +- half[k]`` [m]. From the last kept vertex ``i``, the next kept
    vertex is the farthest ``j`` such that every segment ``i -> j'`` with ``j' <= j`` crosses
    every line ``k`` with ``i < k < j'`` inside its band (at least ``j = i + 1``). With
    ``half = 0`` only collinear vertices go.

    Returns
    -------
    Increasing indices, with the first and the last vertex.
    """
    pts = np.asarray(points, dtype=float)
    org, tan, nrm, cen, hlf = (np.asarray(a, dtype=float)
                               for a in (origin, tangent, normal, centre, half))
    m = len(pts)
    if m <= 2:
        return np.arange(m, dtype=np.int64)
    kept = [0]
    i = 0
    ends = _band_ends(pts, org, nrm, cen, hlf)
    while i < m - 1:
        i = _farthest(pts[i], i, m - 1, pts, org, tan, nrm, cen, hlf, ends=ends)
        kept.append(i)
    return np.asarray(kept, dtype=np.int64)


def _farthest(p: FloatArray, i: int, cap: int, pts: FloatArray, origin: FloatArray,
              tangent: FloatArray, normal: FloatArray, centre: FloatArray, half: FloatArray,
              tol: float = 1e-9, ends: FloatArray | None = None) -> int:
    """Largest ``j`` in ``(i, cap]`` (at least ``i + 1``) such that every segment
    ``p -> pts[j']``, ``i < j' <= j``, crosses the lines ``i < k < j'`` inside their bands.

    The rays from ``p`` that meet band ``k`` form the angle between its two ends (seen
    from ``p``, relative to the road's direction at ``k``); a segment ``p -> pts[j]``
    crosses every band before ``j`` if its direction lies in all their angles (running
    maximum of the lower and minimum of the upper ends), and reaches each line ``k < j``
    as the lines do not cross.
    """
    if cap <= i + 1:
        return min(i + 1, len(pts) - 1)
    # the test is a running one: a window of candidates gives the same answer as all of
    # them unless every candidate in it passes, then a window four times as long
    window = 32
    if ends is None:
        ends = _band_ends(pts, origin, normal, centre, half)
    while True:
        end = min(cap, i + window)
        j = _farthest_upto(p, i, end, pts, origin, tangent, normal, centre, half, tol, ends)
        if j < end or end == cap:
            return j
        window *= 4


def _band_ends(pts: FloatArray, origin: FloatArray, normal: FloatArray, centre: FloatArray,
               half: FloatArray) -> FloatArray:
    """Per vertex ``(m, 3, 2)``: the lower and the upper end of its band, and the vertex."""
    return np.stack((origin + (centre - half)[:, None] * normal,
                     origin + (centre + half)[:, None] * normal, pts), axis=1)


def _farthest_upto(p: FloatArray, i: int, cap: int, pts: FloatArray, origin: FloatArray,
                   tangent: FloatArray, normal: FloatArray, centre: FloatArray,
                   half: FloatArray, tol: float, ends: FloatArray | None = None) -> int:
    """:func:`_farthest` over all candidates ``(i, cap]`` at once (``ends``: the
    :func:`_band_ends` of all vertices, computed here if ``None``)."""
    ks = slice(i + 1, cap + 1)
    ref = tangent[i + 1] if i + 1 < len(tangent) else tangent[-1]
    c, s = ref[0], ref[1]
    if ends is None:
        ends = _band_ends(pts, origin, normal, centre, half)
    # directions (relative to the road's) from p to both band ends and to the vertex
    q = ends[ks]
    dx, dy = q[..., 0] - p[0], q[..., 1] - p[1]
    ang = np.arctan2(-dx * s + dy * c, dx * c + dy * s)
    a1, a2, th = ang[:, 0], ang[:, 1], ang[:, 2]
    lo, hi = np.minimum(a1, a2), np.maximum(a1, a2)
    # a line through p itself does not constrain the direction
    o, t = origin[ks], tangent[ks]
    on = np.abs((o[:, 0] - p[0]) * t[:, 0] + (o[:, 1] - p[1]) * t[:, 1]) < 1e-9
    lo[on], hi[on] = -np.inf, np.inf
    # bounds from the lines strictly before each candidate
    low, high = np.empty(len(lo)), np.empty(len(hi))
    low[0], high[0] = -np.inf, np.inf
    np.maximum.accumulate(lo[:-1], out=low[1:])
    np.minimum.accumulate(hi[:-1], out=high[1:])
    good = (th >= low - tol) & (th <= high + tol)
    good[0] = True
    if good.all():
        return cap
    return int(i + np.argmin(good))


# ---- detour ----------------------------------------------------------------------------
def _steep(roadmap: Roadmap, rate: float) -> bool:
    """Whether level 2's path changes its lateral offset faster than ``rate`` somewhere
    (only then can :func:`detour_roadmap` find a path a curve follows better)."""
    ds = np.diff(np.asarray(roadmap.s, dtype=float))
    dl = np.abs(np.diff(np.asarray(roadmap.l, dtype=float)))
    return bool(np.any(dl > rate * np.maximum(ds, 1e-9) + 1e-9))


#: Lateral grid step [m] of :func:`detour_roadmap`'s search.
_DETOUR_STEP = 0.1
#: Distance [m] to a free interval's ends below which the detour search pays for nearness.
_DETOUR_CLEAR = 1.0


def detour_roadmap(roadmap: Roadmap, corridor: Corridor, rate: float) -> Roadmap | None:
    """Level 2's roadmap with its path replaced by one that a curve can follow.

    The widest path may jump between lanes wherever a sweep line is free across (its
    vertex stands mid-road), and a lane a hair narrower than the bottleneck elsewhere
    sends it across two lanes and back within a gap between parked cars, which no curve
    within the turning limit follows. This searches the same graph (its free intervals
    and arcs) on a lateral grid of :data:`_DETOUR_STEP` [m] for the path whose lateral
    offset changes by at most ``rate`` [m per m of station] from line to line, starting
    at the vehicle's offset, that minimises the sum of squared lateral steps over their
    lengths plus a penalty for passing within :data:`_DETOUR_CLEAR` [m] of an interval's
    end (dynamic programming over the lines). Its vertices stand at those offsets, inside
    their free intervals. ``None`` if the graph has no such path.
    """
    line = np.asarray(roadmap.graph_line, dtype=np.int64)
    if len(line) == 0 or len(roadmap.arcs) == 0 or rate <= 0:
        return None
    lo_v = np.asarray(roadmap.graph_lo, dtype=float)
    hi_v = np.asarray(roadmap.graph_hi, dtype=float)
    n_lines, n_v = int(line.max()) + 1, len(line)
    st = np.zeros(n_lines)
    st[line] = roadmap.graph_s
    h = _DETOUR_STEP
    l0 = float(lo_v.min()) - h
    nb = int(np.ceil((float(hi_v.max()) + h - l0) / h)) + 1
    grid = l0 + h * np.arange(nb)
    # vid[k, b]: the vertex of line k whose interval holds grid offset b (half a step of
    # tolerance, so that zero-width intervals count), -1 where none does
    vid = np.full((n_lines, nb), -1, dtype=np.int64)
    b_lo = np.ceil((lo_v - h / 2 - l0) / h - 1e-9).astype(np.int64)
    b_hi = np.floor((hi_v + h / 2 - l0) / h + 1e-9).astype(np.int64)
    for v in range(n_v):
        vid[line[v], b_lo[v]:b_hi[v] + 1] = v
    lv = np.clip(grid[None, :], lo_v[vid], hi_v[vid])
    near = np.minimum(lv - lo_v[vid], hi_v[vid] - lv)
    penalty = np.where(vid >= 0, np.maximum(_DETOUR_CLEAR - near, 0.0) ** 2, np.inf)
    # moves b - dlt -> b between lines k and k + 1 that follow an arc within the rate:
    # ok[k, b, dlt + r], with their lateral cost
    ds = np.maximum(np.diff(st), 1e-6)
    r = int(np.floor(rate * float(ds.max()) / h + 1e-9))
    dlt = np.arange(-r, r + 1)
    frm = np.arange(nb)[:, None] - dlt[None, :]
    # arcs as tables per pair of lines, (lines - 1, P + 1, P + 1), over each vertex's index
    # on its line (P: none, never connected)
    by_line = np.argsort(line, kind="stable")
    loc = np.empty(n_v, dtype=np.int64)
    loc[by_line] = np.arange(n_v) - np.searchsorted(line[by_line], line[by_line])
    n_loc = int(loc.max()) + 1
    arcs = np.asarray(roadmap.arcs, dtype=np.int64)
    arcs = arcs[line[arcs[:, 1]] == line[arcs[:, 0]] + 1]
    table = np.zeros((n_lines - 1, n_loc + 1, n_loc + 1), dtype=bool)
    table[line[arcs[:, 0]], loc[arcs[:, 0]], loc[arcs[:, 1]]] = True
    lid = np.full((n_lines, nb + 2 * r), n_loc)  # padded by r bins of none on each side
    lid[:, r:r + nb] = np.where(vid >= 0, loc[vid], n_loc)
    # flat index into the tables: (line, from, to)
    flat = lid[:-1][:, frm + r]
    flat += (n_loc + 1) * np.arange(n_lines - 1)[:, None, None]
    flat *= n_loc + 1
    flat += lid[1:, r:r + nb, None]
    ok = table.ravel()[flat]
    ok &= np.abs(dlt)[None, None, :] * h <= rate * ds[:, None, None] + 1e-9
    lat_cost = (dlt[None, :] * h) ** 2 / ds[:, None]  # (lines - 1, 2r + 1)
    step_cost = np.where(ok, lat_cost[:, None, :], np.inf)  # (lines - 1, nb, 2r + 1)
    frm_c = np.clip(frm, 0, nb - 1)
    # start: the source vertex, at the vehicle's offset
    src = int(roadmap.path[0])
    l_start = float(corridor.to_sl(np.asarray(roadmap.start_xy, dtype=float)[None])[0, 1])
    cost = np.where(vid[0] == src, np.abs(grid - l_start), np.inf)
    cost = np.where(cost <= np.min(cost) + 1e-9, penalty[0], np.inf)
    back = np.zeros((n_lines, nb), dtype=np.int64)
    rows = np.arange(nb)
    for k in range(n_lines - 1):
        cand = cost[frm_c] + step_cost[k]
        j = np.argmin(cand, axis=1)
        cost = cand[rows, j] + penalty[k + 1]
        back[k + 1] = j
    if not np.isfinite(cost).any():
        return None
    bins = np.zeros(n_lines, dtype=np.int64)
    bins[-1] = int(np.argmin(cost))
    for k in range(n_lines - 1, 0, -1):
        bins[k - 1] = frm_c[bins[k], back[k, bins[k]]]
    ks = np.arange(n_lines)
    path = vid[ks, bins]
    lat = lv[ks, bins]
    xy = corridor.to_xy(st, lat)
    width = np.asarray(roadmap.graph_width, dtype=float)[path]
    j = int(np.argmin(width))
    return replace(roadmap, xy=xy, s=st.copy(), l=lat, width=width,
                   bottleneck_width=float(width[j]), bottleneck_index=j,
                   length=float(polyline_stations(xy)[-1]), path=path,
                   links=np.zeros((0, 2, 2)))
