"""Level 2: the sweep-line roadmap, searched for the widest, then shortest, path.

(Kala & Warwick, section III; the objective as fixed in ALGORITHM.md: maximise
``min(bottleneck width, wmax)``, then minimise length.)
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass, field, replace

import numpy as np
from numba import njit
from numpy.typing import ArrayLike, NDArray

from splineplan.corridor import REFERENCE_SPACING, Corridor
from splineplan.errors import (
    GeometryError,
    ParameterError,
    RoadBlockedError,
    require_non_negative,
    require_positive,
)
from splineplan.geometry import (
    FloatArray,
    kernel_floats,
    kernel_ints,
    polygon_edges,
    wrap_angle,
)
from splineplan.obstacles import Obstacles

logger = logging.getLogger(__name__)

#: How far [m] the vehicle may stand outside the road and still get a roadmap.
MAX_START_OFFROAD = 3.0
#: Sweep-line spacings [m] that a user's input may ask for (``plan --d``, a scenario's
#: ``[roadmap] d``): finer lines take minutes and write hundreds of megabytes of plan.json
#: for no better plan (0.001 m on the 600 m straight network: 54 s, 2.8 GB of memory and a
#: 235 MB plan.json, against 3 s and 2.4 MB at 0.1 m); coarser ones step over the
#: lateral moves between obstacles. :class:`RoadmapParams` itself takes any positive d.
D_RANGE = (0.1, 10.0)
#: Numerical slack [m] of the clearance checks (free-interval ends lie exactly at the
#: inflation distance, so arcs leaving a zero-width vertex touch it).
_EPS = 1e-7


@dataclass(frozen=True)
class RoadmapParams:
    """Parameters of level 2, checked on creation.

    Attributes
    ----------
    d
        Spacing [m] of the sweep lines.
    wmax
        Width [m] above which free intervals count as equally wide.
    safety_margin
        Clearance [m] kept from obstacles and road edges, beyond the ego's half width.
    vehicle_length, vehicle_width
        Ego dimensions [m].
    segment_length
        Length [m] of the road segments a long route is cut into.
    road_margin
        Clearance [m] kept from the road edges, beyond the ego's half width: the road
        edges are grown by ``vehicle_width / 2 + road_margin``. By default the safety
        margin, so that the paper's midpoints keep it from the road edges as from the
        obstacles (with none, 19 of 177 drivable Monaco junction turns that were feasible
        came out infeasible). With ``place=True``, the placed vertices beside an obstacle
        give this margin to their separation from it (:func:`place_vertices`), and keep
        ``safety_margin`` from the road edges where the obstacles leave room; 0 also
        lets level 2's graph pass between an obstacle and the road's edge where the car
        just fits.
    lane_width
        Width [m] of a lane (SUMO's default 3.2 m): a road ``w`` wide holds
        ``round(w / lane_width)`` lanes (at least one), whose centres the chosen vertices
        keep on a free road (see :func:`place_vertices`).
    place
        Whether the chosen vertices are placed for the separation and the lane
        (:func:`place_vertices`: as far from obstacles as a car in the next lane keeps,
        then from the road's edges, then the lane's centre). Off by default, the paper's
        midpoints of the free intervals: placed, the vertices keep most of the best
        clearance in tight passages, but the paths they give weave more (a blocked field
        took 42 s instead of 34 s) and turned a planned vehicle's timely yield to another's
        plan into a conflict that needs full braking.
    """

    d: float = 1.0
    wmax: float = 3.5
    safety_margin: float = 0.3
    vehicle_length: float = 4.5
    vehicle_width: float = 1.8
    segment_length: float = 300.0
    road_margin: float = 0.3
    lane_width: float = 3.2
    place: bool = False

    def __post_init__(self) -> None:
        for name in ("d", "wmax", "vehicle_length", "vehicle_width", "segment_length",
                     "lane_width"):
            require_positive(f"RoadmapParams.{name}", getattr(self, name))
        require_non_negative("RoadmapParams.safety_margin", self.safety_margin)
        require_non_negative("RoadmapParams.road_margin", self.road_margin)
        if self.segment_length < 2 * self.d:
            raise ParameterError(
                f"RoadmapParams.d ({self.d:g} m) must be at most half of "
                f"RoadmapParams.segment_length ({self.segment_length:g} m)")

    @property
    def inflation(self) -> float:
        """How far [m] obstacles are grown: half width plus the safety margin."""
        return self.vehicle_width / 2.0 + self.safety_margin

    @property
    def road_inflation(self) -> float:
        """How far [m] the road edges are grown: half width plus the road margin."""
        return self.vehicle_width / 2.0 + self.road_margin

    @property
    def enough_separation(self) -> float:
        """Separation [m] of a vertex from the grown obstacles beyond which more counts
        as no better: what a car keeps from a car in the next lane when both keep their
        lanes' centres (``lane_width - vehicle_width``, less the safety margin that the
        growth holds), at most ``wmax / 2`` (the paper's threshold, for one side)."""
        return float(min(max(self.lane_width - self.vehicle_width - self.safety_margin, 0.0),
                         self.wmax / 2.0))


@dataclass(frozen=True, eq=False)
class Roadmap:
    """Result of level 2.

    The chosen path runs through ``m`` vertices, one per sweep line from the source's
    line to the last line. Widths are those of the free intervals of the grown
    (configuration-space) obstacles: a width of 0 means the ego just fits.

    Attributes
    ----------
    xy, s, l, width
        The chosen vertices: points ``(m, 2)`` [m], station ``(m,)`` [m], lateral offset
        ``(m,)`` [m] and free-interval width ``(m,)`` [m].
    bottleneck_width
        Narrowest width [m] on the chosen path (not capped at wmax).
    bottleneck_index
        Index into the chosen vertices of that narrowest vertex.
    length
        Length [m] of the chosen polyline.
    graph_xy, graph_s, graph_l, graph_width, graph_line
        The whole graph's vertices: points ``(V, 2)``, station, lateral offset, width and
        the index of each vertex's sweep line ``(V,)`` (line 0 is the source's; lines
        behind the vehicle are not built).
    graph_lo, graph_hi
        Lateral bounds ``(V,)`` [m] of each vertex's free interval.
    arcs
        ``(E, 2)`` vertex indices of the graph's arcs, from line i to line i + 1.
    path
        ``(m,)`` indices into the graph's vertices of the chosen path.
    start_xy
        Where the vehicle was ``(2,)`` [m].
    params
        The parameters used.
    arc_direct
        ``(E,)``: whether the straight segment between the arc's two vertices keeps the
        inflation distance from obstacles and road edges.
    links
        ``(m - 1, 2, 2)`` [m]: for each step of the chosen path, a free straight link
        ``p -> q`` from the first vertex's sweep line to the next one's (see
        :attr:`passage_xy`).
    band_lo, band_hi
        ``(m,)`` [m]: lateral offsets between which level 3's control polygon may cross
        each chosen vertex's sweep line without coming nearer the obstacles than the
        vertex (nor leaving the vertex's lane where it keeps a lane's centre); see
        :func:`place_vertices`. Beside an obstacle on one side and the road's edge on the
        other they may reach beyond the free interval into the road margin. Empty:
        within the free intervals.
    separation
        ``(m,)`` [m]: how far each placed vertex keeps from the grown obstacles beside it
        (at most :attr:`RoadmapParams.enough_separation`; 0 where no obstacle bounds its
        interval), of which level 3's smoothing keeps :data:`BAND_KEEP`. Empty: not
        placed.
    """

    xy: FloatArray
    s: FloatArray
    l: FloatArray  # noqa: E741
    width: FloatArray
    bottleneck_width: float
    bottleneck_index: int
    length: float
    graph_xy: FloatArray
    graph_s: FloatArray
    graph_l: FloatArray
    graph_width: FloatArray
    graph_line: NDArray[np.int64]
    graph_lo: FloatArray
    graph_hi: FloatArray
    arcs: NDArray[np.int64]
    path: NDArray[np.int64]
    start_xy: FloatArray
    params: RoadmapParams
    arc_direct: NDArray[np.bool_] = field(default_factory=lambda: np.zeros(0, dtype=bool))
    links: FloatArray = field(default_factory=lambda: np.zeros((0, 2, 2)))
    band_lo: FloatArray = field(default_factory=lambda: np.zeros(0))
    band_hi: FloatArray = field(default_factory=lambda: np.zeros(0))
    separation: FloatArray = field(default_factory=lambda: np.zeros(0))

    @property
    def passage_xy(self) -> FloatArray:
        """A polyline ``(k, 2)`` [m] through the chosen vertices that keeps the inflation
        distance from obstacles and road edges (configuration-space free).

        From each vertex it runs along its sweep line (inside the free interval) to the
        link's start, across to the link's end, and along the next line to the next
        vertex. Where the straight segment between two vertices is free, that is all it
        takes. Without links it is the vertices' polyline.
        """
        if len(self.links) != len(self.xy) - 1 or len(self.xy) < 2:
            return self.xy
        pts = np.concatenate((self.xy[:-1, None], self.links), axis=1).reshape(-1, 2)
        pts = np.concatenate((pts, self.xy[-1:]))
        keep = np.concatenate(([True], np.hypot(*np.diff(pts, axis=0).T) > 1e-9))
        return np.asarray(pts[keep])

    def at_midpoints(self) -> Roadmap:
        """The same path with its vertices at their free intervals' midpoints (the paper's
        vertices) and no bands."""
        path = np.asarray(self.path)
        xy = np.asarray(self.graph_xy)[path]
        return replace(self, xy=xy, l=np.asarray(self.graph_l)[path],
                       length=float(np.hypot(*np.diff(xy, axis=0).T).sum()),
                       band_lo=np.zeros(0), band_hi=np.zeros(0), separation=np.zeros(0))

    @property
    def bottleneck_s(self) -> float:
        """Station [m] of the narrowest vertex on the chosen path."""
        return float(self.s[self.bottleneck_index])


def plan_roadmap(
    corridor: Corridor,
    obstacles: Obstacles,
    start_xy: ArrayLike,
    params: RoadmapParams | None = None,
) -> Roadmap:
    """Widest-then-shortest roadmap across a corridor among obstacles.

    Sweep lines stand at stations ``0, d, 2d, ...`` and at the corridor's end; each is the
    straight segment along the reference line's normal between the road boundaries. Its
    free intervals are the points at least ``params.inflation`` [m] from every obstacle and
    ``params.road_inflation`` [m] from both road edges (lateral offset within
    ``[right + road_inflation, left - road_inflation]``), and, where the corridor has keep
    offsets (the lanes a vehicle keeps to), within those beyond :data:`KEEP_GRACE` of the
    start; where they leave no passage, only around the stretch they block
    (:data:`RELEASE_AFTER`).
    A vertex stands at each interval's midpoint. An arc joins vertices ``a`` and ``b`` of
    consecutive lines when the vehicle (a point in the grown configuration space) can pass
    from ``a`` to ``b``: along ``a``'s line inside its free interval, across a straight
    *link* to a point of ``b``'s interval, and along ``b``'s line. A link is free when it
    keeps ``inflation`` from every obstacle (exact segment-to-polygon distance) and stays on
    the shrunk road (exact on straight stretches; checked at points at most
    ``REFERENCE_SPACING / 2`` apart where the road bends). The straight segment between
    the midpoints is tried first (``Roadmap.arc_direct``); where it cuts a grown corner,
    links at other places across the two intervals are tried, so that an obstacle just
    ahead of a sweep line does not close an open road. ``Roadmap.passage_xy`` is the
    chosen path with its links: a collision-free polyline.

    The search maximises ``min(bottleneck width, wmax)``, then minimises length, exactly
    (dynamic programming over the sweep lines, which form a layered acyclic graph). The
    chosen path's vertices then move within their intervals to keep the separation from
    the obstacles and the lane's centre (:func:`place_vertices`); ``graph_xy`` keeps the
    midpoints.

    Parameters
    ----------
    corridor
        The road segment.
    obstacles
        Static obstacles (not yet grown); ``None``: none.
    start_xy
        Vehicle position ``(2,)`` [m]. The path starts on the first sweep line at or ahead
        of the vehicle's station, at the vertex nearest the vehicle. A start inside an
        obstacle is planned from all the same (the vehicle is where it is; level 3 then
        reports the trajectory infeasible), with a warning in the log that names the
        obstacle and where the roadmap starts instead.
    params
        Level-2 parameters; defaults to ``RoadmapParams()``.

    Raises
    ------
    GeometryError
        The start lies outside the corridor's station range, or more than
        ``MAX_START_OFFROAD`` [m] off the road; or the inputs are malformed.
    RoadBlockedError
        No path of the graph reaches the last sweep line; ``station`` is the route
        station (``corridor.offset`` added) of the first sweep line no path reaches.
    """
    params = RoadmapParams() if params is None else params
    if not isinstance(params, RoadmapParams):
        raise ParameterError(f"params must be RoadmapParams, not {type(params).__name__}")
    if not isinstance(corridor, Corridor):
        raise GeometryError(f"corridor must be a Corridor, not {type(corridor).__name__}")
    if obstacles is None:
        obstacles = Obstacles.empty()
    if not isinstance(obstacles, Obstacles):
        raise GeometryError(f"obstacles must be Obstacles, not {type(obstacles).__name__}")
    start = np.asarray(start_xy, dtype=float).reshape(-1)
    if start.shape != (2,) or not np.all(np.isfinite(start)):
        raise GeometryError(f"start_xy must be two finite coordinates, got {start_xy!r}")
    s0, l0 = (float(v) for v in corridor.to_sl(start[None])[0])
    _check_start(corridor, s0, l0)
    out = _plan_keeping(corridor, obstacles, start, s0, l0, params)
    _warn_start_inside(obstacles, start, out)
    return out


def _plan_keeping(corridor: Corridor, obstacles: Obstacles, start: FloatArray, s0: float,
                  l0: float, params: RoadmapParams) -> Roadmap:
    """:func:`_plan` within the corridor's keep offsets, released around each stretch
    where they leave no passage (:data:`RELEASE_AFTER` beyond the first line that no path
    reached, tapered before and after: :func:`_sweep_lines`), one stretch at a time; where
    a released stretch is still blocked, or after :data:`RELEASE_TRIES` stretches, the keep
    offsets do not bind at all."""
    released: list[tuple[float, float]] = []
    while corridor.keep_left is not None and len(released) < RELEASE_TRIES:
        try:
            return _plan(corridor, obstacles, start, s0, l0, params, s0 + KEEP_GRACE,
                         tuple(released))
        except RoadBlockedError as err:
            at = err.station - corridor.offset
            if any(a - 1e-6 <= at <= b + 1e-6 for a, b in released):
                break  # blocked where the keep offsets were released
            released.append((at, at + RELEASE_AFTER))
            logger.debug("roadmap: no passage within the lanes at s=%.1f m; other lanes "
                         "there", at)
    if corridor.keep_left is not None:
        # blocked even where the keep offsets were released (or too many stretches):
        # the whole road will do
        logger.debug("roadmap: no passage within the lanes, released or not; using any "
                     "lane")
    return _plan(corridor, obstacles, start, s0, l0, params, math.inf)


def _warn_start_inside(obstacles: Obstacles, start: FloatArray, roadmap: Roadmap) -> None:
    """Log a warning when the start lies inside an obstacle: the roadmap then begins at
    the nearest free vertex, away from the vehicle."""
    near = obstacles.near(start[None], 0.0)
    if not len(near):
        return
    inside = np.flatnonzero(np.array([near.subset([i]).distance(start[None])[0] <= 0.0
                                      for i in range(len(near))]))
    if len(inside):
        first = roadmap.xy[0]
        logger.warning(
            "start (%.2f, %.2f) m lies inside obstacle '%s'; the roadmap starts %.2f m away "
            "at (%.2f, %.2f) m, and the trajectory from the start is not collision-free",
            start[0], start[1], near.ids[int(inside[0])], float(np.hypot(*(first - start))),
            first[0], first[1])


def _plan(corridor: Corridor, obstacles: Obstacles, start: FloatArray, s0: float, l0: float,
          params: RoadmapParams, keep_from: float,
          released: tuple[tuple[float, float], ...] = ()) -> Roadmap:
    """:func:`plan_roadmap` with the corridor's keep offsets bound from ``keep_from`` [m]
    and released over the stretches ``released`` (:func:`_sweep_lines`)."""
    r = params.inflation
    stations = _stations(corridor.length, params.d)
    first = min(int(np.searchsorted(stations, s0 - 1e-9, side="left")), len(stations) - 1)
    stations = stations[first:]
    lines = _sweep_lines(corridor, stations, params.road_inflation, keep_from=keep_from,
                         released=released)
    iv_line, iv_lo, iv_hi = _free_intervals(lines, obstacles, r)
    nline = len(stations)
    mid = (iv_lo + iv_hi) / 2.0
    width = iv_hi - iv_lo
    vxy = lines.center[iv_line] + mid[:, None] * lines.normal[iv_line]
    graph = _arcs(corridor, lines, iv_line, iv_lo, iv_hi, obstacles, r)
    arcs, arc_len = graph.pairs, graph.length

    on_first = np.flatnonzero(iv_line == 0)
    if len(on_first) == 0:
        _raise_blocked(corridor, stations, 0)
    gap = np.maximum(np.maximum(iv_lo[on_first] - l0, l0 - iv_hi[on_first]), 0.0)
    source = int(on_first[np.lexsort((np.abs(mid[on_first] - l0), gap))[0]])
    path, steps, reached = _search(source, arcs, arc_len, width, iv_line, nline, params.wmax)
    if path is None or steps is None:
        _raise_blocked(corridor, stations, reached + 1)
        raise AssertionError  # unreachable: _raise_blocked raises
    pw = width[path]
    k = int(np.argmin(pw))
    give_lo = give_hi = None
    if params.place:
        give_lo, give_hi = _road_give(corridor, lines, iv_line[path], iv_lo[path],
                                      iv_hi[path], obstacles, params)
    lat, band_lo, band_hi, kept = place_vertices(corridor, lines, iv_line[path],
                                                 iv_lo[path], iv_hi[path], l0, params,
                                                 give_lo, give_hi)
    pline = iv_line[path]
    pxy = lines.center[pline] + lat[:, None] * lines.normal[pline]
    seg = np.diff(pxy, axis=0)
    out = Roadmap(
        xy=pxy, s=stations[pline], l=lat, width=pw,
        bottleneck_width=float(pw[k]), bottleneck_index=k,
        length=float(np.hypot(seg[:, 0], seg[:, 1]).sum()),
        graph_xy=vxy, graph_s=stations[iv_line], graph_l=mid, graph_width=width,
        graph_line=iv_line, graph_lo=iv_lo, graph_hi=iv_hi, arcs=arcs, path=path,
        start_xy=start, params=params, arc_direct=graph.direct, links=graph.link[steps],
        band_lo=band_lo, band_hi=band_hi, separation=kept,
    )
    logger.debug("roadmap: %d lines, %d vertices, %d arcs, bottleneck %.2f m at s=%.1f m",
                 nline, len(vxy), len(arcs), out.bottleneck_width, out.bottleneck_s)
    return out if params.place else out.at_midpoints()


# -- where the chosen vertices stand -----------------------------------------------------
#: Largest lateral change [m per m of station] by which a vertex's offset follows the
#: separation that a vertex ahead or behind must keep (:func:`place_vertices`): a lane
#: change over 16 m.
PLACE_RATE = 0.2
#: Room [m] that the offset of most separation from the obstacles leaves to a road edge's
#: end of the interval (the footprint's turns and the curve's rounding need some).
PLACE_ROAD_RESERVE = 0.1
#: Stretch [m] before and after a vertex over which its separation from the obstacles
#: holds (:func:`place_vertices`): a cubic B-spline rounds the corner where the vertices
#: reach that offset, and the rounding must lie off the obstacle's side.
PLACE_HOLD = 4.0
#: Share of a vertex's separation from the obstacles (beyond the grown obstacles) that its
#: band keeps: the rest may go to a control polygon with fewer, straighter legs.
BAND_KEEP = 0.9


def _road_give(corridor: Corridor, lines: _Lines, line: NDArray[np.int64], lo: FloatArray,
               hi: FloatArray, obstacles: Obstacles, params: RoadmapParams
               ) -> tuple[FloatArray, FloatArray]:
    """How far [m] each end of the chosen path's free intervals ``lo..hi`` ``(m,)`` on
    sweep lines ``line`` could move out, were the road edges grown by the car's half
    width only (no road margin), keeping the obstacles' inflation: ``(m,)``, ``(m,)``
    (0 where a keep offset, not the road, bounds the line, or where that end is an
    obstacle's)."""
    m = len(line)
    if params.road_margin <= 0.0 or m == 0:
        return np.zeros(m), np.zeros(m)
    right, left = corridor.bounds_at(lines.station[line])
    half = params.vehicle_width / 2.0
    lo_road = np.abs(lines.lo[line] - (right + params.road_inflation)) < 1e-6
    hi_road = np.abs(lines.hi[line] - (left - params.road_inflation)) < 1e-6
    wide = _Lines(lines.station[line], lines.center[line], lines.tangent[line],
                  lines.normal[line], np.where(lo_road, right + half, lines.lo[line]),
                  np.where(hi_road, left - half, lines.hi[line]), lines.inflation)
    w_line, w_lo, w_hi = _free_intervals(wide, obstacles, params.inflation)
    give_lo, give_hi = np.zeros(m), np.zeros(m)
    # each interval of the wider lines holds at most one of the path's (the path's lies
    # within one of them): the one whose range covers the path's midpoint
    mid = 0.5 * (lo + hi)
    at = np.flatnonzero((w_lo <= mid[w_line] + 1e-9) & (mid[w_line] <= w_hi + 1e-9))
    j = w_line[at]
    give_lo[j] = np.maximum(lo[j] - w_lo[at], 0.0)
    give_hi[j] = np.maximum(w_hi[at] - hi[j], 0.0)
    return give_lo, give_hi


def place_vertices(corridor: Corridor, lines: _Lines, line: NDArray[np.int64],
                   lo: FloatArray, hi: FloatArray, l0: float, params: RoadmapParams,
                   give_lo: FloatArray | None = None, give_hi: FloatArray | None = None
                   ) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """Lateral offsets ``(m,)`` [m] of the chosen path's vertices in their free intervals
    ``lo..hi`` ``(m,)`` on sweep lines ``line``, the bands ``(m,)``, ``(m,)`` [m] of
    :attr:`Roadmap.band_lo`, ``band_hi``, and :attr:`Roadmap.separation` ``(m,)``.

    The paper's separation is from obstacles and road edges alike, its threshold
    ``wmax`` making widths beyond it equal; a midpoint between a parked car and the kerb
    keeps half of what the car could keep from the car, and a midpoint of an empty
    two-lane road is the lane line. So each vertex stands, in this order of priority:

    1. as far from the obstacles (the interval's ends that an obstacle sets, not the
       road) as the interval allows, up to :attr:`RoadmapParams.enough_separation`;
       where an obstacle sets one end and the road the other, the road's end moves out
       by ``give_lo`` or ``give_hi`` [m] ``(m,)`` (:func:`_road_give`: into the road
       margin, as far as the obstacles' inflation allows; the footprint may then come to
       the road's edge, less :data:`PLACE_ROAD_RESERVE`): the separation from the
       obstacle comes first;
    2. among those offsets, as far from the road edges (the ends the road or the keep
       offsets set) as they allow, up to the safety margin beyond the road margin;
    3. among those, nearest the centre of the route's lane: the lane the vehicle is in
       (nearest ``l0`` [m]) or the one it changed to when that lane's centre was not
       among them, the lane centre nearest it that is. Lanes are ``lane_width`` wide
       across the corridor. In a junction (between two edges' own stretches) lanes do not
       count: the offset of the lane it came from, as near as step 2 allows (the middle of
       step 2's offsets where the path starts in the junction).

    The band of a vertex is the set of step 1 (the control polygon may trade the road's
    separation, not the obstacles'), narrowed to the lane (the footprint inside it)
    where the vertex keeps a lane's centre.
    """
    right, left = corridor.bounds_at(lines.station[line])
    junction = np.zeros(len(line), dtype=np.bool_)
    ends, starts = corridor.edge_ends, corridor.edge_starts
    if len(ends) > 1:
        st = lines.station[line]
        i = np.searchsorted(starts, st, side="right") - 1
        nxt = np.minimum(i + 1, len(starts) - 1)
        junction = (i >= 0) & (i + 1 < len(starts)) & (st > ends[np.maximum(i, 0)]) & (
            st < starts[nxt])
    road_extra = max(params.safety_margin - params.road_margin, 0.0)
    zero = np.zeros(len(line))
    return _place_kernel(_f64(lines.station[line]), _f64(lo), _f64(hi), _f64(lines.lo[line]),
                         _f64(lines.hi[line]), _f64(zero if give_lo is None else give_lo),
                         _f64(zero if give_hi is None else give_hi), _f64(right), _f64(left),
                         junction, float(l0), params.enough_separation, road_extra,
                         float(params.lane_width), float(params.vehicle_width),
                         PLACE_RATE, PLACE_HOLD, PLACE_ROAD_RESERVE, BAND_KEEP)


@njit(cache=True)
def _place_kernel(st: FloatArray, lo_in: FloatArray, hi_in: FloatArray, road_lo: FloatArray,
                  road_hi: FloatArray, give_lo: FloatArray, give_hi: FloatArray,
                  right: FloatArray, left: FloatArray,
                  junction: NDArray[np.bool_], l0: float, enough: float, road_extra: float,
                  lane_width: float, vehicle_width: float, rate: float, hold: float,
                  road_reserve: float, keep: float
                  ) -> tuple[FloatArray, ...]:  # pragma: no cover
    """:func:`place_vertices` along the path (``st``: the lines' stations; ``road_lo``,
    ``road_hi``: the lines' bounds from the road or keep offsets; ``give_lo``,
    ``give_hi``: how far each road-set end may move out for step 1; ``right``, ``left``:
    the road's edges, for the lanes; ``road_extra`` [m]: step 2's cap; ``vehicle_width``
    [m]: for the band in a lane, which keeps the footprint inside it; ``rate``,
    ``hold``, ``road_reserve``, ``keep``: :data:`PLACE_RATE`, :data:`PLACE_HOLD`,
    :data:`PLACE_ROAD_RESERVE`, :data:`BAND_KEEP`)."""
    m = len(lo_in)
    lo, hi = lo_in.copy(), hi_in.copy()
    extra_lo, extra_hi = np.zeros(m), np.zeros(m)
    by_lo, by_hi = np.zeros(m, dtype=np.bool_), np.zeros(m, dtype=np.bool_)
    out = np.empty(m)
    b_lo = np.empty(m)
    b_hi = np.empty(m)
    at_lane = np.zeros(m, dtype=np.bool_)
    lane_tol = np.zeros(m)
    sep = np.empty(m)
    pref = np.nan
    for j in range(m):
        a, b = lo[j], hi[j]
        obs_lo = a > road_lo[j] + 1e-6
        obs_hi = b < road_hi[j] - 1e-6
        by_lo[j], by_hi[j] = obs_lo, obs_hi
        # between an obstacle and the road, the road's margin goes to the obstacle's
        # separation: that end of the interval moves out into the road margin
        if obs_lo and not obs_hi:
            extra_hi[j] = give_hi[j]
            b = hi[j] = b + give_hi[j]
        elif obs_hi and not obs_lo:
            extra_lo[j] = give_lo[j]
            a = lo[j] = a - give_lo[j]
        w = max(b - a, 0.0)
        # step 1: the obstacles' separation
        if obs_lo and obs_hi:
            t = min(w / 2.0, enough)
            a1, b1 = a + t, b - t
        elif obs_lo:
            t = min(max(w - road_reserve, 0.0), enough)
            a1, b1 = a + t, b
        elif obs_hi:
            t = min(max(w - road_reserve, 0.0), enough)
            a1, b1 = a, b - t
        else:
            a1, b1 = a, b
            t = enough
        sep[j] = t
        if b1 < a1:
            a1 = b1 = 0.5 * (a1 + b1)
        # step 2: the road's
        if not obs_lo and not obs_hi:
            t = min((b1 - a1) / 2.0, road_extra)
            a2, b2 = a1 + t, b1 - t
        elif not obs_lo:
            t = min(b1 - a1, road_extra + extra_lo[j])
            a2, b2 = a1 + t, b1
        elif not obs_hi:
            t = min(b1 - a1, road_extra + extra_hi[j])
            a2, b2 = a1, b1 - t
        else:
            a2, b2 = a1, b1
        b_lo[j], b_hi[j] = a1, b1
        if junction[j]:
            # no lanes across a junction: on at the lane's offset, as far as it may
            out[j] = min(max(pref if not np.isnan(pref) else 0.5 * (a2 + b2), a2), b2)
            continue
        # step 3: the route's lane
        width = left[j] - right[j]
        n = max(int(np.floor(width / lane_width + 0.5)), 1)
        lw = width / n
        if np.isnan(pref):
            pref = l0
        k = min(max(int(np.floor((pref - right[j]) / lw)), 0), n - 1)
        c = right[j] + (k + 0.5) * lw
        if not (a2 - 1e-9 <= c <= b2 + 1e-9):
            # the lane centre among the offsets nearest the route's lane, if any
            best = np.inf
            for q in range(n):
                cq = right[j] + (q + 0.5) * lw
                if a2 - 1e-9 <= cq <= b2 + 1e-9 and abs(cq - c) < best:
                    best = abs(cq - c)
                    k = q
            if np.isfinite(best):
                c = right[j] + (k + 0.5) * lw
        if a2 - 1e-9 <= c <= b2 + 1e-9:
            pref = c
            at_lane[j] = True
            lane_tol[j] = max(lw - vehicle_width, 0.0) / 2.0
        out[j] = min(max(c, a2), b2)
    # the road margin taken beside an obstacle is there for ``hold`` [m] before and after
    # it too (where the road bounds that side), so that the vertices reach their offsets
    # there in time
    w_from, w_to = _windows(st, hold)
    for j in range(m):
        for k in range(w_from[j], w_to[j]):
            # (taking it again, for another obstacle line, changes nothing)
            if extra_lo[k] > 0.0 and not by_lo[j]:
                if b_lo[j] <= lo[j] + 1e-9:
                    b_lo[j] = lo_in[j] - give_lo[j]
                lo[j] = lo_in[j] - give_lo[j]
            if extra_hi[k] > 0.0 and not by_hi[j]:
                if b_hi[j] >= hi[j] - 1e-9:
                    b_hi[j] = hi_in[j] + give_hi[j]
                hi[j] = hi_in[j] + give_hi[j]
    # the separation a vertex ahead or behind must reach bounds this one's offset by
    # ``rate`` per metre between them, so that the vertices leave the lane in time
    low, high = b_lo.copy(), b_hi.copy()
    # each vertex's separation held over ``hold`` [m] before and after it
    for j in range(m):
        for k in range(w_from[j], w_to[j]):
            low[j] = max(low[j], b_lo[k])
            high[j] = min(high[j], b_hi[k])
    for j in range(1, m):
        low[j] = max(low[j], low[j - 1] - rate * (st[j] - st[j - 1]))
        high[j] = min(high[j], high[j - 1] + rate * (st[j] - st[j - 1]))
    for j in range(m - 2, -1, -1):
        low[j] = max(low[j], low[j + 1] - rate * (st[j + 1] - st[j]))
        high[j] = min(high[j], high[j + 1] + rate * (st[j + 1] - st[j]))
    for j in range(m):
        if low[j] > high[j]:
            # the separations ahead and behind ask for more than the rate allows: between
            # them, within this vertex's own
            v = min(max(0.5 * (low[j] + high[j]), b_lo[j]), b_hi[j])
            low[j] = high[j] = v
        low[j], high[j] = min(max(low[j], lo[j]), hi[j]), min(max(high[j], lo[j]), hi[j])
        v = min(max(out[j], low[j]), high[j])
        # the band: a share of the separation may go to a smoother polygon
        give = (1.0 - keep) * sep[j]
        b_lo[j], b_hi[j] = max(low[j] - give, lo[j]), min(high[j] + give, hi[j])
        if at_lane[j] and abs(v - out[j]) < 1e-9:
            b_lo[j] = max(b_lo[j], v - lane_tol[j])
            b_hi[j] = min(b_hi[j], v + lane_tol[j])
        out[j] = v
    # the separation each vertex keeps from the obstacles beside it (0: none beside it)
    kept = np.zeros(m)
    for j in range(m):
        if by_lo[j] or by_hi[j]:
            kept[j] = enough
            if by_lo[j]:
                kept[j] = min(kept[j], out[j] - lo[j])
            if by_hi[j]:
                kept[j] = min(kept[j], hi[j] - out[j])
            kept[j] = max(kept[j], 0.0)
    return out, b_lo, b_hi, kept


@njit(cache=True)
def _windows(st: FloatArray, hold: float
             ) -> tuple[NDArray[np.int64], NDArray[np.int64]]:  # pragma: no cover
    """For each of the ascending stations ``st`` [m], the index range ``[from, to)`` of
    those within ``hold`` [m] of it."""
    m = len(st)
    w_from, w_to = np.empty(m, dtype=np.int64), np.empty(m, dtype=np.int64)
    a = b = 0
    for j in range(m):
        while st[a] < st[j] - hold:
            a += 1
        while b < m and st[b] <= st[j] + hold:
            b += 1
        w_from[j], w_to[j] = a, b
    return w_from, w_to


# -- construction of the graph ---------------------------------------------------------
@dataclass(frozen=True)
class _Lines:
    """Sweep lines: station ``(n,)`` [m], centre on the reference, unit tangent and normal
    ``(n, 2)``, lateral range ``lo..hi`` ``(n,)`` [m] of the shrunk road, the inflation [m]."""

    station: FloatArray
    center: FloatArray
    tangent: FloatArray
    normal: FloatArray
    lo: FloatArray
    hi: FloatArray
    inflation: float


def _f64(a: ArrayLike) -> FloatArray:
    """A contiguous float64 array (the one array type the compiled loops take)."""
    return kernel_floats(a)


def _check_start(corridor: Corridor, s0: float, l0: float) -> None:
    tol = 1e-6
    if s0 < -tol or s0 > corridor.length + tol:
        raise GeometryError(
            f"start at station {corridor.offset + s0:.1f} m is outside the corridor "
            f"[{corridor.offset:.1f}, {corridor.offset + corridor.length:.1f}] m"
        )
    right, left = (float(v) for v in corridor.bounds_at(s0))
    off = max(right - l0, l0 - left)
    if off > MAX_START_OFFROAD:
        raise GeometryError(
            f"start is {off:.1f} m off the road at station {corridor.offset + s0:.1f} m "
            f"(at most {MAX_START_OFFROAD:.1f} m allowed)"
        )


def _stations(length: float, d: float) -> FloatArray:
    """Stations ``0, d, 2d, ...`` and the end; a last gap shorter than ``d / 2`` is merged
    into the one before (a very short last step would end level 3's curve on a kink)."""
    n = math.floor(length / d + 1e-9)
    s = np.arange(n + 1, dtype=float) * d
    if length - s[-1] > 1e-6:
        if length - s[-1] < d / 2.0 and len(s) > 1:
            s[-1] = length
        else:
            s = np.append(s, length)
    else:
        s[-1] = min(s[-1], length)
    return np.asarray(s, dtype=float)


#: Stretch [m] ahead of the start over which the corridor's keep offsets do not bind: a
#: vehicle that starts in another lane needs room to change lanes.
KEEP_GRACE = 10.0
#: Where the keep offsets leave no passage (an obstacle on the route's lanes), they are
#: released over this stretch [m] from the first line that no path reached, and widened
#: each side by :data:`RELEASE_TAPER` metres per metre for :data:`RELEASE_REACH` metres
#: before and after it: the widest path then moves to the passing lane gradually (at half
#: the taper: a lane change over about 45 m) and back into its lane after the obstacle.
RELEASE_AFTER = 10.0
RELEASE_TAPER = 0.15
RELEASE_REACH = 50.0
#: Stretches released one after another before the keep offsets are dropped altogether.
RELEASE_TRIES = 8


def _sweep_lines(corridor: Corridor, stations: FloatArray, r: float, *,
                 keep_from: float = 0.0,
                 released: tuple[tuple[float, float], ...] = ()) -> _Lines:
    """Sweep lines; the vehicle's centre keeps within the shrunk road and, from station
    ``keep_from`` on and where they leave room, within the corridor's keep offsets, which
    the stretches ``released`` (from, to [m]) widen (see :data:`RELEASE_AFTER`)."""
    h = corridor.heading_at(stations)
    tangent = np.column_stack((np.cos(h), np.sin(h)))
    normal = np.column_stack((-tangent[:, 1], tangent[:, 0]))
    center = corridor.to_xy(stations, np.zeros_like(stations))
    right, left = corridor.bounds_at(stations)
    lo, hi = right + r, left - r
    if corridor.keep_left is not None:
        k_lo, k_hi = corridor.keep_at(stations)
        for a, b in released:
            away = np.maximum(np.maximum(a - stations, stations - b), 0.0)
            wider = RELEASE_TAPER * np.maximum(RELEASE_REACH - away, 0.0)
            k_lo, k_hi = k_lo - wider, k_hi + wider
        k_lo, k_hi = np.maximum(lo, k_lo), np.minimum(hi, k_hi)
        use = (stations >= keep_from) & (k_lo <= k_hi)
        lo, hi = np.where(use, k_lo, lo), np.where(use, k_hi, hi)
    return _Lines(stations, center, tangent, normal, lo, hi, r)


def _cull(
    seg_a: FloatArray, seg_b: FloatArray, bbox: FloatArray, r: float
) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """Pairs (segment, obstacle) whose bounding boxes come within ``r`` of each other,
    sorted by segment, then obstacle.

    Obstacles are sorted along the axis on which the segments spread most; each segment
    tests only the obstacles whose extent on that axis can reach it.
    """
    if len(seg_a) == 0 or len(bbox) == 0:
        return np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64)
    return _cull_kernel(_f64(seg_a), _f64(seg_b), _f64(bbox), float(r))


