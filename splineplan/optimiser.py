"""Level 3's curve and its optimisation (steps 3 to 6 of :mod:`splineplan.trajectory`).

A clamped B-spline evaluated on fixed parameter samples with a cached basis
(:class:`_Curve`), the local repair of the first curve (:func:`_refine`) and equation (3),
which moves control points to their neighbours' mean while the footprint stays clear
(:class:`_Optimiser`): a move changes the samples linearly, so only the changed stretch is
re-evaluated and re-checked. Separate from the control polygon (where the points come
from) and from the sampling of the final curve (:mod:`splineplan.trajectory`).
"""

from __future__ import annotations

import itertools
import logging
from dataclasses import dataclass

import numpy as np
from numba import njit
from numpy.typing import NDArray

from splineplan import kernels
from splineplan.curvature import curvature_from_derivatives
from splineplan.footprint import _Checker
from splineplan.geometry import FloatArray, kernel_floats, kernel_ints
from splineplan.roadmap import BAND_KEEP
from splineplan.trajectory_params import TrajectoryParams

log = logging.getLogger(__name__)

#: Moves per control point that the steering's smoothing may try (a bound on its time).
SMOOTH_MOVES = 2

#: Control points beyond those shaping a sample over the turning limit, on each side, that
#: :meth:`_Optimiser.ease_bends` moves too (the bend spreads over them).
BEND_REACH = 3
#: Largest move [m] of a control point in :meth:`_Optimiser.ease_bends`.
BEND_MOVE = 1.5
#: Step [m] of the finite differences of the footprint's slack.
_BEND_EPS = 1e-4

#: Room [m] beyond the safety margin that a sideways push of the curve aims for (see
#: :func:`_push`).
PUSH_EXTRA = 0.03


# ---- spline set-up ---------------------------------------------------------------------
def _knots(n: int, k: int) -> FloatArray:
    inner = np.linspace(0.0, 1.0, n - k + 1)
    return np.concatenate((np.zeros(k), inner, np.ones(k)))


def _basis(u: FloatArray, t: FloatArray, k: int, n: int) -> tuple[NDArray[np.int64], FloatArray]:
    """First control index ``(m,)`` and basis values ``(3, k + 1, m)`` for nu = 0, 1, 2.

    ``basis[nu, :, j]`` holds the values at ``u[j]`` of the basis functions of control
    points ``first[j] .. first[j] + k`` (the only ones that are not zero there) and their
    first and second derivatives with respect to the parameter (Cox-de Boor recursion; at
    ``u = 1`` the left limits).
    """
    return _basis_kernel(kernel_floats(u),
                         kernel_floats(t), k, n)


@njit(cache=True, inline="always")
def _ratio(a: float, b: float) -> float:  # pragma: no cover - compiled
    """``a / b`` where ``b > 0``, else 0."""
    return a / b if b > 0 else 0.0


@njit(cache=True)
def _basis_kernel(u: FloatArray, t: FloatArray, k: int, n: int
                  ) -> tuple[NDArray[np.int64], FloatArray]:  # pragma: no cover - compiled
    """:func:`_basis`, one sample at a time."""
    m = len(u)
    first = np.empty(m, dtype=np.int64)
    vals = np.zeros((3, k + 1, m))
    tt = np.empty(2 * k + 2)
    # tables[p, :p + 1]: the degree-p functions span - p .. span; ext: one padded table
    tables = np.zeros((k + 1, k + 1))
    ext = np.zeros(k + 3)
    der = np.zeros(k + 1)
    span = k
    for j in range(m):
        # the knot span: t[span] <= u[j] < t[span + 1], within k .. n - 1 (walking on from
        # the last sample's: samples ascend)
        if u[j] < t[span]:
            span = k
        while span < n - 1 and t[span + 1] <= u[j]:
            span += 1
        first[j] = span - k
        # the knots around the sample: tt[r] = t[span + r - k], r = 0 .. 2k + 1
        for r in range(2 * k + 2):
            tt[r] = t[span + r - k]
        tables[0, 0] = 1.0
        for p in range(1, k + 1):
            ext[0] = ext[p + 1] = 0.0
            for q in range(p):  # loops, not slices: a slice assignment compiles slowly
                ext[1 + q] = tables[p - 1, q]
            for q in range(p + 1):
                # function span - p + q: knots t[i], t[i + 1], t[i + p], t[i + p + 1]
                ti, ti1, tip, tip1 = tt[k - p + q], tt[k - p + 1 + q], tt[k + q], tt[k + 1 + q]
                tables[p, q] = (_ratio(u[j] - ti, tip - ti) * ext[q]
                                + _ratio(tip1 - u[j], tip1 - ti1) * ext[q + 1])
        for q in range(k + 1):
            vals[0, q, j] = tables[k, q]
        _derive_into(tables[k - 1, :k], tt, k, k, vals[1, :, j])
        if k >= 2:
            _derive_into(tables[k - 2, :k - 1], tt, k, k - 1, der[:k])
            _derive_into(der[:k], tt, k, k, vals[2, :, j])
    return first, vals


