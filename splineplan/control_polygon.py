"""Level 3's first control polygon, from level 2's roadmap (steps 1, 2 and 8 of
:mod:`splineplan.trajectory`).

Band simplification (:func:`band_simplify`) keeps the roadmap vertices that string pulling
through lateral bands of the free intervals needs; at junction turns the vertices first move
within their bands to the polygon of least bending, reweighted so that it spreads its turn
(:func:`min_turning_offsets`), and long legs are split in gradually growing pieces; the
vehicle's position and a heading point lead in. Where the curve along level 2's path
cannot be made feasible, :func:`detour_roadmap` searches the same graph for a path of
limited lateral rate. Pure geometry on the roadmap and the corridor: no spline and no
footprint here.

The string pulling, the least-bending active-set loops, the leg splits and the detour's
dynamic programme are loops compiled with numba (cached on disk after the first run): as
array code they spent most of their time in the overhead of many small numpy calls.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from numba import njit
from numpy.typing import ArrayLike, NDArray

from splineplan.corridor import Corridor
from splineplan.errors import TrajectoryError
from splineplan.geometry import FloatArray, kernel_floats, polyline_stations
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


@dataclass(frozen=True, eq=False)
class VertexFrame:
    """What :func:`_control_points` needs of the roadmap and the corridor whichever its
    polygon (:func:`vertex_frame`)."""

    start: FloatArray  #: (2,) the vehicle's position [m]
    pts: FloatArray  #: (m, 2) the distinct roadmap vertices at their bands' centres [m]
    s0: float  #: the start's station [m]
    vs: FloatArray  #: (m,) the vertices' stations [m]
    lines: tuple[FloatArray, ...]  #: the vertices' :func:`_vertex_lines`
    free: FloatArray  #: (m, 2) the vertices' :func:`_free_intervals` [m]


def vertex_frame(roadmap: Roadmap, corridor: Corridor, params: TrajectoryParams
                 ) -> VertexFrame:
    """The roadmap's vertices in the corridor's frame, with their sweep lines and bands.

    Raises
    ------
    TrajectoryError
        Fewer than two distinct roadmap points, a start off the road, or a roadmap that
        ends at or behind the start.
    """
    raw = np.asarray(roadmap.xy, dtype=float)
    if raw.ndim != 2 or raw.shape[1] != 2 or len(raw) < 2:
        raise TrajectoryError(f"a trajectory needs at least 2 roadmap points, got {len(raw)}")
    distinct = np.concatenate(([True], np.hypot(*np.diff(raw, axis=0).T) > 1e-6))
    pts = raw[distinct]
    if len(pts) < 2:
        raise TrajectoryError(f"a trajectory needs at least 2 roadmap points, got {len(pts)}")
    start = np.asarray(roadmap.start_xy, dtype=float).reshape(2)
    sl = corridor.to_sl(np.vstack((start, pts)))
    # (the start on the road: :meth:`Corridor.contains` on its station and offset)
    right, left = corridor.bounds_at(sl[0, 0])
    if not (0.0 <= sl[0, 0] <= corridor.length and right <= sl[0, 1] <= left):
        raise TrajectoryError(
            f"start ({start[0]:.2f}, {start[1]:.2f}) is off the road "
            f"(station {corridor.offset + sl[0, 0]:.1f} m, lateral offset {sl[0, 1]:.2f} m)")
    s0, vs = float(sl[0, 0]), sl[1:, 0]
    if float(vs[-1] - s0) <= 1e-6:
        raise TrajectoryError("the roadmap ends at or behind the vehicle: no curve to follow")
    lines = _vertex_lines(roadmap, corridor, distinct, sl[1:], params.band_fraction,
                          params.band_reserve)
    # the control points stand at the bands' centres (the roadmap vertices, except where
    # the band reserve moved them off an interval's end)
    moved = np.abs(lines[3] - sl[1:, 1]) > 1e-9
    pts = pts.copy()
    pts[moved] = lines[0][moved] + lines[3][moved, None] * lines[2][moved]
    return VertexFrame(start, pts, s0, vs, lines, _free_intervals(roadmap, distinct, lines))


def _free_intervals(roadmap: Roadmap, distinct: NDArray[np.bool_],
                    lines: tuple[FloatArray, ...]) -> FloatArray:
    """Each distinct vertex's free interval ``(m, 2)`` [m] (lateral offsets), within level
    2's band where it has one (no nearer the obstacles than the vertex); the vertex's band
    of :func:`_vertex_lines` where the roadmap has no graph."""
    band = np.column_stack((lines[3] - lines[4], lines[3] + lines[4]))
    path = np.asarray(roadmap.path)
    if not (len(path) == len(distinct) and len(roadmap.graph_lo) and len(roadmap.graph_hi)):
        return band
    if len(roadmap.band_lo) == len(path):
        # the band (which may reach into the road margin beside an obstacle)
        lo = np.asarray(roadmap.band_lo, dtype=float)[distinct]
        hi = np.asarray(roadmap.band_hi, dtype=float)[distinct]
    else:
        lo = np.asarray(roadmap.graph_lo, dtype=float)[path][distinct]
        hi = np.asarray(roadmap.graph_hi, dtype=float)[path][distinct]
    # never narrower than the band (the band reserve may move a vertex off its interval)
    return np.column_stack((np.minimum(lo, band[:, 0]), np.maximum(hi, band[:, 1])))


def _control_points(roadmap: Roadmap, corridor: Corridor, start_heading: float | None,
                    params: TrajectoryParams, start_speed: float, smooth: bool = False,
                    frame: VertexFrame | None = None, keep_turns: bool = False,
                    free: bool = False) -> tuple[FloatArray, NDArray[np.int64]]:
    """Candidate control points ``(c, 2)`` and how often the first curve uses each (0 or 1).

    The candidates are the vehicle's position, a heading point ahead of it and the roadmap
    vertices beyond the heading point. The first curve uses the first two, the last, and the
    vertices that band simplification (:func:`band_simplify`) keeps, beginning at the
    farthest vertex that the vehicle's position reaches within the bands (at least the
    lead-in distance ahead).

    With ``smooth``, every vertex beyond a heading point one sweep line ahead first moves
    within its band to the polygon of least bending that spreads its turn
    (:func:`min_turning_offsets`), band simplification then drops those that stand in
    line, and long legs are split in pieces that grow gradually from the short legs
    beside them (:func:`_leg_splits`): the first curve then turns as gently as the bands
    allow, which a junction turn needs. With ``keep_turns`` too, band
    simplification keeps every vertex where that polygon turns (:data:`KEEP_TURN`): a long
    leg among short ones there bends the curve (its knots are uniform) beyond the polygon.
    With ``free`` too, the smooth polygon's bands widen to the vertices' free intervals
    (:func:`_free_intervals`), for a turn that the bands leave too little room.

    ``frame``: the roadmap's :func:`vertex_frame` (computed here if ``None``; both
    polygons of one roadmap share it).
    """
    rp = roadmap.params
    if frame is None:
        frame = vertex_frame(roadmap, corridor, params)
    if start_heading is not None and not np.isfinite(start_heading):
        raise TrajectoryError(f"start heading must be finite, got {start_heading!r}")
    start, pts, s0, vs, lines = frame.start, frame.pts, frame.s0, frame.vs, frame.lines
    intervals = frame.free
    reach = float(vs[-1] - s0)
    lead = max(params.lead_in_lengths * rp.vehicle_length, params.lead_in_time * start_speed)
    lead = min(lead, 0.5 * reach)
    head_len = max(min(lead / 2.0, reach / 3.0), 1e-3)
    if smooth:
        # the least-bending polygon takes the lateral offset gently by itself: the turn
        # may begin a sweep line ahead (a lane that bends just ahead of the vehicle)
        head_len = min(head_len, rp.d)
    ahead = vs > s0 + head_len + rp.d / 2.0
    ahead[-1] = True
    verts, vst = pts[ahead], vs[ahead]
    lines = tuple(a[ahead] for a in lines)
    intervals = intervals[ahead]
    first = 0 if smooth else int(np.searchsorted(vst, s0 + lead - 1e-9))
    first = min(first, len(verts) - 1)
    if not smooth:
        ends = _band_ends(verts, lines[0], lines[2], lines[3], lines[4])
        # from the vehicle's position as far as the bands allow
        cap = int(np.searchsorted(polyline_stations(verts), params.max_control_spacing
                                  - float(np.hypot(*(verts[0] - start))), side="right")) - 1
        if cap >= 0:
            first = max(first, _farthest_from(float(start[0]), float(start[1]), -1, cap, ends,
                                              lines[0], lines[1], _TOL))
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
        if free:
            # the bands widened to the free intervals (which keep the safety margin)
            lo_f = np.minimum(centre - half, intervals[first:, 0])
            hi_f = np.maximum(centre + half, intervals[first:, 1])
            centre = np.clip(centre, lo_f, hi_f)
            half = np.minimum(centre - lo_f, hi_f - centre)
        lo, hi = _lead_in_bands(centre - half, centre + half, start, origin, normal,
                                intervals[first:], vst[first:] - s0 < lead)
        lat = min_turning_offsets(
            np.vstack((start, heading_point, origin)), np.vstack((np.zeros((2, 2)), normal)),
            np.concatenate((fixed, lo)), np.concatenate((fixed, hi)),
            np.concatenate((fixed, centre)), SMOOTH_CENTRE_WEIGHT, params.kappa_max)[2:]
        verts = verts.copy()
        verts[first:] = origin + lat[:, None] * normal
        tol = np.minimum(half, SMOOTH_TOLERANCE)
        if keep_turns:
            tol = np.where(_turning(np.vstack((heading_point, verts[first:])),
                                    KEEP_TURN * params.kappa_max), 0.0, tol)
        ends = _band_ends(verts[first:], origin, normal, lat, tol)
    else:
        ends = ends[first:]
    kept = first + _simplify(ends, origin, tangent)
    # long legs get extra control points on them (they stay within the bands)
    legs_a = np.concatenate(([first], kept[:-1]))
    leg_len = np.hypot(*(verts[kept] - verts[legs_a]).T)
    f, leg = _leg_fractions(leg_len, legs_a == kept, params.max_control_spacing, LEG_GROWTH,
                            smooth)
    a, b = legs_a[leg], kept[leg]
    ex = verts[a] + f[:, None] * (verts[b] - verts[a])
    at = np.searchsorted(vst, vst[a] + f * (vst[b] - vst[a]), side="right")
    # the extra points go before the vertices at ``at`` (in their order where they share
    # one), behind the vehicle's position and the heading point
    order = np.argsort(at, kind="stable")
    new = 2 + at[order] + np.arange(len(at))
    old = np.ones(len(verts) + len(at) + 2, dtype=bool)
    old[:2] = False
    old[new] = False
    pool = np.empty((len(old), 2))
    pool[0], pool[1] = start, heading_point
    pool[old] = verts
    pool[new] = ex[order]
    counts = (~old).astype(np.int64)
    counts[np.flatnonzero(old)[kept]] = 1
    return pool, counts


def _lead_in_bands(lo: FloatArray, hi: FloatArray, start: FloatArray, origin: FloatArray,
                   normal: FloatArray, free: FloatArray, near: NDArray[np.bool_]
                   ) -> tuple[FloatArray, FloatArray]:
    """The bands ``lo``, ``hi`` ``(m,)`` [m] of the vertices, those within the lead-in
    (``near``) widened to the vehicle's own offset on their sweep lines, within their free
    intervals ``free`` ``(m, 2)``: the least-bending polygon then leaves the lateral
    position the vehicle has over the lead-in, as the first control polygon does, instead
    of swinging to level 2's path within a few metres (too sharp for the speed a closed
    loop replans at)."""
    if not np.any(near):
        return lo, hi
    own = np.clip(np.einsum("ij,ij->i", start[None, :] - origin, normal), free[:, 0], free[:, 1])
    return (np.where(near, np.minimum(lo, own), lo), np.where(near, np.maximum(hi, own), hi))


# ---- least bending ---------------------------------------------------------------------
def min_bending_offsets(origin: FloatArray, normal: FloatArray, lo: FloatArray,
                           hi: FloatArray, centre: FloatArray, weight: float,
                           max_rounds: int = 30, legs: FloatArray | None = None,
                           rows: FloatArray | None = None) -> FloatArray:
    """Lateral offsets ``(m,)`` [m] of the points ``origin + l * normal`` that minimise the
    sum of squared second differences of the points (the discrete bending of the polyline)
    plus ``weight`` times the squared distance of ``l`` to ``centre``, within ``lo <= l <=
    hi``.

    Equation (3) moves a point to its neighbours' mean, which drives exactly this sum down;
    this is its fixed point within the bands, found at once: the Hessian is banded
    (pentadiagonal, :func:`_bending_system`), solved by banded factorisation, first in a
    primal-dual active-set loop (fast, usually exact), then in a primal active-set loop
    that ends at the optimum (:func:`_min_bending_loops`).

    ``legs`` ``(m - 1,)`` [m]: the leg lengths that the second differences are scaled
    by (default: the origins' spacing); ``rows`` ``(m - 2,)``: a weight per second
    difference (default 1). :func:`min_turning_offsets` sets both.
    """
    m = len(origin)
    if m < 3:
        return np.clip(centre, lo, hi)
    f64 = (kernel_floats(a) for a in (origin, normal, centre, lo, hi))
    origin, normal, centre, lo, hi = f64
    legs = kernel_floats(np.hypot(*np.diff(origin, axis=0).T) if legs is None else legs)
    rows = kernel_floats(np.ones(m - 2) if rows is None else rows)
    h0, h1, h2, g = _bending_system(origin, normal, centre, float(weight), legs, rows)
    x, ok = _min_bending_loops(h0, h1, h2, g, lo, hi, int(max_rounds))
    if not ok:
        raise np.linalg.LinAlgError("the least-bending system is not positive definite")
    return x


#: Rounds of :func:`min_turning_offsets` (the first is the least-bending polygon).
TURN_ROUNDS = 10
#: Share of the turning limit above which the smooth polygon's vertices (and the two
#: after each) stay (:func:`_turning`).
KEEP_TURN = 0.3
#: Share of the turning limit above which :func:`min_turning_offsets` weights a turn up.
TURN_SHARE = 0.8
#: Power of the excess turn in :func:`min_turning_offsets`' weights.
TURN_POWER = 2.0
#: Largest weight of a turn in :func:`min_turning_offsets` (against 1 where the polygon
#: turns gently): heavier rows would make the system ill-conditioned against the pins
#: that hold offsets at their bounds.
TURN_CAP = 1e4


def min_turning_offsets(origin: FloatArray, normal: FloatArray, lo: FloatArray,
                        hi: FloatArray, centre: FloatArray, weight: float, kappa_max: float,
                        rounds: int = TURN_ROUNDS) -> FloatArray:
    """Lateral offsets ``(m,)`` [m] like :func:`min_bending_offsets`, re-solved so that the
    polygon spreads its turn over the room the bands leave.

    The least-bending polygon measures each second difference on the origins' spacing;
    where the sweep lines fan out round a corner, points on the inside stand closer
    together than their origins, so a turn there counts as gentler than it is and the
    polygon crowds its turn at the inner corner, sharper than the car can turn. While the
    polygon turns somewhere by more than ``target`` (below), each further round scales
    the second differences by the last polygon's own legs and, from the third on,
    weights them up, cumulatively, by ``(turn / target) ** TURN_POWER``
    where the polygon's discrete curvature ``turn`` [1/m] (turning angle over the mean of
    the two legs) exceeds ``target = TURN_SHARE * kappa_max`` [1/m]: iteratively
    reweighted least squares towards the polygon of least largest turn (equation (3)'s
    smoothing, aimed at the turning limit), each weight at most :data:`TURN_CAP`. The
    offsets stay within ``lo <= l <= hi``.
    """
    m = len(origin)
    x = min_bending_offsets(origin, normal, lo, hi, centre, weight)
    if m < 3 or rounds <= 1:
        return x
    rows = np.ones(m - 2)
    target = TURN_SHARE * kappa_max
    for r in range(rounds - 1):
        turn, legs = polygon_turns(origin + x[:, None] * normal)
        if not np.any(turn > target):
            break
        if r > 0:
            rows = np.minimum(rows * np.maximum(turn / target, 1.0) ** TURN_POWER, TURN_CAP)
        try:
            x = min_bending_offsets(origin, normal, lo, hi, centre, weight, legs=legs,
                                    rows=rows)
        except np.linalg.LinAlgError:  # pragma: no cover - the cap keeps it definite
            break
    return x


def _turning(pts: FloatArray, kappa: float) -> NDArray[np.bool_]:
    """Per vertex after the first of a polygon ``(m, 2)`` (``(m - 1,)``): whether it, or
    one of the two before it, turns by more than ``kappa`` [1/m] (:func:`polygon_turns`)."""
    out = np.zeros(len(pts) - 1, dtype=bool)
    if len(pts) < 3:
        return out
    bent = polygon_turns(pts)[0] > kappa
    out[:-1] |= bent
    out[1:] |= bent
    out[2:] |= bent[:-1]
    return out


def polygon_turns(pts: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Discrete curvature ``(m - 2,)`` [1/m] at the inner vertices of a polygon ``(m, 2)``
    (turning angle over the mean of the two legs) and its leg lengths ``(m - 1,)`` [m]."""
    d = np.diff(pts, axis=0)
    legs = np.hypot(d[:, 0], d[:, 1])
    head = np.arctan2(d[:, 1], d[:, 0])
    turn = np.abs((np.diff(head) + np.pi) % (2.0 * np.pi) - np.pi)
    return turn / np.maximum((legs[:-1] + legs[1:]) / 2.0, 1e-6), legs


