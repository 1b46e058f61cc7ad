"""Metrics of a driven trajectory: footprint distances, accelerations, jerk, summaries.

Pure functions on numpy arrays, no SUMO: the closed loop (:mod:`splineplan.sim`) records
poses and calls these.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from splineplan.geometry import FloatArray, box_corners, point_segment_distance


def footprint(center: ArrayLike, heading: float, length: float, width: float) -> FloatArray:
    """Corners ``(4, 2)`` [m] of a vehicle's rectangle from its centre and heading [rad]."""
    c = np.asarray(center, dtype=float).reshape(1, 2)
    return np.asarray(box_corners(c, np.array([heading]), np.array([length]),
                                  np.array([width]))[0])


def footprints(
    fronts: ArrayLike, headings: ArrayLike, lengths: ArrayLike, widths: ArrayLike
) -> FloatArray:
    """Corners ``(k, 4, 2)`` [m] of rectangles given by front-bumper middles ``(k, 2)``.

    SUMO's position of a vehicle is the middle of its front bumper; headings [rad] are
    counter-clockwise from east.
    """
    f = np.asarray(fronts, dtype=float).reshape(-1, 2)
    h = np.asarray(headings, dtype=float).reshape(-1)
    ln = np.asarray(lengths, dtype=float).reshape(-1)
    w = np.asarray(widths, dtype=float).reshape(-1)
    centers = f - (ln / 2.0)[:, None] * np.column_stack((np.cos(h), np.sin(h)))
    return np.asarray(box_corners(centers, h, ln, w))


def box_distances(box: ArrayLike, others: ArrayLike) -> FloatArray:
    """Distance [m] between a convex quadrilateral ``(4, 2)`` and each of ``(k, 4, 2)``.

    Zero where they touch or overlap (also when edges cross with no corner inside the
    other box, or when one box contains the other).
    """
    a = np.asarray(box, dtype=float).reshape(4, 2)
    b = np.asarray(others, dtype=float).reshape(-1, 4, 2)
    k = len(b)
    if k == 0:
        return np.zeros(0)
    a1 = np.roll(a, -1, axis=0)
    b1 = np.roll(b, -1, axis=1)
    # corners of a to edges of b, and corners of b to edges of a: (k, 4, 4)
    d_ab = point_segment_distance(a[None, :, None, :], b[:, None, :, :], b1[:, None, :, :])
    d_ba = point_segment_distance(b[:, :, None, :], a[None, None, :, :], a1[None, None, :, :])
    dist = np.minimum(d_ab.reshape(k, -1).min(axis=1), d_ba.reshape(k, -1).min(axis=1))
    # proper crossings of an edge of a with an edge of b
    p, p1 = a[None, :, None, :], a1[None, :, None, :]
    q, q1 = b[:, None, :, :], b1[:, None, :, :]
    o1 = _cross(p, p1, q)
    o2 = _cross(p, p1, q1)
    o3 = _cross(q, q1, p)
    o4 = _cross(q, q1, p1)
    crossing = ((o1 * o2 < 0) & (o3 * o4 < 0)).reshape(k, -1).any(axis=1)
    inside = _convex_contains(b, a).any(axis=1) | _convex_contains_one(a, b).any(axis=1)
    dist[crossing | inside] = 0.0
    return np.asarray(dist)


