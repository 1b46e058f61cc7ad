"""Curvature of plane curves: from derivatives, and the paper's discrete equation (2).

Shared by the optimiser (:mod:`splineplan.optimiser`) and the trajectory's samples
(:mod:`splineplan.trajectory`, which re-exports both functions).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from splineplan.errors import TrajectoryError
from splineplan.geometry import FloatArray


def curvature_from_derivatives(d1: ArrayLike, d2: ArrayLike) -> FloatArray:
    """Signed curvature [1/m] ``(x'y'' - y'x'') / (x'^2 + y'^2)^(3/2)`` from ``(n, 2)`` derivatives.

    Positive when the curve turns left; its absolute value is the paper's curvature.
    """
    a = np.asarray(d1, dtype=float)
    b = np.asarray(d2, dtype=float)
    cross = a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]
    speed2 = np.einsum("...i,...i->...", a, a)
    with np.errstate(divide="ignore", invalid="ignore"):
        k = cross / speed2**1.5
    return np.asarray(np.where(speed2 > 0, k, np.inf))


def curvature_discrete(points: ArrayLike, h: float) -> FloatArray:
    """Equation (2): ``|S(t+delta) + S(t-delta) - 2 S(t)| / h^2`` [1/m].

    ``points`` ``(n, 2)`` [m] are spaced ``h`` [m] apart in arc length. The two end points,
    which lack a neighbour, copy their neighbour's value.
    """
    p = np.asarray(points, dtype=float)
    if len(p) < 3:
        raise TrajectoryError("discrete curvature needs at least 3 points")
    cu = np.hypot(*(p[2:] + p[:-2] - 2.0 * p[1:-1]).T) / h**2
    return np.concatenate(([cu[0]], cu, [cu[-1]]))