#: Stiffness that holds an offset at its bound in :func:`min_bending_offsets`.
_PIN = 1e8


@njit(cache=True)
def _bending_system(origin: FloatArray, normal: FloatArray, centre: FloatArray, weight: float,
                    legs: FloatArray, rows: FloatArray
                    ) -> tuple[FloatArray, ...]:  # pragma: no cover - compiled
    """The quadratic objective of :func:`min_bending_offsets` in the offsets (``m >= 3``):
    the diagonal ``h0`` ``(m,)``, the off-diagonals ``h1`` ``(m - 1,)`` and ``h2``
    ``(m - 2,)`` of its pentadiagonal Hessian, and its gradient ``g`` ``(m,)`` at zero.

    The second differences ``D`` ``(m - 2, m)`` of the points for uneven spacing (the leg
    lengths ``legs`` ``(m - 1,)``) are curvature-like, weighted by the length each one
    stands for and by ``rows`` ``(m - 2,)``; the Hessian is ``N^T D^T D N`` (``N``: the
    normals) plus ``weight`` and a tiny ridge that keeps it definite where nothing else
    pins the offsets down.
    """
    m = len(origin)
    c0, c1, c2 = np.empty(m - 2), np.empty(m - 2), np.empty(m - 2)
    for r in range(m - 2):
        ha = max(legs[r], 1e-3)
        hb = max(legs[r + 1], 1e-3)
        # 2 / (ha + hb) * sqrt((ha + hb) / 2), times the row's weight's root
        w = np.sqrt(2.0 / (ha + hb) * rows[r])
        c0[r], c1[r], c2[r] = w / ha, -w * (1.0 / ha + 1.0 / hb), w / hb
    h0, h1, h2, g = np.zeros(m), np.zeros(m - 1), np.empty(m - 2), np.empty(m)
    dtx, dty = np.zeros(m), np.zeros(m)
    for r in range(m - 2):
        h0[r] += c0[r] * c0[r]
        h0[r + 1] += c1[r] * c1[r]
        h0[r + 2] += c2[r] * c2[r]
        h1[r] += c0[r] * c1[r]
        h1[r + 1] += c1[r] * c2[r]
        h2[r] = c0[r] * c2[r] * (normal[r, 0] * normal[r + 2, 0]
                                 + normal[r, 1] * normal[r + 2, 1])
        # D @ origin, then D^T of it
        sx = c0[r] * origin[r, 0] + c1[r] * origin[r + 1, 0] + c2[r] * origin[r + 2, 0]
        sy = c0[r] * origin[r, 1] + c1[r] * origin[r + 1, 1] + c2[r] * origin[r + 2, 1]
        dtx[r] += c0[r] * sx
        dty[r] += c0[r] * sy
        dtx[r + 1] += c1[r] * sx
        dty[r + 1] += c1[r] * sy
        dtx[r + 2] += c2[r] * sx
        dty[r + 2] += c2[r] * sy
    for k in range(m):
        h0[k] = (h0[k] * (normal[k, 0] * normal[k, 0] + normal[k, 1] * normal[k, 1])
                 + weight + 1e-9)
        g[k] = normal[k, 0] * dtx[k] + normal[k, 1] * dty[k] - weight * centre[k]
    for k in range(m - 1):
        h1[k] *= normal[k, 0] * normal[k + 1, 0] + normal[k, 1] * normal[k + 1, 1]
    return h0, h1, h2, g