@njit(cache=True, inline="always")
def _derive_into(b: FloatArray, tt: FloatArray, k: int, p: int,
                 out: FloatArray) -> None:  # pragma: no cover - compiled
    """Parameter derivatives ``(p + 1,)`` of the degree-``p`` basis functions
    ``span - p .. span`` from the degree ``p - 1`` ones ``b`` ``(p,)``, into ``out``:
    ``N'_{i,p} = p (N_{i,p-1} / (t_{i+p} - t_i) - N_{i+1,p-1} / (t_{i+p+1} - t_{i+1}))``
    (``tt``: the knots around the sample, as in :func:`_basis_kernel`)."""
    for q in range(p + 1):
        lo = b[q - 1] if q >= 1 else 0.0
        hi = b[q] if q < p else 0.0
        out[q] = p * (_ratio(lo, tt[k + q] - tt[k - p + q])
                      - _ratio(hi, tt[k + 1 + q] - tt[k - p + 1 + q]))


def _greville(t: FloatArray, k: int, n: int) -> FloatArray:
    if k == 0:
        return np.asarray(t[:n], dtype=float)
    cs = np.concatenate(([0.0], np.cumsum(t)))
    i = np.arange(n)
    return np.asarray((cs[i + k + 1] - cs[i + 1]) / k)


# ---- curve, repair and equation (3) ----------------------------------------------------
@dataclass(frozen=True, eq=False)
class _Curve:
    """A clamped B-spline on fixed parameter samples, with its basis there.

    ``first[j]`` is the first of the ``k + 1`` control points that shape sample ``j``;
    ``basis[nu, :, j]`` their values (nu = 0) and parameter derivatives (nu = 1, 2) there.
    ``pool_index`` maps each control point to its index among the candidates.
    """

    ctrl: FloatArray
    pool_index: NDArray[np.int64]
    knots: FloatArray
    k: int
    u: FloatArray
    first: NDArray[np.int64]
    basis: FloatArray

    @classmethod
    def build(cls, ctrl: FloatArray, pool_index: NDArray[np.int64], degree: int,
              spacing: float) -> _Curve:
        n = len(ctrl)
        k = min(degree, n - 1)
        knots = _knots(n, k)
        # samples per knot span from the longest nearby leg: moves to neighbours' means never
        # lengthen a leg beyond the longest of its neighbours
        legs = np.hypot(*np.diff(ctrl, axis=0).T)
        padded = np.concatenate(([legs[0]], legs, [legs[-1]]))
        span_len = padded[:n - k].copy()  # the longest of the k + 2 legs around each span
        for j in range(1, k + 2):
            np.maximum(span_len, padded[j:j + n - k], out=span_len)
        per = np.clip(np.ceil(span_len / spacing).astype(int) + 1, 2, 400)
        inner = knots[k:n + 1]
        # per span, evenly spaced from its start (as np.linspace without the end point)
        step = np.repeat(np.diff(inner) / per, per)
        within = np.arange(int(per.sum())) - np.repeat(np.cumsum(per) - per, per)
        u = np.concatenate((within * step + np.repeat(inner[:-1], per), [1.0]))
        first, basis = _basis(u, knots, k, n)
        return cls(ctrl, pool_index, knots, k, u, first, basis)

    def combine(self, values: FloatArray) -> FloatArray:
        """The curve's blend ``(m,)`` at the samples of one value per control point ``(n,)``
        (e.g. their stations: an estimate of the samples' stations)."""
        cols = self.first + np.arange(self.k + 1)[:, None]
        return np.asarray((self.basis[0] * values[cols]).sum(axis=0))

    def evaluate(self, ctrl: FloatArray | None = None) -> tuple[FloatArray, FloatArray,
                                                                  FloatArray]:
        """Positions, first and second parameter derivatives ``(m, 2)`` at the samples."""
        c = kernel_floats(self.ctrl if ctrl is None else ctrl)
        return _evaluate_kernel(c, self.first, self.basis, self.k)