@njit(cache=True)
def _cull_kernel(seg_a: FloatArray, seg_b: FloatArray, bbox: FloatArray, r: float
                 ) -> tuple[NDArray[np.int64], NDArray[np.int64]]:  # pragma: no cover - compiled
    """:func:`_cull`: each segment's candidates ``order[first:last]`` along the sorting
    axis, box-tested."""
    lo = np.minimum(seg_a, seg_b) - r
    hi = np.maximum(seg_a, seg_b) + r
    spread0 = hi[:, 0].max() - lo[:, 0].min()
    spread1 = hi[:, 1].max() - lo[:, 1].min()
    ax = 1 if spread1 > spread0 else 0
    # a contiguous copy: the same sort as _free_kernel's, compiled once
    order = np.argsort(bbox[:, ax].copy(), kind="mergesort")
    bmin = bbox[order, ax]
    reach = (bbox[:, ax + 2] - bbox[:, ax]).max()
    first = np.searchsorted(bmin, lo[:, ax] - reach, side="left")
    last = np.searchsorted(bmin, hi[:, ax], side="right")
    n = len(lo)
    total = 0
    for i in range(n):
        total += max(last[i] - first[i], 0)
    out_i = np.empty(total, dtype=np.int64)
    out_j = np.empty(total, dtype=np.int64)
    m = 0
    for i in range(n):
        start = m
        for c in range(first[i], last[i]):
            j = order[c]
            if (lo[i, 0] <= bbox[j, 2] and hi[i, 0] >= bbox[j, 0]
                    and lo[i, 1] <= bbox[j, 3] and hi[i, 1] >= bbox[j, 1]):
                # insertion keeps the segment's obstacles sorted
                k = m
                while k > start and out_j[k - 1] > j:
                    out_j[k] = out_j[k - 1]
                    k -= 1
                out_j[k] = j
                out_i[m] = i
                m += 1
    return out_i[:m], out_j[:m]