def rectangle_distances(
    center: ArrayLike, heading: float, length: float, width: float,
    centers: ArrayLike, headings: ArrayLike, lengths: ArrayLike, widths: ArrayLike,
) -> FloatArray:
    """Distance [m] between one rectangle and each of ``k`` others, from centres and headings.

    The same as :func:`box_distances` on their corners (zero where they touch or overlap),
    computed in each rectangle's own frame: the rectangles overlap unless one of the four
    axes separates them; otherwise the distance is that of the nearest corner of one to the
    other rectangle. ``center`` ``(2,)`` [m], ``heading`` [rad]; ``centers`` ``(k, 2)``,
    ``headings``, ``lengths``, ``widths`` ``(k,)``. Returns ``(k,)``.
    """
    c = np.asarray(centers, dtype=float).reshape(-1, 2)
    if not len(c):
        return np.zeros(0)
    h = np.asarray(headings, dtype=float).reshape(-1, 1)
    hl = 0.5 * np.asarray(lengths, dtype=float).reshape(-1, 1)
    hw = 0.5 * np.asarray(widths, dtype=float).reshape(-1, 1)
    x0, y0 = (float(v) for v in np.asarray(center, dtype=float).reshape(2))
    ca, sa = math.cos(heading), math.sin(heading)
    ha, wa = 0.5 * length, 0.5 * width
    cos, sin = np.cos(h), np.sin(h)
    # the others' corners, relative to this rectangle's centre: (k, 4)
    fx, fy, lx, ly = cos * hl, sin * hl, -sin * hw, cos * hw
    sx = np.array([-1.0, 1.0, 1.0, -1.0])
    sy = np.array([-1.0, -1.0, 1.0, 1.0])
    bx = (c[:, :1] - x0) + sx * fx + sy * lx
    by = (c[:, 1:] - y0) + sx * fy + sy * ly
    px = bx * ca + by * sa  # in this rectangle's frame
    py = by * ca - bx * sa
    # this rectangle's corners relative to each other's centre, in its frame: (k, 4)
    ax = (x0 - c[:, :1]) + sx * (ca * ha) - sy * (sa * wa)
    ay = (y0 - c[:, 1:]) + sx * (sa * ha) + sy * (ca * wa)
    qx = ax * cos + ay * sin
    qy = ay * cos - ax * sin
    apart = ((px.min(axis=1) > ha) | (px.max(axis=1) < -ha) | (py.min(axis=1) > wa)
             | (py.max(axis=1) < -wa) | (qx.min(axis=1) > hl[:, 0])
             | (qx.max(axis=1) < -hl[:, 0]) | (qy.min(axis=1) > hw[:, 0])
             | (qy.max(axis=1) < -hw[:, 0]))
    d_b = np.hypot(np.maximum(np.abs(px) - ha, 0.0), np.maximum(np.abs(py) - wa, 0.0))
    d_a = np.hypot(np.maximum(np.abs(qx) - hl, 0.0), np.maximum(np.abs(qy) - hw, 0.0))
    dist = np.minimum(d_b.min(axis=1), d_a.min(axis=1))
    return np.asarray(np.where(apart, dist, 0.0))


def _cross(o: FloatArray, a: FloatArray, b: FloatArray) -> FloatArray:
    return np.asarray((a[..., 0] - o[..., 0]) * (b[..., 1] - o[..., 1])
                      - (a[..., 1] - o[..., 1]) * (b[..., 0] - o[..., 0]))


def _convex_contains(polys: FloatArray, pts: FloatArray) -> np.ndarray:
    """Whether each of ``pts (m, 2)`` lies inside each convex ``polys (k, 4, 2)``: ``(k, m)``."""
    e0 = polys[:, None, :, :]
    e1 = np.roll(polys, -1, axis=1)[:, None, :, :]
    c = _cross(e0, e1, pts[None, :, None, :])
    return np.asarray((c > 0).all(axis=2) | (c < 0).all(axis=2))


def _convex_contains_one(poly: FloatArray, pts: FloatArray) -> np.ndarray:
    """Whether each corner of ``pts (k, 4, 2)`` lies inside the convex ``poly (4, 2)``."""
    k = len(pts)
    inside = _convex_contains(poly[None], pts.reshape(-1, 2))[0]
    return np.asarray(inside.reshape(k, 4))


#: Default span [m] of the second difference that gives the driven path's curvature.
CURVATURE_SPAN = 2.0