@njit(cache=True)
def _hess(h0: FloatArray, h1: FloatArray, h2: FloatArray, x: FloatArray
          ) -> FloatArray:  # pragma: no cover - compiled
    """The pentadiagonal matrix (diagonal ``h0``, first and second off-diagonals ``h1``,
    ``h2``) times ``x``."""
    m = len(x)
    y = h0 * x
    for k in range(m - 1):
        y[k] += h1[k] * x[k + 1]
        y[k + 1] += h1[k] * x[k]
    for k in range(m - 2):
        y[k] += h2[k] * x[k + 2]
        y[k + 2] += h2[k] * x[k]
    return y


@njit(cache=True)
def _pinned_solve(h0: FloatArray, h1: FloatArray, h2: FloatArray, g: FloatArray,
                  lo: FloatArray, hi: FloatArray, at_lo: NDArray[np.bool_],
                  at_hi: NDArray[np.bool_], start: int, fac: FloatArray, x: FloatArray
                  ) -> bool:  # pragma: no cover - compiled
    """Minimum ``x`` of ``x H x / 2 + g x`` with the offsets in ``at_lo`` / ``at_hi`` held at
    those bounds by a stiff penalty (:data:`_PIN`); ``False`` if the system is not positive
    definite.

    ``fac`` ``(5, m)`` holds the factorisation ``L D L^T`` of the pentadiagonal system
    (``D``, the two subdiagonals of ``L``), ``w = L^-1 b`` and ``D^-1 w``; its columns
    before ``start`` are those of the previous call (the first offset whose pin changed
    since: the factorisation runs from the first row on).
    """
    m = len(h0)
    dd, l1, l2, w, z = fac[0], fac[1], fac[2], fac[3], fac[4]
    for j in range(start, m):
        a = h0[j]
        b = -g[j]
        if at_lo[j]:
            a += _PIN
            b += _PIN * lo[j]
        elif at_hi[j]:
            a += _PIN
            b += _PIN * hi[j]
        c = h1[j] if j + 1 < m else 0.0
        if j >= 1:
            t = l1[j - 1] * dd[j - 1]
            a -= l1[j - 1] * t
            c -= l2[j - 1] * t
            b -= l1[j - 1] * w[j - 1]
        if j >= 2:
            t = l2[j - 2] * dd[j - 2]
            a -= l2[j - 2] * t
            b -= l2[j - 2] * w[j - 2]
        if not a > 0.0:
            return False
        dd[j] = a
        w[j] = b
        z[j] = b / a
        if j + 1 < m:
            l1[j] = c / a
        if j + 2 < m:
            l2[j] = h2[j] / a
    for j in range(m - 1, -1, -1):
        v = z[j]
        if j + 1 < m:
            v -= l1[j] * x[j + 1]
        if j + 2 < m:
            v -= l2[j] * x[j + 2]
        x[j] = v
    return True