@njit(cache=True)
def _evaluate_kernel(ctrl: FloatArray, first: NDArray[np.int64], basis: FloatArray, k: int
                     ) -> tuple[FloatArray, FloatArray, FloatArray]:  # pragma: no cover
    """:meth:`_Curve.evaluate`: per sample and derivative order, the basis-weighted sum of
    the ``k + 1`` shaping control points, in their order."""
    m = len(first)
    out = np.empty((3, m, 2))
    for nu in range(3):
        for j in range(m):
            f = first[j]
            x, y = basis[nu, 0, j] * ctrl[f, 0], basis[nu, 0, j] * ctrl[f, 1]
            for r in range(1, k + 1):
                x += basis[nu, r, j] * ctrl[f + r, 0]
                y += basis[nu, r, j] * ctrl[f + r, 1]
            out[nu, j, 0], out[nu, j, 1] = x, y
    return out[0].copy(), out[1].copy(), out[2].copy()


#: How far [m] the first curve may stray beyond level 2's bands (toward the obstacles, or
#: out of its lane) before :func:`_refine` repairs it there.
BAND_TOL = 0.05


def band_excess(checker: _Checker, pos: FloatArray, station: FloatArray,
                band: tuple[FloatArray, ...] | None) -> FloatArray:
    """How far [m] each sample ``(m, 2)`` at ``station`` ``(m,)`` [m] lies beyond level 2's
    bands ``(stations, low, high)`` (:attr:`splineplan.roadmap.Roadmap.band_lo`,
    ``band_hi``, interpolated at the sample's station), 0 within them; zeros without
    bands."""
    if band is None or len(band[0]) < 2:
        return np.zeros(len(pos))
    cor = checker.corridor
    ref = cor.to_xy(station, np.zeros(len(station)))
    h = cor.heading_at(station)
    lat = (pos[:, 1] - ref[:, 1]) * np.cos(h) - (pos[:, 0] - ref[:, 0]) * np.sin(h)
    st, lo, hi = band
    inside = (station >= st[0]) & (station <= st[-1])
    over = np.maximum(np.interp(station, st, lo) - lat, lat - np.interp(station, st, hi))
    return np.asarray(np.where(inside, np.maximum(over, 0.0), 0.0))


def _refine(pool: FloatArray, counts: NDArray[np.int64], checker: _Checker,
            params: TrajectoryParams, band: tuple[FloatArray, ...] | None = None
            ) -> tuple[_Curve, int, int, tuple[FloatArray, ...]]:
    """The first curve, repaired locally where its footprint is not clear.

    For each sample where the footprint touches an obstacle (with the margin) or leaves the
    road, or where the curve cuts a corner of its polygon more than :data:`BAND_TOL` beyond
    level 2's ``band`` (stations, low and high lateral offsets [m]; see
    :func:`band_excess`), giving away the separation that the roadmap keeps, the
    left-out candidate nearest to it, among those between the control points that
    shape it, comes back; where none is left there, the shaping control point nearest to
    the sample is doubled (up to ``degree`` copies: repeated control points pull the curve
    onto its control polygon, undoing the corner cut). At most ``repair_rounds`` rounds,
    and none after two rounds that did not improve on the best curve; the least violating
    curve is returned (footprint first, then curvature: the curvature is left to the
    optimisation; a curve beyond the bands counts after both), pushed sideways off a road
    edge where it still comes too close
    (:func:`_push`; its rounds count as repair rounds).

    Returns the curve, the rounds, the number of control points doubled and the curve's
    samples (positions, derivatives, footprint slack, stations) for the optimiser.
    """
    counts = counts.astype(np.int64)  # a copy
    pool = kernel_floats(pool)
    rounds = doubled = stall = 0
    n_pool = len(pool)
    # the candidates' stations: blended by the basis, they estimate the samples' stations,
    # which the footprint check refines (no nearest-point search per sample)
    pool_s = checker.stations(pool)
    best: tuple[tuple[float, float, float], _Curve, int, int, tuple[FloatArray, ...]] | None = None
    while True:
        pool_idx = np.repeat(np.arange(n_pool), counts)
        curve = _Curve.build(pool[pool_idx], pool_idx, params.degree, params.sample_spacing)
        pos, d1, d2 = curve.evaluate()
        slack, sc = checker.slack(pos, np.arctan2(d1[:, 1], d1[:, 0]),
                                  curve.combine(pool_s[pool_idx]))
        kmax = float(np.abs(curvature_from_derivatives(d1, d2)).max())
        over = band_excess(checker, pos, sc, band)
        # violation: footprint [m] inside the margin, then curvature beyond the limit,
        # then the separation given away
        score = (max(-float(slack.min()), 0.0), max(kmax - params.kappa_max, 0.0),
                 float(np.round(over.max(), 3)))
        if best is None or score < best[0]:
            best = (score, curve, rounds, doubled, (pos, d1, d2, slack, sc))
            stall = 0
        else:
            stall += 1
        bad = np.flatnonzero((slack < 0) | (over > BAND_TOL))
        if len(bad) == 0 or rounds >= params.repair_rounds or stall >= 2:
            break
        add, dup = _repair_marks(bad, curve.first, pool_idx, counts, pool, pos, curve.k)
        if not (add.any() or dup.any()):
            break
        counts[add] = 1
        counts[dup] += 1
        doubled += int(dup.sum())
        rounds += 1
    # the least violating curve seen (the first clear one, if any)
    assert best is not None
    curve, samples = best[1], best[4]
    pushes = 0
    if best[0][0] > 0:
        curve, samples, pushes = _push(curve, samples, checker, params,
                                       pool_s[curve.pool_index])
    return curve, best[2] + pushes, best[3], samples


