"""The optimiser's compiled pieces against independent references."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.interpolate import BSpline

from splineplan.kernels import independent_moves
from splineplan.optimiser import _Curve


@pytest.mark.parametrize("degree", [1, 2, 3, 4, 5])
def test_cached_basis_evaluates_like_scipy(degree: int) -> None:
    rng = np.random.default_rng(degree)
    ctrl = np.cumsum(rng.uniform(0.5, 3.0, size=(12, 2)), axis=0)
    curve = _Curve.build(ctrl, np.arange(12), degree, 0.2)
    spline = BSpline(curve.knots, ctrl, curve.k)
    for nu, got in enumerate(curve.evaluate()):
        want = spline(curve.u, nu)
        # at u = 1 the cached basis takes the left limit, as scipy does
        np.testing.assert_allclose(got, want, rtol=1e-9, atol=1e-9 * np.abs(want).max())
    # each sample's k + 1 basis values sum to one
    np.testing.assert_allclose(curve.basis[0].sum(axis=0), 1.0, atol=1e-12)


@settings(max_examples=60, deadline=None)
@given(st.lists(st.floats(0.0, 5.0), min_size=1, max_size=40), st.integers(1, 4),
       st.integers(1, 50))
def test_independent_moves_are_worst_first_and_apart(bad_list: list[float], k: int,
                                                     budget: int) -> None:
    bad = np.asarray(bad_list)
    chosen = independent_moves(bad, k, budget)
    assert len(chosen) <= budget
    assert np.all(bad[chosen] > 0)
    # supports of control points more than k apart do not overlap
    taken = sorted(chosen.tolist())
    assert all(b - a > k for a, b in itertools.pairwise(taken))
    # greedy: every positive point left out is within k of a chosen one that is at least
    # as bad, unless the budget ran out
    if len(chosen) < budget:
        for i in np.flatnonzero(bad > 0):
            if i not in chosen:
                near = chosen[np.abs(chosen - i) <= k]
                assert len(near) and bad[near].max() >= bad[i]


def test_basis_at_unsorted_parameters_matches_scipy() -> None:
    """The basis walks from one sample's knot span to the next: parameters in any order
    (and the ends, 0 and 1) still get their own spans."""
    from splineplan.optimiser import _basis, _knots

    rng = np.random.default_rng(7)
    n, k = 9, 3
    ctrl = rng.normal(size=(n, 2))
    t = _knots(n, k)
    u = np.concatenate((rng.uniform(0, 1, 50), [1.0, 0.0, 0.5, 1.0]))
    first, vals = _basis(u, t, k, n)
    spline = BSpline(t, ctrl, k)
    cols = first + np.arange(k + 1)[:, None]
    for nu in range(3):
        got = np.stack([(vals[nu] * ctrl[:, d][cols]).sum(axis=0) for d in range(2)], axis=1)
        np.testing.assert_allclose(got, spline(u, nu), rtol=1e-9, atol=1e-9)


def test_bend_easing_derivatives_match_finite_differences(monkeypatch: pytest.MonkeyPatch
                                                          ) -> None:
    """The bends' easing on a real turn (city D0E0 -> E0SE, whose curve equation (3) leaves
    beyond the turning limit): its objective's gradient in closed form and its
    constraints' finite-difference Jacobian agree with central differences, at random
    small moves of the control points; and the moves it keeps are sideways, the same for
    copies of a control point."""
    from pathlib import Path

    from benchmarks.turns import TurnBuilder
    from splineplan import optimiser
    from splineplan.network import load_network
    from splineplan.pipeline import plan

    seen: list[optimiser._BendProblem] = []
    init = optimiser._BendProblem.__init__

    def spy(self: optimiser._BendProblem, *args: object, **kwargs: object) -> None:
        init(self, *args, **kwargs)  # type: ignore[arg-type]
        seen.append(self)

    monkeypatch.setattr(optimiser._BendProblem, "__init__", spy)
    path = Path(__file__).resolve().parents[1] / "sumo_nets" / "city.net.xml"
    net, turn = load_network(path), TurnBuilder(path).turn("D0E0", "E0SE")
    tr = plan(net, "D0E0", "E0SE", start_pos=turn.start_pos, start_xy=turn.start[:2],
              start_heading=turn.start[2], end_pos=turn.end_pos).trajectory
    assert tr.feasible and seen
    rng = np.random.default_rng(0)
    for prob in seen:
        # each moved point moves along a unit normal, copies (equal pool index) alike
        np.testing.assert_allclose(np.hypot(*prob.normal.T), 1.0, atol=1e-9)
        x = rng.normal(0.0, 0.05, prob.size)
        _, grad = prob.objective(x)
        h = 1e-6
        num = np.array([(prob.objective(x + h * e)[0] - prob.objective(x - h * e)[0])
                        / (2 * h) for e in np.eye(prob.size)])
        np.testing.assert_allclose(grad, num, rtol=1e-4, atol=1e-6 * np.abs(num).max())
        jac = prob.room_jacobian(x)
        h = 1e-5
        num = np.column_stack([(prob.room(x + h * e) - prob.room(x - h * e)) / (2 * h)
                               for e in np.eye(prob.size)])
        # the footprint's slack is piecewise smooth (its nearest corner can switch)
        close = np.isclose(jac, num, rtol=1e-2, atol=1e-3)
        assert close.mean() > 0.99
        moved = prob.moved(x) - prob.ctrl
        np.testing.assert_allclose(np.delete(moved, prob.pts, axis=0), 0.0)
        group = prob.opt.pool_index[prob.pts]
        for g in np.unique(group):
            rows = moved[prob.pts[group == g]]
            np.testing.assert_allclose(rows, rows[:1].repeat(len(rows), axis=0))