def _expand_edges(
    group: NDArray[np.int64], obstacle: NDArray[np.int64], offsets: NDArray[np.int64]
) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """For each (group, obstacle) pair, one row per obstacle edge: (group, edge index)."""
    counts = offsets[obstacle + 1] - offsets[obstacle]
    rep = np.repeat(np.arange(len(group)), counts)
    first = np.repeat(np.cumsum(counts) - counts, counts)
    edge = offsets[obstacle][rep] + (np.arange(len(rep)) - first)
    return group[rep], edge


def _free_intervals(
    lines: _Lines, obstacles: Obstacles, r: float
) -> tuple[NDArray[np.int64], FloatArray, FloatArray]:
    """Free intervals of all sweep lines: line index, lower and upper lateral offset [m].

    Sorted by line, then offset. Blocked are the points within ``r`` of an obstacle's
    boundary (the union of its edges' capsules) and the points inside it.
    """
    open_line = lines.hi >= lines.lo
    li = ob = np.zeros(0, dtype=np.int64)
    if len(obstacles):
        a_xy = lines.center + np.minimum(lines.lo, lines.hi)[:, None] * lines.normal
        b_xy = lines.center + lines.hi[:, None] * lines.normal
        li, ob = _cull(a_xy, b_xy, obstacles.bbox, r)
        keep = open_line[li]
        li, ob = li[keep], ob[keep]
    span = float(np.max(lines.hi - lines.lo, initial=0.0)) + 4.0
    c, t, n = lines.center, lines.tangent, lines.normal
    vert = obstacles.vertices
    return _free_kernel(
        li, ob, kernel_floats(c[:, 0]), kernel_floats(c[:, 1]),
        kernel_floats(t[:, 0]), kernel_floats(t[:, 1]),
        kernel_floats(n[:, 0]), kernel_floats(n[:, 1]),
        _f64(lines.lo), _f64(lines.hi), _f64(vert[:, 0]), _f64(vert[:, 1]),
        kernel_ints(obstacles.offsets), float(r), span)