@njit(cache=True)
def _min_bending_loops(h0: FloatArray, h1: FloatArray, h2: FloatArray, g: FloatArray,
                       lo: FloatArray, hi: FloatArray, max_rounds: int
                       ) -> tuple[FloatArray, bool]:  # pragma: no cover - compiled
    """The active-set loops of :func:`min_bending_offsets` on its pentadiagonal Hessian
    (``h0``, ``h1``, ``h2``) and gradient at zero ``g``: the offsets and whether every
    system was positive definite."""
    m = len(h0)
    fixed = lo >= hi
    fac = np.zeros((5, m))
    # primal-dual active set: fast, usually exact, but not guaranteed to settle
    at_lo = np.zeros(m, dtype=np.bool_)
    at_hi = fixed.copy()
    x = np.zeros(m)
    start: int | np.int64 = np.int64(0)  # not a literal 0: that compiles _pinned_solve twice
    for _ in range(max_rounds):
        if not _pinned_solve(h0, h1, h2, g, lo, hi, at_lo, at_hi, start, fac, x):
            return x, False
        grad = _hess(h0, h1, h2, x) + g
        start = m
        for k in range(m):
            new_lo = ((at_lo[k] and grad[k] >= 0) or x[k] < lo[k] - 1e-9) and not fixed[k]
            new_hi = (((at_hi[k] and grad[k] <= 0) or x[k] > hi[k] + 1e-9) and not new_lo
                      ) or fixed[k]
            if (new_lo != at_lo[k] or new_hi != at_hi[k]) and start == m:
                start = k
            at_lo[k], at_hi[k] = new_lo, new_hi
        if start == m:
            break
    # primal active set from there: each step stays within the bounds and lowers the
    # objective, so it ends at the optimum
    start = np.int64(0)
    for k in range(m):
        x[k] = min(max(x[k], lo[k]), hi[k])
        at_lo[k] = x[k] <= lo[k] and not fixed[k]
        at_hi[k] = x[k] >= hi[k] or fixed[k]
    y = np.empty(m)
    for _ in range(4 * m + 10):
        if not _pinned_solve(h0, h1, h2, g, lo, hi, at_lo, at_hi, start, fac, y):
            return x, False
        out = False
        for k in range(m):
            if not (at_lo[k] or at_hi[k]) and (y[k] < lo[k] or y[k] > hi[k]):
                out = True
                break
        if not out:
            for k in range(m):
                if not (at_lo[k] or at_hi[k]):
                    x[k] = y[k]
            grad = _hess(h0, h1, h2, x) + g
            i, worst, big = 0, -np.inf, 0.0
            for k in range(m):
                w = 0.0
                if at_lo[k]:
                    w += -grad[k]
                if at_hi[k] and not fixed[k]:
                    w += grad[k]
                if w > worst:
                    i, worst = k, w
                big = max(big, abs(grad[k]))
            if worst <= 1e-9 * (1.0 + big):
                break
            at_lo[i] = at_hi[i] = False
            start = i
            continue
        j, room_j = 0, np.inf
        for k in range(m):
            if at_lo[k] or at_hi[k]:
                continue
            dk = y[k] - x[k]
            if dk < 0:
                r = max((lo[k] - x[k]) / dk, 0.0)
            elif dk > 0:
                r = max((hi[k] - x[k]) / dk, 0.0)
            else:
                r = np.inf
            if r < room_j:
                j, room_j = k, r
        t = min(room_j, 1.0)
        dj = y[j] - x[j]
        for k in range(m):
            if not (at_lo[k] or at_hi[k]):
                x[k] = x[k] + t * (y[k] - x[k])
        at_lo[j], at_hi[j] = dj < 0, dj > 0
        start = j
    for k in range(m):
        x[k] = min(max(x[k], lo[k]), hi[k])
    return x, True


