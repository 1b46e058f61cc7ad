"""The compiled loops of :mod:`splineplan.control_polygon` against their array formulas."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import winding_line
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.linalg import solveh_banded

from splineplan.control_polygon import (
    _PIN,
    _TOL,
    _band_ends,
    _farthest_from,
    band_simplify,
    min_bending_offsets,
    min_turning_offsets,
    polygon_turns,
)


def farthest_reference(p: np.ndarray, i: int, cap: int, pts: np.ndarray, origin: np.ndarray,
                       tangent: np.ndarray, normal: np.ndarray, centre: np.ndarray,
                       half: np.ndarray, tol: float = 1e-9) -> int:
    """The string-pulling test over all candidates ``(i, cap]`` at once, in array code."""
    if cap <= i + 1:
        return min(i + 1, len(pts) - 1)
    ks = slice(i + 1, cap + 1)
    ref = tangent[i + 1] if i + 1 < len(tangent) else tangent[-1]
    c, s = ref[0], ref[1]
    ends = np.stack((origin + (centre - half)[:, None] * normal,
                     origin + (centre + half)[:, None] * normal, pts), axis=1)
    q = ends[ks]
    dx, dy = q[..., 0] - p[0], q[..., 1] - p[1]
    ang = np.arctan2(-dx * s + dy * c, dx * c + dy * s)
    a1, a2, th = ang[:, 0], ang[:, 1], ang[:, 2]
    lo, hi = np.minimum(a1, a2), np.maximum(a1, a2)
    o, t = origin[ks], tangent[ks]
    on = np.abs((o[:, 0] - p[0]) * t[:, 0] + (o[:, 1] - p[1]) * t[:, 1]) < 1e-9
    lo[on], hi[on] = -np.inf, np.inf
    low, high = np.empty(len(lo)), np.empty(len(hi))
    low[0], high[0] = -np.inf, np.inf
    np.maximum.accumulate(lo[:-1], out=low[1:])
    np.minimum.accumulate(hi[:-1], out=high[1:])
    good = (th >= low - tol) & (th <= high + tol)
    good[0] = True
    if good.all():
        return cap
    return int(i + np.argmin(good))


def band_simplify_reference(pts: np.ndarray, origin: np.ndarray, tangent: np.ndarray,
                            normal: np.ndarray, centre: np.ndarray, half: np.ndarray
                            ) -> np.ndarray:
    """Greedy string pulling, one :func:`farthest_reference` after the other."""
    m = len(pts)
    if m <= 2:
        return np.arange(m)
    kept, i = [0], 0
    while i < m - 1:
        i = farthest_reference(pts[i], i, m - 1, pts, origin, tangent, normal, centre, half)
        kept.append(i)
    return np.asarray(kept)


def random_bands(rng: np.random.Generator, m: int, width: float
                 ) -> tuple[np.ndarray, ...]:
    """Sweep lines along a winding road, with vertices inside bands of random width (some
    zero, some vertices on a straight stretch, so that exact collinearity occurs)."""
    turn = rng.normal(0.0, 0.05, m) * (rng.random(m) < 0.7)
    heading = np.cumsum(turn)
    step = np.where(rng.random(m) < 0.5, 1.0, rng.uniform(0.2, 2.0, m))
    origin = np.column_stack((np.cumsum(step * np.cos(heading)),
                              np.cumsum(step * np.sin(heading))))
    tangent = np.column_stack((np.cos(heading), np.sin(heading)))
    normal = np.column_stack((-tangent[:, 1], tangent[:, 0]))
    centre = np.where(rng.random(m) < 0.3, 0.0, rng.uniform(-width, width, m))
    half = np.where(rng.random(m) < 0.3, 0.0, rng.uniform(0.0, width, m))
    lat = centre + rng.uniform(-1.0, 1.0, m) * half
    pts = origin + lat[:, None] * normal
    return pts, origin, tangent, normal, centre, half


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), m=st.integers(1, 120),
       width=st.sampled_from([0.0, 0.05, 0.5, 2.0]))
def test_band_simplify_matches_array_formula(seed: int, m: int, width: float) -> None:
    rng = np.random.default_rng(seed)
    args = random_bands(rng, m, width)
    got = band_simplify(*args)
    assert got.dtype == np.int64
    np.testing.assert_array_equal(got, band_simplify_reference(*args))


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), m=st.integers(2, 120),
       width=st.sampled_from([0.0, 0.5, 2.0]))
def test_farthest_from_a_point_off_the_vertices(seed: int, m: int, width: float) -> None:
    """From the vehicle's position (``i = -1``) and from vertices, up to random caps."""
    rng = np.random.default_rng(seed)
    pts, origin, tangent, normal, centre, half = random_bands(rng, m, width)
    start = origin[0] - 2.0 * tangent[0] + rng.uniform(-1.0, 1.0) * normal[0]
    for i in (-1, *rng.integers(0, m, 3).tolist()):
        p = start if i < 0 else pts[i]
        cap = int(rng.integers(i + 1, m)) if i + 1 < m else m - 1
        ends = _band_ends(pts, origin, normal, centre, half)
        assert (_farthest_from(float(p[0]), float(p[1]), i, cap, ends, origin, tangent, _TOL)
                == farthest_reference(p, i, cap, pts, origin, tangent, normal, centre, half))