@njit(cache=True)
def _slab(a: float, b: float, lo: float,
          hi: float) -> tuple[float, float]:  # pragma: no cover - compiled
    """Solutions v of ``lo <= a + b v <= hi`` as an interval (empty: lower > upper)."""
    if abs(b) < 1e-12:
        if a >= lo and a <= hi:
            return -np.inf, np.inf
        return np.inf, -np.inf
    x1, x2 = (lo - a) / b, (hi - a) / b
    return min(x1, x2), max(x1, x2)


@njit(cache=True)
def _capsule_on_line(ua: float, va: float, ub: float, vb: float,
                     r: float) -> tuple[float, float]:  # pragma: no cover - compiled
    """Where the line ``u = 0`` comes within ``r`` of the segment ``(ua, va) -> (ub, vb)``.

    Returns the ``v`` bounds of a closed interval (lower > upper: no contact). The capsule
    is convex, so its trace is the hull of the traces of its three parts.
    """
    lo = np.inf
    hi = -np.inf
    h2 = r * r - ua * ua
    if h2 >= 0:
        h = np.sqrt(h2)
        lo = min(lo, va - h)
        hi = max(hi, va + h)
    h2 = r * r - ub * ub
    if h2 >= 0:
        h = np.sqrt(h2)
        lo = min(lo, vb - h)
        hi = max(hi, vb + h)
    du, dv = ub - ua, vb - va
    ln = np.hypot(du, dv)
    if ln > 0:
        eu, ev = du / ln, dv / ln
        l1, h1 = _slab(ua * ev - eu * va, eu, -r, r)  # distance across the segment
        l2, h2 = _slab(-ua * eu - ev * va, ev, 0.0, ln)  # projection onto the segment
        sl, sh = max(l1, l2), min(h1, h2)
        if sl <= sh:
            lo = min(lo, sl)
            hi = max(hi, sh)
    return lo, hi