def path_curvature(x: ArrayLike, y: ArrayLike, *, span: float = CURVATURE_SPAN) -> FloatArray:
    """Signed curvature [1/m] of a driven path at each of its samples, from positions only.

    At sample ``i`` (arc length ``s_i``), the circle through three driven samples: ``i``, the
    last one at least ``span`` [m] of path before it and the first one at least ``span``
    after it; ``kappa = 4 A / (a b c)`` (Menger curvature: ``A`` the triangle's area, ``a, b,
    c`` its sides), positive for left turns. The points are the samples themselves (no
    interpolation), so a path along a circle gives exactly ``1/R``. Samples within ``span``
    of either end take the value of the nearest sample that has both neighbours.

    ``x``, ``y``: ``(n,)`` [m]. Returns ``(n,)``; zeros for a path shorter than ``2 span``.
    """
    xs = np.asarray(x, dtype=float)
    ys = np.asarray(y, dtype=float)
    n = len(xs)
    if n < 3:
        return np.zeros(n)
    s = np.concatenate(([0.0], np.cumsum(np.hypot(np.diff(xs), np.diff(ys)))))
    h = float(span)
    lo = np.searchsorted(s, s - h, side="right") - 1  # last sample at least h before
    hi = np.searchsorted(s, s + h, side="left")  # first sample at least h after
    valid = np.flatnonzero((lo >= 0) & (hi < n))
    if not len(valid):
        return np.zeros(n)
    i, j, k = valid, lo[valid], hi[valid]
    ax, ay = xs[i] - xs[j], ys[i] - ys[j]
    bx, by = xs[k] - xs[i], ys[k] - ys[i]
    cross = ax * by - ay * bx  # twice the signed area
    sides = np.hypot(ax, ay) * np.hypot(bx, by) * np.hypot(xs[k] - xs[j], ys[k] - ys[j])
    kv = 2.0 * cross / np.where(sides > 0, sides, 1.0)
    return np.asarray(np.interp(np.arange(n), valid, kv))


def dynamics(
    t: ArrayLike, x: ArrayLike, y: ArrayLike, speed: ArrayLike, *,
    span: float = CURVATURE_SPAN,
) -> dict[str, FloatArray]:
    """Curvature, accelerations and jerk of a driven path, from its samples.

    ``t`` ``(n,)`` [s], ``x``, ``y`` ``(n,)`` [m] (the vehicle's centre), ``speed`` ``(n,)``
    [m/s]. Lateral acceleration [m/s^2] is ``v^2 * kappa`` with ``kappa`` from
    :func:`path_curvature` (positions only, over ``span`` [m] of path either side:
    independent of the headings the vehicle reported). Longitudinal acceleration is
    ``dv/dt`` and jerk [m/s^3] is the rate of change of ``(a_lon, a_lat)``, both by
    central differences in time (``numpy.gradient``).
    """
    tt = np.asarray(t, dtype=float)
    v = np.asarray(speed, dtype=float)
    if len(tt) < 3 or np.any(np.diff(tt) <= 0):
        z = np.zeros(len(tt))
        return {"curvature": z, "a_lon": z, "a_lat": z, "jerk": z}
    kappa = path_curvature(x, y, span=span)
    a_lat = v * v * kappa
    a_lon = np.gradient(v, tt)
    jerk = np.hypot(np.gradient(a_lon, tt), np.gradient(a_lat, tt))
    return {"curvature": kappa, "a_lon": a_lon, "a_lat": a_lat, "jerk": jerk}


def summary_stats(values: ArrayLike) -> dict[str, Any]:
    """Count, median and maximum of a sample (``None`` where empty)."""
    x = np.asarray(values, dtype=float)
    if len(x) == 0:
        return {"count": 0, "median": None, "max": None}
    return {"count": len(x), "median": float(np.median(x)), "max": float(np.max(x))}


def finite_or_none(value: float) -> float | None:
    """A float for JSON: ``None`` for infinities and NaN."""
    return float(value) if np.isfinite(value) else None