def min_bending_reference(origin: np.ndarray, normal: np.ndarray, lo: np.ndarray,
                          hi: np.ndarray, centre: np.ndarray, weight: float,
                          max_rounds: int = 30) -> np.ndarray:
    """The active-set loops in array code, each system solved by scipy's banded Cholesky."""
    m = len(origin)
    if m < 3:
        return np.clip(centre, lo, hi)
    h = np.maximum(np.hypot(*np.diff(origin, axis=0).T), 1e-3)
    w = np.sqrt(2.0 / (h[:-1] + h[1:]))
    coef = np.column_stack((w / h[:-1], -w * (1.0 / h[:-1] + 1.0 / h[1:]), w / h[1:]))
    m0, m1 = np.zeros(m), np.zeros(m - 1)
    for a in range(3):
        m0[a:m - 2 + a] += coef[:, a] ** 2
    for a in range(2):
        m1[a:m - 2 + a] += coef[:, a] * coef[:, a + 1]
    m2 = coef[:, 0] * coef[:, 2]
    nn1 = np.einsum("ij,ij->i", normal[:-1], normal[1:])
    nn2 = np.einsum("ij,ij->i", normal[:-2], normal[2:])
    n0 = np.einsum("ij,ij->i", normal, normal)
    h0, h1, h2 = m0 * n0 + weight + 1e-9, m1 * nn1, m2 * nn2
    second = (coef[:, 0, None] * origin[:-2] + coef[:, 1, None] * origin[1:-1]
              + coef[:, 2, None] * origin[2:])
    dt = np.zeros((m, 2))
    dt[:-2] += coef[:, 0, None] * second
    dt[1:-1] += coef[:, 1, None] * second
    dt[2:] += coef[:, 2, None] * second
    g = np.einsum("ij,ij->i", normal, dt) - weight * centre

    def hess(x: np.ndarray) -> np.ndarray:
        y = h0 * x
        y[:-1] += h1 * x[1:]
        y[1:] += h1 * x[:-1]
        y[:-2] += h2 * x[2:]
        y[2:] += h2 * x[:-2]
        return y

    fixed = lo >= hi

    def solve(at_lo: np.ndarray, at_hi: np.ndarray) -> np.ndarray:
        ab = np.zeros((3, m))
        ab[2] = h0 + _PIN * (at_lo | at_hi)
        ab[1, 1:] = h1
        ab[0, 2:] = h2
        rhs = -g + _PIN * np.where(at_lo, lo, np.where(at_hi, hi, 0.0))
        return solveh_banded(ab, rhs, lower=False, check_finite=False)

    at_lo, at_hi = np.zeros(m, dtype=bool), fixed.copy()
    for _ in range(max_rounds):
        x = solve(at_lo, at_hi)
        grad = hess(x) + g
        new_lo = ((at_lo & (grad >= 0)) | (x < lo - 1e-9)) & ~fixed
        new_hi = ((at_hi & (grad <= 0)) | (x > hi + 1e-9)) & ~new_lo | fixed
        if np.array_equal(new_lo, at_lo) and np.array_equal(new_hi, at_hi):
            break
        at_lo, at_hi = new_lo, new_hi
    x = np.clip(x, lo, hi)
    at_lo, at_hi = (x <= lo) & ~fixed, (x >= hi) | fixed
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


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), m=st.integers(1, 80),
       weight=st.sampled_from([0.0, 1e-4, 0.1]), max_rounds=st.sampled_from([1, 3, 30]))
def test_min_bending_offsets_matches_banded_solver(seed: int, m: int, weight: float,
                                                   max_rounds: int) -> None:
    """The compiled active-set loops give scipy's banded solutions to rounding (random
    winding lines, narrow and wide bands, fixed points, stopping the first loop early;
    without weight, three points make a system with a condition number near 1e9)."""
    rng = np.random.default_rng(seed)
    origin, normal, centre = winding_line(rng, m)
    scale = rng.choice([0.05, 2.0])
    lo, hi = centre - rng.uniform(0.0, scale, m), centre + rng.uniform(0.0, scale, m)
    fixed = rng.random(m) < 0.1
    lo[fixed] = hi[fixed] = centre[fixed]
    args = (origin, normal, lo, hi, centre, weight, max_rounds)
    np.testing.assert_allclose(min_bending_offsets(*args), min_bending_reference(*args),
                               rtol=0.0, atol=1e-9 if weight > 0 else 1e-6)