@njit(cache=True)
def _free_kernel(li: NDArray[np.int64], ob: NDArray[np.int64], cx: FloatArray, cy: FloatArray,
                 tx: FloatArray, ty: FloatArray, nx: FloatArray, ny: FloatArray,
                 lo: FloatArray, hi: FloatArray, vx: FloatArray, vy: FloatArray,
                 offsets: NDArray[np.int64], r: float, span: float
                 ) -> tuple[NDArray[np.int64], FloatArray,
                            FloatArray]:  # pragma: no cover - compiled
    """Free intervals of the lines given the (line, obstacle) pairs ``li``, ``ob`` (sorted
    by line, then obstacle) that can block them; see :func:`_free_intervals`.

    Per line, blocked are the edges' capsules (in pair and edge order) and, between
    pairs of the polygon's boundary crossings sorted along the line, its interior; they
    are sorted by their start (stable) and merged, and the gaps between them are free.
    """
    nline = len(lo)
    npair = len(li)
    nedge = 0
    for p in range(npair):
        nedge += offsets[ob[p] + 1] - offsets[ob[p]]
    cap = nline + 2 * nedge + 1
    f_line = np.empty(cap, dtype=np.int64)
    f_lo = np.empty(cap)
    f_hi = np.empty(cap)
    nf = 0
    b_lo = np.empty(2 * nedge + 1)
    b_hi = np.empty(2 * nedge + 1)
    rel_lo = np.empty(2 * nedge + 1)
    rel_hi = np.empty(2 * nedge + 1)
    cross = np.empty(nedge + 1)
    eu_a, ev_a = np.empty(nedge + 1), np.empty(nedge + 1)
    eu_b, ev_b = np.empty(nedge + 1), np.empty(nedge + 1)
    run = -np.inf
    p = 0
    for k in range(nline):
        p0 = p
        while p < npair and li[p] == k:
            p += 1
        if hi[k] < lo[k]:
            continue
        lo_k, hi_k = lo[k], hi[k]
        nb = 0
        for q in range(p0, p):  # the capsules; the edges in the line's frame, kept
            for e in range(offsets[ob[q]], offsets[ob[q] + 1]):
                e1 = e + 1 if e + 1 < offsets[ob[q] + 1] else offsets[ob[q]]
                wax, way = vx[e] - cx[k], vy[e] - cy[k]
                wbx, wby = vx[e1] - cx[k], vy[e1] - cy[k]
                eu_a[nb] = wax * tx[k] + way * ty[k]
                ev_a[nb] = wax * nx[k] + way * ny[k]
                eu_b[nb] = wbx * tx[k] + wby * ty[k]
                ev_b[nb] = wbx * nx[k] + wby * ny[k]
                b_lo[nb], b_hi[nb] = _capsule_on_line(eu_a[nb], ev_a[nb], eu_b[nb],
                                                      ev_b[nb], r)
                nb += 1
        g = 0  # the kept edges, in the same order
        for q in range(p0, p):  # the interiors
            nc = 0
            for _ in range(offsets[ob[q]], offsets[ob[q] + 1]):
                ua, va, ub, vb = eu_a[g], ev_a[g], eu_b[g], ev_b[g]
                g += 1
                if (ua > 0) != (ub > 0):
                    cross[nc] = va + (0.0 - ua) * (vb - va) / (ub - ua)
                    nc += 1
            cv = np.sort(cross[:nc])
            for c in range(0, nc - 1, 2):
                b_lo[nb], b_hi[nb] = cv[c], cv[c + 1]
                nb += 1
        # blocked sets are open intervals; only those that cut into [lo, hi] matter
        m = 0
        for i in range(nb):
            if b_hi[i] > b_lo[i] and b_hi[i] > lo_k and b_lo[i] < hi_k:
                rel_lo[m] = max(b_lo[i] - lo_k, -1.0)
                rel_hi[m] = min(b_hi[i] - lo_k, hi_k - lo_k + 1.0)
                m += 1
        if m == 0:
            f_line[nf], f_lo[nf], f_hi[nf] = k, lo_k, hi_k
            nf += 1
            continue
        order = np.argsort(rel_lo[:m], kind="mergesort")
        base = k * span
        for i in order:
            prev_end = max(run - base, 0.0)  # free from here (relative to lo) ...
            if rel_lo[i] - prev_end >= 0 and rel_lo[i] + lo_k >= prev_end + lo_k:
                f_line[nf], f_lo[nf], f_hi[nf] = k, prev_end + lo_k, rel_lo[i] + lo_k
                nf += 1  # ... up to the next blocked interval's start
            run = max(run, rel_hi[i] + base)
        tail = max(run - base, 0.0) + lo_k  # after the line's last blocked interval
        if hi_k >= tail:
            f_line[nf], f_lo[nf], f_hi[nf] = k, tail, hi_k
            nf += 1
    return f_line[:nf].copy(), f_lo[:nf].copy(), f_hi[:nf].copy()