@njit(cache=True)
def _leg_fractions(leg_len: FloatArray, empty: NDArray[np.bool_], cap: float, ratio: float,
                   smooth: bool) -> tuple[FloatArray, NDArray[np.int64]]:  # pragma: no cover
    """Fractions ``(k,)`` at which to split the control polygon's legs of lengths ``leg_len``
    [m] (none of the ``empty`` ones), and the leg of each: pieces of at most ``cap`` [m],
    and with ``smooth`` as :func:`_leg_splits` grows them."""
    # two passes over plain arrays (a list of arrays would double this loop's compile time)
    n = len(leg_len)
    total = 0
    for j in range(n):
        if not empty[j]:
            total += len(_leg_pieces(leg_len, j, cap, ratio, smooth))
    frac = np.empty(total)
    leg = np.empty(total, dtype=np.int64)
    at = 0
    for j in range(n):
        if empty[j]:
            continue
        f = _leg_pieces(leg_len, j, cap, ratio, smooth)
        for q in range(len(f)):
            frac[at + q] = f[q]
            leg[at + q] = j
        at += len(f)
    return frac, leg


@njit(cache=True)
def _leg_pieces(leg_len: FloatArray, j: int, cap: float, ratio: float, smooth: bool
                ) -> FloatArray:  # pragma: no cover - compiled
    """The fractions of leg ``j`` for :func:`_leg_fractions`."""
    n = len(leg_len)
    if smooth:
        before = leg_len[j - 1] if j > 0 else np.inf
        after = leg_len[j + 1] if j + 1 < n else np.inf
        return _leg_splits(leg_len[j], before, after, cap, ratio)
    pieces = int(np.ceil(leg_len[j] / cap - 1e-9))
    f = np.empty(max(pieces - 1, 0))
    for k in range(1, pieces):
        f[k - 1] = k / max(pieces, 1)
    return f