@njit(cache=True)
def _repair_marks(bad: NDArray[np.int64], first: NDArray[np.int64],
                  pool_idx: NDArray[np.int64], counts: NDArray[np.int64], pool: FloatArray,
                  pos: FloatArray, k: int
                  ) -> tuple[NDArray[np.bool_], NDArray[np.bool_]]:  # pragma: no cover
    """The candidates :func:`_refine` re-inserts for the violating samples ``bad`` (the
    left-out one nearest each, between its shaping control points), and, where none is
    left for any, the control points it doubles (the inner shaping one nearest each,
    fewer than ``k`` copies so far)."""
    n, n_pool = len(pool_idx), len(pool)
    add = np.zeros(n_pool, dtype=np.bool_)
    dup = np.zeros(n_pool, dtype=np.bool_)
    for j in bad:
        a, b = pool_idx[first[j]], pool_idx[min(first[j] + k, n - 1)]
        best, pick = np.inf, -1
        for c in range(a + 1, b):
            if counts[c] == 0:
                d = np.hypot(pool[c, 0] - pos[j, 0], pool[c, 1] - pos[j, 1])
                if d < best:
                    best, pick = d, c
        if pick >= 0:
            add[pick] = True
    if add.any():
        return add, dup
    for j in bad:
        best, pick = np.inf, -1
        for r in range(first[j], min(first[j] + k, n - 1) + 1):
            c = pool_idx[r]
            if 2 <= c < n_pool - 1 and counts[c] < k:
                d = np.hypot(pool[c, 0] - pos[j, 0], pool[c, 1] - pos[j, 1])
                if d < best:
                    best, pick = d, c
        if pick >= 0:
            dup[pick] = True
    return add, dup