#: Where, as fractions of the common lateral range of two intervals, the link between
#: them is tried when the straight segment between their midpoints is not free.
_OVERLAP_TRIES = (0.5, 0.25, 0.75, 0.05, 0.95)
#: Fractions ``t`` of segments from ``lo + t w`` on one line to ``lo + t w`` on the next.
_PROPORTIONAL_TRIES = (0.25, 0.75, 0.05, 0.95)


@dataclass(frozen=True)
class _Arcs:
    """Arcs ``(E, 2)``, their lengths [m] between the vertices, whether that straight
    segment is free, and the free link ``(E, 2, 2)`` [m] found between the two lines."""

    pairs: NDArray[np.int64]
    length: FloatArray
    direct: NDArray[np.bool_]
    link: FloatArray


def _arcs(
    corridor: Corridor, lines: _Lines, vline: NDArray[np.int64], vlo: FloatArray,
    vhi: FloatArray, obstacles: Obstacles, r: float,
) -> _Arcs:
    """Arcs between vertices of consecutive lines that the vehicle can pass between.

    The passage from vertex ``a`` (line k) to vertex ``b`` (line k + 1) is: along line k
    inside ``a``'s free interval to a point ``p``, straight to a point ``q`` of ``b``'s
    interval on line k + 1, along that line to ``b``. Moving inside a free interval is
    free, so the arc exists when some straight link ``p -> q`` is free. Tried in turn: the
    midpoints themselves (then the polyline of vertices is free there), links at constant
    lateral offset across the intervals' common range, and links joining the same
    fraction of both intervals.
    """
    nline = len(lines.lo)
    nband = max(nline - 1, 0)
    vline = kernel_ints(vline)
    head, tail = _arc_pairs(vline, nband)
    be, edge = _band_edges(lines, obstacles, r, nband)
    start, end, _ = polygon_edges(obstacles.vertices, obstacles.offsets)
    geo = (head, tail, vline, _f64(vlo), _f64(vhi), _f64(lines.center[:, 0]),
           _f64(lines.center[:, 1]), _f64(lines.normal[:, 0]), _f64(lines.normal[:, 1]),
           _TRIES, np.searchsorted(be, np.arange(nband + 1)).astype(np.int64),
           _f64(start[edge, 0]), _f64(start[edge, 1]), _f64(end[edge, 0]),
           _f64(end[edge, 1]), float(r))
    bent = _bent_bands(corridor, lines.station)
    # first the midpoints, then every other try at once for the arcs still missing
    band = vline[head]
    idx0 = np.arange(len(head), dtype=np.int64)
    p0, q0, clear = _links_kernel(idx0, np.zeros(len(head), dtype=np.int64), *geo)
    direct = clear & _within_road(corridor, lines, bent, band, p0, q0, need=clear)
    idx, tri = _retries(direct, *geo[:5], len(_OVERLAP_TRIES), len(_TRIES))
    p, q, clear = _links_kernel(idx, tri, *geo)
    ok = clear & _within_road(corridor, lines, bent, band[idx], p, q, need=clear)
    pairs, length, direct, link = _gather(head, tail, direct, p0, q0, idx, ok, p, q)
    return _Arcs(pairs, length, direct, link)