def corner_lines(radius: float, step: float = 1.0, straight: float = 15.0
                 ) -> tuple[np.ndarray, np.ndarray]:
    """Sweep lines (origins and left normals) every ``step`` [m] along a reference line that
    runs ``straight`` [m] north, turns right by 90 degrees on ``radius`` [m] and runs
    ``straight`` [m] east, as a lane's centre round a corner of a junction."""
    s_arc = 0.5 * np.pi * radius
    s = np.arange(0.0, 2 * straight + s_arc + 1e-9, step)
    pts, heads = [], []
    for v in s:
        if v <= straight:
            pts.append((0.0, v))
            heads.append(0.5 * np.pi)
        elif v <= straight + s_arc:
            a = (v - straight) / radius
            pts.append((radius - radius * np.cos(a), straight + radius * np.sin(a)))
            heads.append(0.5 * np.pi - a)
        else:
            pts.append((radius + v - straight - s_arc, straight + radius))
            heads.append(0.0)
    h = np.asarray(heads)
    return np.asarray(pts), np.column_stack((-np.sin(h), np.cos(h)))


@pytest.mark.parametrize("radius", [1.5, 3.2, 5.0])
def test_min_turning_offsets_spread_a_corner_within_the_bands(radius: float) -> None:
    """Round a right-angled corner with bands of +-1.6 m (a two-lane road's free interval
    for the car): the least-bending polygon crowds its turn on the inside, where the sweep
    lines fan in, and turns on less than the 4.2 m limit when the reference line turns on
    1.5 m; the reweighted polygon stays within the bands, turns less sharply at its
    sharpest, and keeps within the limit wherever the least-bending one does not."""
    origin, normal = corner_lines(radius)
    m = len(origin)
    centre = np.zeros(m)
    lo, hi = centre - 1.6, centre + 1.6
    lo[:2] = hi[:2] = 0.0  # the vehicle's position and heading point
    kappa_max = 1.0 / 4.2
    bend = min_bending_offsets(origin, normal, lo, hi, centre, 1e-4)
    turn = min_turning_offsets(origin, normal, lo, hi, centre, 1e-4, kappa_max)
    assert np.all((turn >= lo - 1e-9) & (turn <= hi + 1e-9))
    worst_bend = polygon_turns(origin + bend[:, None] * normal)[0].max()
    worst_turn = polygon_turns(origin + turn[:, None] * normal)[0].max()
    assert worst_turn <= worst_bend + 1e-9
    if radius == 1.5:
        assert worst_bend > kappa_max
    assert worst_turn <= kappa_max


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(1, 12), smooth=st.booleans(),
       cap=st.sampled_from([1.0, 4.0, 10.0]))
def test_leg_fractions_match_leg_by_leg(seed: int, n: int, smooth: bool, cap: float) -> None:
    """All legs' split fractions at once equal those computed leg by leg (short, long and
    empty legs; uniform pieces, or pieces growing from the neighbours), and every leg's
    pieces are at most ``cap`` long."""
    from splineplan.control_polygon import _leg_fractions, _leg_splits

    rng = np.random.default_rng(seed)
    leg_len = rng.choice([0.0, 0.3, 2.0, 8.0, 40.0], n) * rng.uniform(0.5, 1.5, n)
    empty = leg_len == 0.0
    want_f, want_leg = [], []
    for j in range(n):
        if empty[j]:
            continue
        if smooth:
            f = _leg_splits.py_func(leg_len[j], leg_len[j - 1] if j > 0 else np.inf,
                                    leg_len[j + 1] if j + 1 < n else np.inf, cap, 2.0)
        else:
            pieces = int(np.ceil(leg_len[j] / cap - 1e-9))
            f = np.arange(1, pieces) / max(pieces, 1)
        want_f.append(f)
        want_leg.append(np.full(len(f), j))
    f, leg = _leg_fractions(leg_len, empty, cap, 2.0, smooth)
    np.testing.assert_array_equal(f, np.concatenate(want_f) if want_f else np.empty(0))
    np.testing.assert_array_equal(leg, np.concatenate(want_leg) if want_leg else np.empty(0))
    assert np.all((f > 0.0) & (f < 1.0))
    for j in np.flatnonzero(~empty):
        pieces = np.diff(np.concatenate(([0.0], f[leg == j], [1.0]))) * leg_len[j]
        assert np.all(pieces > 0) and np.all(pieces <= cap * (1 + 1e-9))


