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