def _push(curve: _Curve, samples: tuple[FloatArray, ...], checker: _Checker,
          params: TrajectoryParams, ctrl_s: FloatArray
          ) -> tuple[_Curve, tuple[FloatArray, ...], int]:
    """The curve shifted sideways where its footprint comes within the margin of one road
    edge while the other edge leaves room (a lane's curve that cuts a corner a few
    centimetres too far): the control points that shape each such sample move along the
    road's normal by what it lacks (plus :data:`PUSH_EXTRA`), as far as the other side
    allows, so that the curve there moves by as much (a B-spline's basis sums to one).

    A round (else half of it) is kept only if it lowers the largest footprint violation, or
    the total at an equal largest, without raising the curve's largest curvature above
    the turning limit or its former value; at most ``repair_rounds`` rounds. Returns the
    curve, its samples (as :func:`_refine`) and the rounds kept. ``ctrl_s``: the control
    points' stations (a sideways push keeps them), which estimate the samples' stations.
    """
    pos, d1, d2, slack, sc = samples

    def score(sl: FloatArray) -> tuple[float, float]:
        over = np.maximum(-sl, 0.0)
        return float(np.round(over.max(), 9)), float(over.sum())

    best = score(slack)
    bend_best = float(np.abs(curvature_from_derivatives(d1, d2)).max())
    n, k, m = len(curve.ctrl), curve.k, checker.road_margin
    kept = 0
    for _ in range(params.repair_rounds):
        bad = np.flatnonzero(slack < 0)
        if len(bad) == 0:
            break
        cl, cr = checker.road(pos[bad], np.arctan2(d1[bad, 1], d1[bad, 0]), sc[bad],
                              sides=True)
        # positive: to the left; nothing where both edges or neither (an obstacle) is close
        shift = np.where((cr < m) & (cl >= m), np.minimum(m - cr + PUSH_EXTRA, cl - m), 0.0)
        shift = np.where((cl < m) & (cr >= m), -np.minimum(m - cl + PUSH_EXTRA, cr - m), shift)
        go = np.flatnonzero(np.abs(shift) > 1e-9)
        if len(go) == 0:
            break
        h = checker.corridor.heading_at(sc[bad[go]])
        vec = shift[go, None] * np.column_stack((-np.sin(h), np.cos(h)))
        move = np.zeros_like(curve.ctrl)
        size = np.zeros(n)
        for j, v, a in zip(bad[go].tolist(), vec, np.abs(shift[go]), strict=True):
            cols = np.arange(int(curve.first[j]), int(curve.first[j]) + k + 1)
            cols = cols[(cols >= 2) & (cols <= n - 2) & (size[cols] < a)]
            move[cols], size[cols] = v, a
        # copies of a doubled control point move together (apart, they would make a short
        # leg, a curvature spike)
        for a, b in _runs(curve.pool_index):
            j = a + int(np.argmax(size[a:b]))
            move[a:b], size[a:b] = move[j], size[j]
        if not size.any():
            break
        for scale in (1.0, 0.5):  # the whole push, else half of it
            cand = _Curve.build(curve.ctrl + scale * move, curve.pool_index, params.degree,
                                params.sample_spacing)
            p2, e1, e2 = cand.evaluate()
            s2, c2 = checker.slack(p2, np.arctan2(e1[:, 1], e1[:, 0]), cand.combine(ctrl_s))
            new = score(s2)
            bend = float(np.abs(curvature_from_derivatives(e1, e2)).max())
            if new < best and bend <= max(bend_best, params.kappa_max) + 1e-12:
                break
        else:
            break
        curve, best, bend_best, kept = cand, new, bend, kept + 1
        pos, d1, d2, slack, sc = p2, e1, e2, s2, c2
    return curve, (pos, d1, d2, slack, sc), kept


def _runs(values: NDArray[np.int64]) -> list[tuple[int, int]]:
    """Start and end ``[a, b)`` of each run of two or more equal consecutive values."""
    cut = np.flatnonzero(np.diff(values) != 0) + 1
    bounds = np.concatenate(([0], cut, [len(values)]))
    return [(int(a), int(b)) for a, b in itertools.pairwise(bounds) if b - a > 1]


