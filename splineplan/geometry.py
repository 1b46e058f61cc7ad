"""Vectorised planar geometry shared by the planning levels.

Pure functions on numpy arrays; points are ``(n, 2)`` arrays of x, y [m]. Headings are in
radians, counter-clockwise from east (the planner's convention); SUMO's angles are degrees
clockwise from north and are converted only here.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

FloatArray = NDArray[np.float64]


def kernel_floats(a: ArrayLike) -> FloatArray:
    """``a`` as the compiled loops take float arrays: float64, C-contiguous, writeable (a
    copy where it is not). A read-only or strided array would make numba compile another
    specialisation of the loop, and the first run after an install would wait for it."""
    out = np.ascontiguousarray(a, dtype=np.float64)
    return out if out.flags.writeable else out.copy()


def kernel_ints(a: ArrayLike) -> NDArray[np.int64]:
    """``a`` as the compiled loops take integer arrays: int64, C-contiguous, writeable (see
    :func:`kernel_floats`)."""
    out = np.ascontiguousarray(a, dtype=np.int64)
    return out if out.flags.writeable else out.copy()


def heading_from_sumo_angle(angle_deg: ArrayLike) -> FloatArray:
    """Planner heading [rad] from SUMO's angle [deg, 0 = north, clockwise]."""
    return np.asarray(np.radians(90.0 - np.asarray(angle_deg, dtype=float)), dtype=float)


def sumo_angle_from_heading(heading: float) -> float:
    """SUMO's angle [deg, 0 = north, clockwise, in [0, 360)] from a heading [rad] (plain
    floats: it runs once a simulation step)."""
    return (90.0 - math.degrees(heading)) % 360.0


def wrap_angle(angle: ArrayLike) -> FloatArray:
    """Angle [rad] wrapped into [-pi, pi)."""
    return np.asarray(np.mod(np.asarray(angle, dtype=float) + np.pi, 2 * np.pi) - np.pi)


def polyline_stations(points: FloatArray) -> FloatArray:
    """Cumulative arc length [m] at each vertex of a polyline ``(n, 2)``, starting at 0."""
    seg = np.hypot(*np.diff(points, axis=0).T)
    return np.concatenate(([0.0], np.cumsum(seg)))


def resample_polyline(points: FloatArray, spacing: float) -> FloatArray:
    """Polyline resampled at equal arc-length steps of at most ``spacing`` [m].

    Keeps both end points; drops repeated vertices first.
    """
    pts = dedupe_polyline(points)
    s = polyline_stations(pts)
    n = max(int(np.ceil(s[-1] / spacing)), 1) + 1
    t = np.linspace(0.0, s[-1], n)
    return np.column_stack((np.interp(t, s, pts[:, 0]), np.interp(t, s, pts[:, 1])))


def dedupe_polyline(points: FloatArray, tol: float = 1e-9) -> FloatArray:
    """Polyline without consecutive vertices closer than ``tol`` [m]."""
    pts = np.asarray(points, dtype=float)
    if len(pts) < 2:
        return pts
    keep = np.concatenate(([True], np.hypot(*np.diff(pts, axis=0).T) > tol))
    return pts[keep]


def point_segment_distance(points: FloatArray, a: FloatArray, b: FloatArray) -> FloatArray:
    """Distance [m] from points ``(..., 2)`` to segments ``a -> b`` (broadcast)."""
    ab = b - a
    ap = points - a
    denom = np.einsum("...i,...i->...", ab, ab)
    t = np.einsum("...i,...i->...", ap, ab) / np.where(denom > 0, denom, 1.0)
    t = np.clip(t, 0.0, 1.0)
    closest = a + t[..., None] * ab
    return np.asarray(np.hypot(*(points - closest).T).T)


def polygon_edges(vertices: FloatArray, offsets: NDArray[np.int64]) -> tuple[
    FloatArray, FloatArray, NDArray[np.int64]
]:
    """Edges of polygons stored as concatenated vertices and offsets.

    Returns the start points ``(e, 2)``, end points ``(e, 2)`` and, for each edge, the index
    of its polygon ``(e,)``. Each ring is closed implicitly.
    """
    counts = np.diff(offsets)
    owner = np.repeat(np.arange(len(counts)), counts)
    nxt = np.arange(len(vertices)) + 1
    last = offsets[1:] - 1
    nxt[last] = offsets[:-1]
    return vertices, vertices[nxt], owner


def points_in_polygons(
    points: FloatArray, vertices: FloatArray, offsets: NDArray[np.int64]
) -> NDArray[np.bool_]:
    """Whether each point ``(p, 2)`` lies inside each polygon: ``(p, k)`` booleans.

    Even-odd rule on the polygons' rings (crossing number).
    """
    a, b, owner = polygon_edges(vertices, offsets)
    px = points[:, None, 0]
    py = points[:, None, 1]
    ay, by = a[None, :, 1], b[None, :, 1]
    ax, bx = a[None, :, 0], b[None, :, 0]
    straddle = (ay > py) != (by > py)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        xcross = ax + (py - ay) * (bx - ax) / (by - ay)
    hit = straddle & (px < xcross)
    k = len(offsets) - 1
    counts = np.zeros((len(points), k), dtype=np.int64)
    for j in range(k):  # k is small; the edge dimension is vectorised
        counts[:, j] = hit[:, owner == j].sum(axis=1)
    return counts % 2 == 1


def distance_to_polygons(
    points: FloatArray, vertices: FloatArray, offsets: NDArray[np.int64]
) -> FloatArray:
    """Distance [m] from each point ``(p, 2)`` to each polygon, 0 inside: ``(p, k)``."""
    k = len(offsets) - 1
    if k == 0 or len(points) == 0:
        return np.full((len(points), k), np.inf)
    a, b, owner = polygon_edges(vertices, offsets)
    d_edges = point_segment_distance(points[:, None, :], a[None], b[None])
    out = np.full((len(points), k), np.inf)
    for j in range(k):
        out[:, j] = d_edges[:, owner == j].min(axis=1)
    out[points_in_polygons(points, vertices, offsets)] = 0.0
    return out


def box_corners(
    centers: FloatArray, headings: FloatArray, lengths: FloatArray, widths: FloatArray
) -> FloatArray:
    """Corners ``(k, 4, 2)`` of oriented rectangles, counter-clockwise from rear right."""
    c, s = np.cos(headings), np.sin(headings)
    hl, hw = np.asarray(lengths) / 2.0, np.asarray(widths) / 2.0
    fx, fy = c * hl, s * hl  # half-length along the heading
    lx, ly = -s * hw, c * hw  # half-width to the left
    cx, cy = centers[:, 0], centers[:, 1]
    corners = np.stack(
        [
            np.column_stack((cx - fx - lx, cy - fy - ly)),
            np.column_stack((cx + fx - lx, cy + fy - ly)),
            np.column_stack((cx + fx + lx, cy + fy + ly)),
            np.column_stack((cx - fx + lx, cy - fy + ly)),
        ],
        axis=1,
    )
    return np.asarray(corners)