@njit(cache=True)
def _leg_splits(length: float, before: float, after: float, cap: float, ratio: float
                ) -> FloatArray:  # pragma: no cover - compiled
    """Fractions ``(k,)`` of a control-polygon leg of ``length`` [m] at which to split it so
    that no piece is longer than ``cap`` [m] nor ``ratio`` times its neighbour: pieces grow
    geometrically from the legs ``before`` and ``after`` it (their lengths [m]).

    A uniform B-spline turns within its shortest legs, so a short leg beside a long one
    gives a sharp bend that the control polygon does not have.
    """
    cuts_a = []
    cuts_b = []
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
    lo = cuts_a[-1] if len(cuts_a) else 0.0
    hi = cuts_b[-1] if len(cuts_b) else length
    mid = int(np.ceil((hi - lo) / cap - 1e-9))
    out = np.empty(len(cuts_a) + max(mid - 1, 0) + len(cuts_b))
    n = 0
    for c in cuts_a:
        out[n] = c / length
        n += 1
    for k in range(1, mid):
        out[n] = (lo + (hi - lo) * k / max(mid, 1)) / length
        n += 1
    for q in range(len(cuts_b) - 1, -1, -1):
        out[n] = cuts_b[q] / length
        n += 1
    return out


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
        if len(roadmap.band_lo) == len(path):
            # beside an obstacle, placement may take the road margin: the interval with it
            lo = np.minimum(lo, np.asarray(roadmap.band_lo, dtype=float)[distinct])
            hi = np.maximum(hi, np.asarray(roadmap.band_hi, dtype=float)[distinct])
        # the vertex, moved off its interval's ends by the reserve where it can
        q = np.minimum(band_reserve, (hi - lo) / 2.0)
        centre = np.clip(sl[:, 1], lo + q, hi - q)
        room = np.minimum(centre - lo, hi - centre)
        half = np.clip(np.minimum(band_fraction * np.maximum(hi - lo, 0.0) / 2.0,
                                  room - band_reserve), 0.0, None)
        if len(roadmap.band_lo) == len(path):
            # level 2's bands: no nearer the obstacles than the vertex (not for the
            # reserve either), nor out of its lane
            b_lo = np.asarray(roadmap.band_lo, dtype=float)[distinct]
            b_hi = np.asarray(roadmap.band_hi, dtype=float)[distinct]
            centre = np.clip(centre, b_lo, np.maximum(b_lo, b_hi))
            half = np.clip(np.minimum(half, np.minimum(centre - b_lo, b_hi - centre)),
                           0.0, None)
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
    return _simplify(_band_ends(pts, org, nrm, cen, hlf), org, tan)