class _Optimiser:
    """Equation (3) on fixed parameter samples, with local re-evaluation."""

    def __init__(self, curve: _Curve, checker: _Checker, params: TrajectoryParams,
                 samples: tuple[FloatArray, ...]) -> None:
        self.ctrl = curve.ctrl.copy()
        first, k, u, knots = curve.first, curve.k, curve.u, curve.knots
        self.first, self.basis, self.k = first, curve.basis, k
        self.checker, self.params = checker, params
        n = len(self.ctrl)
        cols = first[:, None] + np.arange(k + 1)[None, :]
        self.pos, self.d1, self.d2, self.slack, self.station = (a.copy() for a in samples)
        self.kappa = np.abs(curvature_from_derivatives(self.d1, self.d2))
        # samples a move of control point i changes: [lo[i], hi[i])
        idx = np.arange(n)
        self.lo = np.searchsorted(first, idx - k, side="left")
        self.hi = np.searchsorted(first, idx, side="right")
        # for each sample, the shaping control points ordered by Greville distance
        grev = _greville(knots, k, n)
        order = np.argsort(np.abs(grev[cols] - u[:, None]), axis=1, kind="stable")
        self.cand = np.take_along_axis(cols, order, axis=1)
        self.pool_index = curve.pool_index
        self.movable = np.ones(n, dtype=bool)
        self.movable[:2] = False  # the start and its heading point
        self.movable[-1] = False
        self.refused = np.zeros(n, dtype=bool)
        #: clearance [m] from the obstacles beyond the safety margin that the moves keep
        #: at each sample that has it (:meth:`keep_separation`)
        self.floor = np.zeros(len(self.kappa))

    def keep_separation(self, stations: FloatArray, separation: FloatArray) -> None:
        """Hold the moves to the separation from the obstacles that level 2's placed
        vertices keep (``separation`` ``(m,)`` [m] beyond the grown obstacles at corridor
        ``stations`` ``(m,)`` [m]; 0 where no obstacle bounds a vertex's interval): no
        move brings a sample that keeps :data:`~splineplan.roadmap.BAND_KEEP` of it (at
        most ``TrajectoryParams.keep_separation``), at its station, below that."""
        if len(stations) == 0:
            return
        share = BAND_KEEP * np.interp(self.station, stations, separation, left=0.0,
                                      right=0.0)
        self.floor = np.minimum(share, self.params.keep_separation)

    def run(self) -> tuple[int, int, int, int]:
        """Rounds of moves until no point is slow, none may move, ``max_iterations`` moves
        were tried or ``patience`` rounds did not help; keeps the best curve seen.

        Each round makes the move of the slowest point and those of the slowest points of
        other independent stretches (:func:`splineplan.kernels.independent_moves`); a move
        is kept if the footprint along its changed samples stays clear and their worst
        violation does not grow.
        Returns the moves tried, accepted and refused, and the rounds.
        """
        p = self.params
        ch = self.checker
        out = kernels.optimise(
            self.ctrl, self.pos, self.d1, self.d2, self.kappa, self.slack, self.station,
            kernel_ints(self.first), kernel_floats(self.basis),
            self.lo.astype(np.int64), self.hi.astype(np.int64),
            kernel_ints(self.cand), self.movable, self.refused,
            self.k, p.kappa_smax, p.kappa_max, p.max_iterations, p.patience,
            kernel_floats(self.floor), ch.slack_args())
        tried, accepted, refused, rounds = (int(v) for v in out)
        log.debug("optimisation: %d rounds, %d tried, %d accepted", rounds, tried, accepted)
        return tried, accepted, refused, rounds

    def smooth_steering(self, start_speed: float) -> tuple[int, int]:
        """Where the steering rate rather than the curvature sets the speed (the start and
        end of a turn, a lane change at speed), spread the change of curvature by moving
        control points while the footprint stays clear
        (:func:`splineplan.kernels.smooth_steering`): the car then keeps its speed there
        instead of slowing to turn the wheel. ``start_speed`` [m/s]: where the speed
        profile starts. Returns the moves tried and accepted."""
        p = self.params
        if not np.isfinite(p.max_steering_rate):
            return 0, 0
        tried, accepted = kernels.smooth_steering(
            self.ctrl, self.pos, self.d1, self.d2, self.kappa, self.slack, self.station,
            kernel_ints(self.first), kernel_floats(self.basis),
            self.lo.astype(np.int64), self.hi.astype(np.int64), kernel_ints(self.cand),
            self.movable, self.k, p.wheelbase, p.max_steering_rate, p.mu * p.g, p.s_max,
            min(max(float(self.kappa.max(initial=0.0)), p.kappa_smax), p.kappa_max),
            p.a_max, p.b_max,
            float(start_speed), min(p.max_iterations, SMOOTH_MOVES * len(self.ctrl)),
            kernel_floats(self.floor), self.checker.slack_args())
        log.debug("steering smoothing: %d tried, %d accepted", tried, accepted)
        return int(tried), int(accepted)

    def ease_bends(self, rounds: int, target: float) -> int:
        """Where the curve still turns beyond the turning limit after equation (3)'s
        single-point moves, move the control points that shape those samples together:
        the smallest moves (least squares) that bring the curvature to ``target`` of the
        limit while no sample's footprint comes closer to the
        road's edges or the obstacles than the margins allow (nor closer than it was,
        where it already did). SLSQP, at most ``rounds`` iterations, on the control points
        within :data:`BEND_REACH` of those samples' own. The curve gives up separation
        only to become drivable, as the paper lets smoothing do for speed. Kept if the
        bend gets gentler and no footprint worse (the whole move, else half or a quarter
        of it). Returns the iterations taken (0: nothing to do or nothing kept)."""
        p = self.params
        bad = np.flatnonzero(self.kappa > p.kappa_max)
        if rounds <= 0 or len(bad) == 0:
            return 0
        n, k = len(self.ctrl), self.k
        near = np.zeros(n, dtype=bool)
        for f in np.unique(self.first[bad]):
            near[max(int(f) - BEND_REACH, 0):int(f) + k + 1 + BEND_REACH] = True
        # copies of a doubled control point move together (apart, they would make a short
        # leg, a curvature spike), and only if all of them may move
        group = self.pool_index
        held = np.unique(group[~self.movable])
        touched = np.setdiff1d(np.unique(group[near]), held)
        pts = np.flatnonzero(np.isin(group, touched))
        if len(pts) == 0:
            return 0
        a, b = int(self.lo[pts].min()), int(self.hi[pts].max())
        prob = _BendProblem(self, pts, a, b, target * p.kappa_max)
        f0, g0 = prob.objective(np.zeros(prob.size))
        if not (np.isfinite(f0) and np.all(np.isfinite(g0))
                and np.all(np.isfinite(prob.room(np.zeros(prob.size))))):
            return 0  # a cusp (zero speed along the curve): nothing to ease smoothly
        from scipy.optimize import minimize

        res = minimize(prob.objective, np.zeros(prob.size), jac=True, method="SLSQP",
                       constraints=[{"type": "ineq", "fun": prob.room,
                                     "jac": prob.room_jacobian}],
                       bounds=[(-BEND_MOVE, BEND_MOVE)] * prob.size,
                       options={"maxiter": rounds, "ftol": 1e-4})
        before = float(self.kappa[a:b].max())
        for scale in (1.0, 0.5, 0.25):
            x = res.x * scale
            kappa, slack, pos, d1, d2 = prob.evaluate(x)
            if (float(np.abs(kappa).max()) < before
                    and not np.any(slack < prob.floor - 1e-6)):
                break
        else:
            log.debug("bend easing: %d iterations, nothing kept", res.nit)
            return 0
        self.ctrl[:] = prob.moved(x)
        self.pos[a:b], self.d1[a:b], self.d2[a:b], self.slack[a:b] = pos, d1, d2, slack
        self.kappa[a:b] = np.abs(kappa)
        log.debug("bend easing: %d iterations, curvature %.3f -> %.3f 1/m", res.nit, before,
                  float(self.kappa[a:b].max()))
        return int(res.nit)