@njit(cache=True)
def _arc_pairs(vline: NDArray[np.int64], nband: int) -> tuple[
        NDArray[np.int64], NDArray[np.int64]]:  # pragma: no cover - compiled
    """Every pair (head, tail) of vertices on lines k and k + 1 ``k < nband`` (vertices
    sorted by line), by band, then head, then tail."""
    first = np.searchsorted(vline, np.arange(nband + 2))
    n = 0
    for k in range(nband):
        n += (first[k + 1] - first[k]) * (first[k + 2] - first[k + 1])
    head = np.empty(n, dtype=np.int64)
    tail = np.empty(n, dtype=np.int64)
    m = 0
    for k in range(nband):
        for a in range(first[k], first[k + 1]):
            for b in range(first[k + 1], first[k + 2]):
                head[m], tail[m] = a, b
                m += 1
    return head, tail


@njit(cache=True)
def _retries(direct: NDArray[np.bool_], head: NDArray[np.int64], tail: NDArray[np.int64],
             vline: NDArray[np.int64], vlo: FloatArray, vhi: FloatArray, n_overlap: int,
             n_tries: int) -> tuple[NDArray[np.int64],
                                    NDArray[np.int64]]:  # pragma: no cover - compiled
    """The arcs without a direct link, and the tries left for them, try by try (the
    constant-offset tries only where the two intervals share a lateral range)."""
    rest = np.flatnonzero(~direct)
    idx = np.empty(len(rest) * (n_tries - 1), dtype=np.int64)
    tri = np.empty(len(rest) * (n_tries - 1), dtype=np.int64)
    m = 0
    for t in range(1, n_tries):
        for i in rest:
            a, b = head[i], tail[i]
            if t > n_overlap or min(vhi[a], vhi[b]) >= max(vlo[a], vlo[b]):
                idx[m], tri[m] = i, t
                m += 1
    return idx[:m], tri[:m]


@njit(cache=True)
def _gather(head: NDArray[np.int64], tail: NDArray[np.int64], direct: NDArray[np.bool_],
            p0: FloatArray, q0: FloatArray, idx: NDArray[np.int64], ok: NDArray[np.bool_],
            p: FloatArray, q: FloatArray) -> tuple[NDArray[np.int64], FloatArray,
                                                   NDArray[np.bool_],
                                                   FloatArray]:  # pragma: no cover - compiled
    """The arcs found: direct ones (link ``p0 -> q0``, the midpoints) and those with a
    free retry (the first in try order); their pairs, lengths between the midpoints,
    whether direct, and links ``(E, 2, 2)``."""
    n = len(head)
    pick = np.full(n, -1, dtype=np.int64)
    for c in range(len(idx)):
        if ok[c] and pick[idx[c]] < 0:
            pick[idx[c]] = c
    ne = 0
    for i in range(n):
        if direct[i] or pick[i] >= 0:
            ne += 1
    pairs = np.empty((ne, 2), dtype=np.int64)
    length = np.empty(ne)
    is_direct = np.empty(ne, dtype=np.bool_)
    link = np.empty((ne, 2, 2))
    e = 0
    for i in range(n):
        if not (direct[i] or pick[i] >= 0):
            continue
        pairs[e, 0], pairs[e, 1] = head[i], tail[i]
        length[e] = np.hypot(q0[i, 0] - p0[i, 0], q0[i, 1] - p0[i, 1])
        is_direct[e] = direct[i]
        src_p, src_q, j = (p0, q0, i) if direct[i] else (p, q, pick[i])
        link[e, 0, 0], link[e, 0, 1] = src_p[j, 0], src_p[j, 1]
        link[e, 1, 0], link[e, 1, 1] = src_q[j, 0], src_q[j, 1]
        e += 1
    return pairs, length, is_direct, link


#: Every try of :func:`_arcs` as (kind, fraction): 0 the midpoints, 1 constant lateral
#: offset across the common range, 2 the same fraction of both intervals.
_TRIES = np.array([(0.0, 0.0)] + [(1.0, f) for f in _OVERLAP_TRIES]
                  + [(2.0, f) for f in _PROPORTIONAL_TRIES])


@njit(cache=True)
def _links_kernel(idx: NDArray[np.int64], tri: NDArray[np.int64], head: NDArray[np.int64],
                  tail: NDArray[np.int64], vline: NDArray[np.int64], vlo: FloatArray,
                  vhi: FloatArray, cx: FloatArray, cy: FloatArray, nx: FloatArray,
                  ny: FloatArray, tries: FloatArray, e_first: NDArray[np.int64],
                  ax: FloatArray, ay: FloatArray, bx: FloatArray, by: FloatArray,
                  r: float) -> tuple[FloatArray, FloatArray,
                                     NDArray[np.bool_]]:  # pragma: no cover - compiled
    """Links ``p -> q`` ``(n, 2)`` of try ``tri`` of arcs ``idx`` (vertex ``head`` to
    vertex ``tail``, free intervals ``vlo..vhi``), and whether each keeps ``r`` from the
    obstacle edges ``a -> b`` near its band (edges of band k: ``e_first[k]:e_first[k +
    1]``); exact segment-to-segment distances."""
    n = len(idx)
    p = np.empty((n, 2))
    q = np.empty((n, 2))
    clear = np.ones(n, dtype=np.bool_)
    for c in range(n):
        a, b = head[idx[c]], tail[idx[c]]
        k = vline[a]
        kind, f = tries[tri[c], 0], tries[tri[c], 1]
        if kind == 0.0:
            la, lb = (vlo[a] + vhi[a]) / 2.0, (vlo[b] + vhi[b]) / 2.0
        elif kind == 1.0:
            c_lo, c_hi = max(vlo[a], vlo[b]), min(vhi[a], vhi[b])
            la = lb = c_lo + f * (c_hi - c_lo)
        else:
            la, lb = vlo[a] + f * (vhi[a] - vlo[a]), vlo[b] + f * (vhi[b] - vlo[b])
        px, py = cx[k] + la * nx[k], cy[k] + la * ny[k]
        qx, qy = cx[k + 1] + lb * nx[k + 1], cy[k + 1] + lb * ny[k + 1]
        p[c, 0], p[c, 1], q[c, 0], q[c, 1] = px, py, qx, qy
        for e in range(e_first[k], e_first[k + 1]):
            near = (min(px, qx) - r <= max(ax[e], bx[e]) and max(px, qx) + r >= min(ax[e], bx[e])
                    and min(py, qy) - r <= max(ay[e], by[e])
                    and max(py, qy) + r >= min(ay[e], by[e]))
            if near and _segment_distance(px, py, qx, qy, ax[e], ay[e], bx[e], by[e]) < r - _EPS:
                clear[c] = False
                break
    return p, q, clear


def _band_edges(
    lines: _Lines, obstacles: Obstacles, r: float, nband: int
) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """Obstacle edges near each band between consecutive lines: (band, edge), by band."""
    if len(obstacles) == 0 or nband == 0:
        return np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64)
    lo_l = np.minimum(lines.lo, lines.hi)
    ends = np.stack((lines.center + lo_l[:, None] * lines.normal,
                     lines.center + lines.hi[:, None] * lines.normal))
    lo = np.minimum(ends[:, :-1].min(axis=0), ends[:, 1:].min(axis=0))
    hi = np.maximum(ends[:, :-1].max(axis=0), ends[:, 1:].max(axis=0))
    bi, ob = _cull(lo, hi, obstacles.bbox, r)
    be, edge = _expand_edges(bi, ob, obstacles.offsets)
    order = np.argsort(be, kind="stable")
    return be[order], edge[order]


@njit(cache=True)
def _point_segment(px: float, py: float, ax: float, ay: float, bx: float,
                   by: float) -> float:  # pragma: no cover - compiled
    """Distance [m] from point ``p`` to segment ``a -> b``."""
    abx, aby = bx - ax, by - ay
    apx, apy = px - ax, py - ay
    den = abx * abx + aby * aby
    t = min(max((apx * abx + apy * aby) / (den if den > 0 else 1.0), 0.0), 1.0)
    return float(np.hypot(apx - t * abx, apy - t * aby))