#: Angular tolerance [rad] of band simplification's test.
_TOL = 1e-9


def _simplify(ends: FloatArray, origin: FloatArray, tangent: FloatArray) -> NDArray[np.int64]:
    """:func:`band_simplify` of the vertices with the band ends ``ends`` (:func:`_band_ends`),
    on lines through ``origin`` ``(m, 2)``, the road's direction there ``tangent`` ``(m, 2)``."""
    m = len(ends)
    if m <= 2:
        return np.arange(m, dtype=np.int64)
    return _band_simplify_loop(ends, kernel_floats(origin),
                               kernel_floats(tangent), _TOL)


def _band_ends(pts: FloatArray, origin: FloatArray, normal: FloatArray, centre: FloatArray,
               half: FloatArray) -> FloatArray:
    """Per vertex ``(m, 3, 2)``: the lower and the upper end of its band, and the vertex."""
    return kernel_floats(
        np.stack((origin + (centre - half)[:, None] * normal,
                  origin + (centre + half)[:, None] * normal, pts), axis=1))


@njit(cache=True)
def _farthest_from(px: float, py: float, i: int, cap: int, ends: FloatArray,
                   origin: FloatArray, tangent: FloatArray, tol: float
                   ) -> int:  # pragma: no cover - compiled
    """Largest ``j`` in ``(i, cap]`` (at least ``i + 1``) such that every segment from
    ``(px, py)`` to vertex ``j' <= j`` crosses the lines ``i < k < j'`` inside their bands
    (``ends``: :func:`_band_ends`).

    The rays from the point that meet band ``k`` form the angle between its two ends (seen
    from the point, relative to the road's direction at ``i + 1``); a segment to vertex
    ``j`` crosses every band before ``j`` if its direction lies in all their angles (running
    maximum of the lower and minimum of the upper ends, within ``tol`` [rad]), and reaches
    each line ``k < j`` as the lines do not cross. A line through the point itself does
    not constrain the direction.
    """
    m = len(ends)
    if cap <= i + 1:
        return min(i + 1, m - 1)
    ref = i + 1 if i + 1 < m else m - 1
    c, s = tangent[ref, 0], tangent[ref, 1]
    low, high = -np.inf, np.inf
    for k in range(i + 1, cap + 1):
        dx, dy = ends[k, 2, 0] - px, ends[k, 2, 1] - py
        th = np.arctan2(-dx * s + dy * c, dx * c + dy * s)
        if k > i + 1 and not (th >= low - tol and th <= high + tol):
            return k - 1
        if abs((origin[k, 0] - px) * tangent[k, 0] + (origin[k, 1] - py) * tangent[k, 1]) < 1e-9:
            continue
        dx, dy = ends[k, 0, 0] - px, ends[k, 0, 1] - py
        a1 = np.arctan2(-dx * s + dy * c, dx * c + dy * s)
        dx, dy = ends[k, 1, 0] - px, ends[k, 1, 1] - py
        a2 = np.arctan2(-dx * s + dy * c, dx * c + dy * s)
        low = max(low, min(a1, a2))
        high = min(high, max(a1, a2))
    return cap