class _BendProblem:
    """:meth:`_Optimiser.ease_bends`' problem: sideways moves ``x`` of the control points
    ``pts`` (one per group of copies, across the control polygon there) and the samples
    ``[a, b)`` they shape."""

    def __init__(self, opt: _Optimiser, pts: NDArray[np.int64], a: int, b: int,
                 target: float) -> None:
        self.opt, self.pts, self.target = opt, pts, target
        self.first = opt.first[a:b]
        self.basis = np.ascontiguousarray(opt.basis[:, :, a:b])
        self.station = opt.station[a:b]
        self.floor = np.minimum(opt.slack[a:b], 0.0)  # no footprint gets worse
        self.ctrl = kernel_floats(opt.ctrl)
        n, k = len(opt.ctrl), opt.k
        groups, self.var_of_pt = np.unique(opt.pool_index[pts], return_inverse=True)
        self.size = len(groups)
        # across the polygon: normal to the chord between the neighbours of each group
        ends = np.searchsorted(opt.pool_index, groups, side="right")
        starts = np.searchsorted(opt.pool_index, groups, side="left")
        chord = (self.ctrl[np.minimum(ends, n - 1)]
                 - self.ctrl[np.maximum(starts - 1, 0)])
        unit = chord / np.maximum(np.hypot(chord[:, 0], chord[:, 1]), 1e-12)[:, None]
        self.normal = np.column_stack((-unit[:, 1], unit[:, 0]))[self.var_of_pt]  # per pt
        var = np.full(n, -1)
        var[pts] = self.var_of_pt
        # each (sample, slot) shaped by a moved point: its variable and the change of the
        # sample's position and derivatives per unit of that variable
        jj, rr = np.nonzero(var[self.first[:, None] + np.arange(k + 1)[None, :]] >= 0)
        cc = self.first[jj] + rr
        nrm = np.zeros((n, 2))
        nrm[pts] = self.normal
        self.jj, self.gg = jj, var[cc]
        self.dd = [self.basis[nu, rr, jj][:, None] * nrm[cc] for nu in range(3)]
        # the same summed per (sample, variable), for the footprint's finite differences
        key = jj * self.size + self.gg
        uniq, inv = np.unique(key, return_inverse=True)
        self.rows, self.owner = uniq // self.size, uniq % self.size
        self.dp, self.dq = np.zeros((len(uniq), 2)), np.zeros((len(uniq), 2))
        np.add.at(self.dp, inv, self.dd[0])
        np.add.at(self.dq, inv, self.dd[1])
        self._key: bytes | None = None
        self._value: tuple[FloatArray, ...] = ()

    def moved(self, x: FloatArray) -> FloatArray:
        """All control points, those in ``pts`` moved by ``x``."""
        ctrl = self.ctrl.copy()
        ctrl[self.pts] += x[self.var_of_pt, None] * self.normal
        return ctrl

    def evaluate(self, x: FloatArray) -> tuple[FloatArray, ...]:
        """Signed curvature, footprint slack, positions and derivatives at the samples."""
        key = x.tobytes()
        if key != self._key:
            pos, d1, d2 = _evaluate_kernel(self.moved(x), self.first, self.basis, self.opt.k)
            kappa = curvature_from_derivatives(d1, d2)
            slack, _ = self.opt.checker.slack(pos, np.arctan2(d1[:, 1], d1[:, 0]),
                                              self.station)
            self._key, self._value = key, (kappa, slack, pos, d1, d2)
        return self._value

    def objective(self, x: FloatArray) -> tuple[float, FloatArray]:
        """The squared curvature beyond the target plus the squared moves, each in its
        unit (:data:`_BEND_KAPPA_UNIT`, :data:`_BEND_MOVE_UNIT`), and its gradient (the
        curvature's derivatives in closed form)."""
        kappa, _, _, d1, d2 = self.evaluate(x)
        # a sample where the curve stops (its control points meet) bends without limit:
        # as sharply as the largest finite curvature, so that the moves stay numbers
        kappa = np.clip(kappa, -_BEND_KAPPA_CAP, _BEND_KAPPA_CAP)
        over = np.maximum(np.abs(kappa) - self.target, 0.0) / _BEND_KAPPA_UNIT
        sp2 = np.maximum((d1 * d1).sum(axis=1), 1e-12)
        sp3 = sp2 ** 1.5
        w = (2.0 * over * np.sign(kappa) / _BEND_KAPPA_UNIT)[self.jj]
        j = self.jj
        # d kappa / d (x', y', x'', y'') at each (sample, slot), times the slot's change
        dk = ((d2[j, 1] / sp3[j] - 3.0 * kappa[j] * d1[j, 0] / sp2[j]) * self.dd[1][:, 0]
              + (-d2[j, 0] / sp3[j] - 3.0 * kappa[j] * d1[j, 1] / sp2[j]) * self.dd[1][:, 1]
              - d1[j, 1] / sp3[j] * self.dd[2][:, 0] + d1[j, 0] / sp3[j] * self.dd[2][:, 1])
        grad = np.bincount(self.gg, w * dk, self.size) + 2.0 * x / _BEND_MOVE_UNIT**2
        return float(over @ over) + float(x @ x) / _BEND_MOVE_UNIT**2, grad

    def room(self, x: FloatArray) -> FloatArray:
        """The constraint: each sample's footprint slack above its floor (>= 0)."""
        return np.asarray(self.evaluate(x)[1] - self.floor)

    def room_jacobian(self, x: FloatArray) -> FloatArray:
        """:meth:`room`'s derivatives by finite differences, each move's over the samples
        it shapes only (one footprint check in all)."""
        _, slack, pos, d1, _ = self.evaluate(x)
        rows = self.rows
        p = pos[rows] + _BEND_EPS * self.dp
        q = d1[rows] + _BEND_EPS * self.dq
        moved, _ = self.opt.checker.slack(p, np.arctan2(q[:, 1], q[:, 0]), self.station[rows])
        jac = np.zeros((len(slack), self.size))
        jac[rows, self.owner] = (moved - slack[rows]) / _BEND_EPS
        return jac


#: Units of :class:`_BendProblem`'s objective: curvature beyond the target [1/m] in
#: 0.01 1/m, moves [m] in 10 m, so that 0.001 1/m beyond it weighs as much as a move of
#: 1 m (a penalty: the curvature ends within about that of the target). The scale also
#: sets how SLSQP's merit function weighs the footprint's constraints; this one (and the
#: objective 100 times larger or smaller) measured best.
_BEND_KAPPA_UNIT = 0.01
_BEND_MOVE_UNIT = 10.0
#: Curvature [1/m] that the bends' easing takes for a sample where the curve stops.
_BEND_KAPPA_CAP = 1e3