@njit(cache=True)
def _segment_distance(px: float, py: float, qx: float, qy: float, ax: float, ay: float,
                      bx: float, by: float) -> float:  # pragma: no cover - compiled
    """Distance [m] between segments ``p -> q`` and ``a -> b``."""
    d = min(min(_point_segment(ax, ay, px, py, qx, qy), _point_segment(bx, by, px, py, qx, qy)),
            min(_point_segment(px, py, ax, ay, bx, by), _point_segment(qx, qy, ax, ay, bx, by)))
    pqx, pqy, abx, aby = qx - px, qy - py, bx - ax, by - ay
    o1 = pqx * (ay - py) - pqy * (ax - px)
    o2 = pqx * (by - py) - pqy * (bx - px)
    o3 = abx * (py - ay) - aby * (px - ax)
    o4 = abx * (qy - ay) - aby * (qx - ax)
    return 0.0 if (o1 * o2 < 0) and (o3 * o4 < 0) else d


def _bent_bands(corridor: Corridor, stations: FloatArray) -> NDArray[np.bool_]:
    """Whether the reference line or a boundary offset bends between consecutive
    stations ``(n - 1,)``."""
    s = _f64(corridor.s)
    if len(s) <= 2:
        return np.zeros(max(len(stations) - 1, 0), dtype=bool)
    turn = wrap_angle(np.diff(corridor.heading_at((s[:-1] + s[1:]) / 2.0)))
    return _bent_kernel(s, _f64(turn), _f64(corridor.left), _f64(corridor.right),
                        _f64(stations))


@njit(cache=True)
def _bent_kernel(s: FloatArray, turn: FloatArray, left: FloatArray, right: FloatArray,
                 stations: FloatArray) -> NDArray[np.bool_]:  # pragma: no cover - compiled
    """:func:`_bent_bands` given the reference's turn ``(n - 2,)`` [rad] at each inner
    vertex: whether a vertex where the heading or a boundary's slope changes lies
    strictly between consecutive stations."""
    n = len(s)
    count = np.zeros(n + 1, dtype=np.int64)  # kinks among vertices 0 .. i - 1
    for i in range(n):
        kink = False
        if 0 < i < n - 1:
            d0, d1 = s[i] - s[i - 1], s[i + 1] - s[i]
            kink = (abs(turn[i - 1]) > 1e-12
                    or abs((left[i + 1] - left[i]) / d1 - (left[i] - left[i - 1]) / d0) > 1e-12
                    or abs((right[i + 1] - right[i]) / d1 - (right[i] - right[i - 1]) / d0)
                    > 1e-12)
        count[i + 1] = count[i] + (1 if kink else 0)
    lo = np.searchsorted(s, stations[:-1], side="right")
    hi = np.searchsorted(s, stations[1:], side="left")
    out = np.empty(len(stations) - 1, dtype=np.bool_)
    for b in range(len(out)):
        out[b] = count[hi[b]] - count[lo[b]] > 0
    return out


def _within_road(
    corridor: Corridor, lines: _Lines, bent: NDArray[np.bool_], band: NDArray[np.int64],
    p: FloatArray, q: FloatArray, *, need: NDArray[np.bool_] | None = None,
) -> NDArray[np.bool_]:
    """Whether segments ``p -> q`` between lines ``band`` and ``band + 1`` stay on the
    shrunk road. Both ends do by construction; where the reference line and the boundary
    offsets are straight over the band the shrunk road is convex there and nothing is
    left to check; elsewhere the segment is checked at points at most
    ``REFERENCE_SPACING / 2`` apart (as many for every segment, the longest setting the
    spacing); with ``need``, only those segments are checked (the others count as on the
    road)."""
    ok = np.ones(len(band), dtype=bool)
    sel = np.flatnonzero(bent[band]) if len(band) else np.zeros(0, dtype=np.int64)
    if len(sel) == 0:
        return ok
    gap = float(np.max(np.hypot(*(q[sel] - p[sel]).T)))
    m = max(2, math.ceil(gap / (REFERENCE_SPACING / 2.0)))
    if need is not None:
        sel = sel[need[sel]]
        if len(sel) == 0:
            return ok
    f = np.arange(1, m) / m
    pts = p[sel, None, :] + f[None, :, None] * (q[sel] - p[sel])[:, None, :]
    sl = corridor.to_sl(pts.reshape(-1, 2))
    right, left = corridor.bounds_at(sl[:, 0])
    r = lines.inflation
    inside = (sl[:, 1] >= right + r - _EPS) & (sl[:, 1] <= left - r + _EPS)
    ok[sel] = inside.reshape(len(sel), m - 1).all(axis=1)
    return ok


# -- search ------------------------------------------------------------------------------
def _search(
    source: int, arcs: NDArray[np.int64], arc_len: FloatArray, width: FloatArray,
    vline: NDArray[np.int64], nline: int, wmax: float,
) -> tuple[NDArray[np.int64] | None, NDArray[np.int64] | None, int]:
    """Widest (capped at ``wmax``), then shortest path from ``source`` to the last line.

    Arcs run from line k to line k + 1 only, so visiting them by line is a topological
    order: one pass computes each vertex's best bottleneck, a second the shortest path
    through vertices at least as wide as the capped optimum. Returns the path's vertices
    and arcs (or None, None) and the last line that some path reaches.
    """
    order = (np.argsort(vline[arcs[:, 0]], kind="stable") if len(arcs)
             else np.zeros(0, dtype=np.int64))
    a_from = kernel_ints(arcs[order, 0])
    a_to = kernel_ints(arcs[order, 1])
    path, steps, reached = _search_kernel(
        int(source), a_from, a_to, kernel_floats(arc_len[order]),
        order.astype(np.int64), kernel_floats(width),
        kernel_ints(vline), int(nline), float(wmax))
    if reached < nline - 1:
        return None, None, int(reached)
    return path, steps, nline - 1


@njit(cache=True)
def _search_kernel(source: int, a_from: NDArray[np.int64], a_to: NDArray[np.int64],
                   a_len: FloatArray, a_idx: NDArray[np.int64], w: FloatArray,
                   vline: NDArray[np.int64], nline: int, wmax: float
                   ) -> tuple[NDArray[np.int64], NDArray[np.int64],
                              int]:  # pragma: no cover - compiled
    """:func:`_search` over arcs in topological order (``a_idx``: their indices in the
    caller's arcs). Returns the path's vertices, its arcs and the last line reached (the
    path is empty when that is not the last line)."""
    nv = len(w)
    best = np.full(nv, -np.inf)
    best[source] = w[source]
    for e in range(len(a_from)):
        u, v = a_from[e], a_to[e]
        bu = best[u]
        if bu > best[v]:
            cand = bu if bu < w[v] else w[v]
            if cand > best[v]:
                best[v] = cand
    top = -np.inf
    reached = -1
    for v in range(nv):
        if np.isfinite(best[v]):
            reached = max(reached, vline[v])
            if vline[v] == nline - 1 and best[v] > top:
                top = best[v]
    empty = np.zeros(0, dtype=np.int64)
    if reached < nline - 1 or not np.isfinite(top):
        return empty, empty, reached
    target = min(top, wmax)
    dist = np.full(nv, np.inf)
    pred = np.full(nv, -1, dtype=np.int64)
    dist[source] = 0.0
    for e in range(len(a_from)):
        u, v = a_from[e], a_to[e]
        if w[v] >= target and dist[u] + a_len[e] < dist[v]:
            dist[v] = dist[u] + a_len[e]
            pred[v] = e
    end = -1
    d_end = np.inf
    for v in range(nv):
        if vline[v] == nline - 1 and (end < 0 or dist[v] < d_end):
            end, d_end = v, dist[v]
    n = 1
    v = end
    while pred[v] >= 0:
        v = a_from[pred[v]]
        n += 1
    path = np.empty(n, dtype=np.int64)
    steps = np.empty(n - 1, dtype=np.int64)
    v = end
    path[n - 1] = v
    for i in range(n - 2, -1, -1):
        e = pred[v]
        steps[i] = a_idx[e]
        v = a_from[e]
        path[i] = v
    return path, steps, reached


def _raise_blocked(corridor: Corridor, stations: FloatArray, line: int) -> None:
    s = float(stations[line])
    edge = corridor.edge_at(s)
    junction = corridor.junction_at(s)
    where = (f" in the junction from edge {junction[0]!r} onto {junction[1]!r}" if junction
             else f" on edge {edge!r}" if edge is not None else "")
    raise RoadBlockedError(
        f"road blocked at station {corridor.offset + s:.1f} m{where}: "
        f"no passage for the vehicle", station=corridor.offset + s, edge=edge,
        junction=junction)