@njit(cache=True)
def _band_simplify_loop(ends: FloatArray, origin: FloatArray, tangent: FloatArray, tol: float
                        ) -> NDArray[np.int64]:  # pragma: no cover - compiled
    """The vertices that :func:`band_simplify` keeps (``ends``: :func:`_band_ends`)."""
    m = len(ends)
    kept = np.empty(m, dtype=np.int64)
    kept[0] = 0
    n, i = 1, np.int64(0)  # not a literal 0: that would compile _farthest_from twice
    while i < m - 1:
        i = _farthest_from(ends[i, 2, 0], ends[i, 2, 1], i, m - 1, ends, origin, tangent, tol)
        kept[n] = i
        n += 1
    return kept[:n].copy()


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
    _fill_bins(vid, line, b_lo, b_hi)
    lv = np.clip(grid[None, :], lo_v[vid], hi_v[vid])
    near = np.minimum(lv - lo_v[vid], hi_v[vid] - lv)
    penalty = np.where(vid >= 0, np.maximum(_DETOUR_CLEAR - near, 0.0) ** 2, np.inf)
    # moves b - dlt -> b between lines k and k + 1 that follow an arc within the rate:
    # ok[k, b, dlt + r], with their lateral cost
    ds = np.maximum(np.diff(st), 1e-6)
    r = int(np.floor(rate * float(ds.max()) / h + 1e-9))
    dlt = np.arange(-r, r + 1)
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
    # moves within the rate and their lateral cost, (lines - 1, 2r + 1)
    within = np.abs(dlt)[None, :] * h <= rate * ds[:, None] + 1e-9
    lat_cost = (dlt[None, :] * h) ** 2 / ds[:, None]
    # start: the source vertex, at the vehicle's offset
    src = int(roadmap.path[0])
    l_start = float(corridor.to_sl(np.asarray(roadmap.start_xy, dtype=float)[None])[0, 1])
    cost = np.where(vid[0] == src, np.abs(grid - l_start), np.inf)
    cost = np.where(cost <= np.min(cost) + 1e-9, penalty[0], np.inf)
    cost, back = _detour_sweep(cost, penalty, lid, table, within, lat_cost, r)
    if not np.isfinite(cost).any():
        return None
    bins = _detour_bins(back, int(np.argmin(cost)), r)
    ks = np.arange(n_lines)
    path = vid[ks, bins]
    lat = lv[ks, bins]
    xy = corridor.to_xy(st, lat)
    width = np.asarray(roadmap.graph_width, dtype=float)[path]
    j = int(np.argmin(width))
    return replace(roadmap, xy=xy, s=st.copy(), l=lat, width=width,
                   bottleneck_width=float(width[j]), bottleneck_index=j,
                   length=float(polyline_stations(xy)[-1]), path=path,
                   links=np.zeros((0, 2, 2)), band_lo=np.zeros(0), band_hi=np.zeros(0),
                   separation=np.zeros(0))


@njit(cache=True)
def _fill_bins(vid: NDArray[np.int64], line: NDArray[np.int64], b_lo: NDArray[np.int64],
               b_hi: NDArray[np.int64]) -> None:  # pragma: no cover - compiled
    """Writes vertex ``v`` into ``vid[line[v], b_lo[v]:b_hi[v] + 1]``, vertex after vertex."""
    for v in range(len(line)):
        for b in range(max(b_lo[v], 0), min(b_hi[v] + 1, vid.shape[1])):
            vid[line[v], b] = v


@njit(cache=True)
def _detour_sweep(cost: FloatArray, penalty: FloatArray, lid: NDArray[np.int64],
                  table: NDArray[np.bool_], within: NDArray[np.bool_], lat_cost: FloatArray,
                  r: int) -> tuple[FloatArray, NDArray[np.int64]]:  # pragma: no cover
    """:func:`detour_roadmap`'s dynamic programme over the lines.

    From the costs ``(nb,)`` on the first line, bin ``b`` of line ``k + 1`` takes the
    cheapest move ``b - dlt -> b`` (``dlt = d - r``, ``d < 2r + 1``; the first of equal
    ones) that is ``within[k, d]`` the rate and follows an arc: ``table[k, p, q]`` of the
    bins' vertices' places ``lid[k, b - dlt + r]``, ``lid[k + 1, b + r]`` on their lines
    (``lid`` ``(lines, nb + 2r)`` padded by ``r`` bins of none on each side); the move costs
    ``lat_cost[k, d]``, the bin its ``penalty[k + 1, b]``. Returns the costs on the last line
    and the move ``d`` taken into each bin ``(lines, nb)``.
    """
    n_lines, nb = penalty.shape
    w = 2 * r + 1
    back = np.zeros((n_lines, nb), dtype=np.int64)
    for k in range(n_lines - 1):
        new = np.empty(nb)
        for b in range(nb):
            to = lid[k + 1, b + r]
            j, best = 0, np.inf
            for d in range(w):
                f = b - (d - r)
                if not (within[k, d] and table[k, lid[k, f + r], to]):
                    continue
                c = cost[min(max(f, 0), nb - 1)] + lat_cost[k, d]
                if c < best:
                    j, best = d, c
            new[b] = best + penalty[k + 1, b]
            back[k + 1, b] = j
        cost = new
    return cost, back


@njit(cache=True)
def _detour_bins(back: NDArray[np.int64], last: int, r: int
                 ) -> NDArray[np.int64]:  # pragma: no cover - compiled
    """The bins ``(lines,)`` of :func:`_detour_sweep`'s moves back from bin ``last`` of the
    last line."""
    n_lines, nb = back.shape
    bins = np.zeros(n_lines, dtype=np.int64)
    bins[-1] = last
    for k in range(n_lines - 1, 0, -1):
        bins[k - 1] = min(max(bins[k] - (back[k, bins[k]] - r), 0), nb - 1)
    return bins