@pytest.mark.parametrize("seed", [0, 3])
def test_shared_vertex_frame_gives_the_same_polygons(seed: int) -> None:
    """Both control polygons of a roadmap from one :func:`vertex_frame` equal those that
    compute it themselves, and building them leaves the shared frame as it was."""
    from benchmarks.fields import obstacle_field
    from splineplan.control_polygon import _control_points, vertex_frame
    from splineplan.planner import elongate_for_roadmap
    from splineplan.roadmap import RoadmapParams, plan_roadmap
    from splineplan.trajectory_params import TrajectoryParams

    corridor, obstacles, start = obstacle_field(300, 20, 9.6, seed)
    rp = RoadmapParams()
    rm = plan_roadmap(corridor, elongate_for_roadmap(corridor, obstacles, rp), start, rp)
    params = TrajectoryParams()
    frame = vertex_frame(rm, corridor, params)
    before = [a.copy() for a in (frame.start, frame.pts, frame.vs, *frame.lines)]
    for smooth in (False, True, False):
        pool, counts = _control_points(rm, corridor, 0.0, params, 5.0, smooth, frame=frame)
        want_pool, want_counts = _control_points(rm, corridor, 0.0, params, 5.0, smooth)
        np.testing.assert_array_equal(pool, want_pool)
        np.testing.assert_array_equal(counts, want_counts)
        assert counts.sum() < len(counts) and counts[:2].tolist() == [1, 1]
    for a, b in zip(before, (frame.start, frame.pts, frame.vs, *frame.lines), strict=True):
        np.testing.assert_array_equal(a, b)


def detour_sweep_reference(cost: np.ndarray, penalty: np.ndarray, lid: np.ndarray,
                           table: np.ndarray, within: np.ndarray, lat_cost: np.ndarray,
                           r: int) -> tuple[np.ndarray, np.ndarray]:
    """The detour's dynamic programme in array code: all moves' costs as one table, then
    a minimum per line."""
    n_lines, nb = penalty.shape
    n_loc = table.shape[1] - 1
    dlt = np.arange(-r, r + 1)
    frm = np.arange(nb)[:, None] - dlt[None, :]
    flat = lid[:-1][:, frm + r]
    flat += (n_loc + 1) * np.arange(n_lines - 1)[:, None, None]
    flat *= n_loc + 1
    flat += lid[1:, r:r + nb, None]
    ok = table.ravel()[flat] & within[:, None, :]
    step_cost = np.where(ok, lat_cost[:, None, :], np.inf)
    frm_c = np.clip(frm, 0, nb - 1)
    back = np.zeros((n_lines, nb), dtype=np.int64)
    rows = np.arange(nb)
    for k in range(n_lines - 1):
        cand = cost[frm_c] + step_cost[k]
        j = np.argmin(cand, axis=1)
        cost = cand[rows, j] + penalty[k + 1]
        back[k + 1] = j
    bins = np.zeros(n_lines, dtype=np.int64)
    bins[-1] = int(np.argmin(cost))
    for k in range(n_lines - 1, 0, -1):
        bins[k - 1] = frm_c[bins[k], back[k, bins[k]]]
    return cost, bins


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), n_lines=st.integers(1, 40), nb=st.integers(1, 30),
       r=st.integers(0, 4), n_loc=st.integers(1, 4))
def test_detour_sweep_matches_array_formula(seed: int, n_lines: int, nb: int, r: int,
                                            n_loc: int) -> None:
    """Random arcs, rates, costs (with ties: costs on a coarse grid) and bins without a
    vertex: the compiled programme takes the same moves to the same costs."""
    from splineplan.control_polygon import _detour_bins, _detour_sweep

    rng = np.random.default_rng(seed)
    lid = np.full((n_lines, nb + 2 * r), n_loc)
    lid[:, r:r + nb] = rng.integers(0, n_loc + 1, (n_lines, nb))
    table = rng.random((max(n_lines - 1, 0), n_loc + 1, n_loc + 1)) < 0.6
    table[:, n_loc, :] = table[:, :, n_loc] = False
    within = rng.random((max(n_lines - 1, 0), 2 * r + 1)) < 0.8
    lat_cost = rng.integers(0, 4, (max(n_lines - 1, 0), 2 * r + 1)) * 0.25
    penalty = np.where(rng.random((n_lines, nb)) < 0.1, np.inf,
                       rng.integers(0, 3, (n_lines, nb)) * 0.5)
    cost = np.where(rng.random(nb) < 0.5, np.inf, rng.integers(0, 3, nb) * 0.5)
    want_cost, want_bins = detour_sweep_reference(cost, penalty, lid, table, within,
                                                  lat_cost, r)
    got_cost, back = _detour_sweep(cost, penalty, lid, table, within, lat_cost, r)
    np.testing.assert_array_equal(got_cost, want_cost)
    np.testing.assert_array_equal(_detour_bins(back, int(np.argmin(got_cost)), r), want_bins)
