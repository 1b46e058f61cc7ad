"""Level 2: sweep-line roadmap, widest-then-shortest search.

Checked against the paper's cases (Fig. 4), an exact geometric check of the free
intervals with shapely, and a raster oracle (tests/oracle.py) on random obstacle fields.
"""

from __future__ import annotations

import itertools

import numpy as np
import pytest
import shapely
from hypothesis import given, settings
from hypothesis import strategies as st
from numpy.typing import NDArray
from oracle import best_clearance
from shapely.geometry import LineString, Polygon

from splineplan.corridor import Corridor
from splineplan.errors import GeometryError, ParameterError, RoadBlockedError
from splineplan.obstacles import Obstacles
from splineplan.roadmap import (
    KEEP_GRACE,
    PLACE_HOLD,
    PLACE_ROAD_RESERVE,
    RELEASE_AFTER,
    RELEASE_REACH,
    Roadmap,
    RoadmapParams,
    plan_roadmap,
)

R_DEFAULT = RoadmapParams().inflation  # 1.2 m: obstacles
R_ROAD = RoadmapParams().road_inflation  # 0.9 m: road edges
#: Level 2 as the raster oracle sees it: road edges grown as much as the obstacles.
EVEN = {"road_margin": RoadmapParams().safety_margin, "place": True}
#: Level 2 with its chosen vertices placed for the separation and the lane.
PLACED = RoadmapParams(place=True)


# -- scenarios ---------------------------------------------------------------------------
def straight(length: float = 100.0, left: float = 4.8, right: float = -4.8, **kw) -> Corridor:
    ref = np.array([[0.0, 0.0], [length, 0.0]])
    return Corridor.from_reference(ref, [left] * 2, [right] * 2, **kw)


def open_road(corridor: Corridor) -> Polygon:
    """The road of a straight corridor along +x, extended 3 m beyond both ends (the ends
    are no walls)."""
    right, left = corridor.bounds_at([0.0, corridor.length])
    x0, x1 = -3.0, corridor.length + 3.0
    return Polygon([(x0, right[0]), (x1, right[1]), (x1, left[1]), (x0, left[0])])


def frenet_map(kind: str, length: float, radius: float):
    """Analytic (s, l) -> (x, y) of a straight or circular road (extended straight beyond
    both ends), written independently of Corridor."""
    if kind == "straight":
        def f(s, l):  # noqa: E741
            s, l = np.broadcast_arrays(np.asarray(s, float), np.asarray(l, float))  # noqa: E741
            return np.stack((s, l), -1)
        return f, lambda s: np.zeros_like(np.asarray(s, float))
    sg = 1.0 if kind == "left" else -1.0
    end = length / radius

    def f(s, l):  # noqa: E741
        s, l = np.broadcast_arrays(np.asarray(s, float), np.asarray(l, float))  # noqa: E741
        th = np.clip(s, 0.0, length) / radius
        rad = radius - sg * l
        x = rad * np.sin(th) + np.where(s < 0, s, 0) + np.where(s > length,
                                                                (s - length) * np.cos(end), 0)
        y = sg * (radius - rad * np.cos(th)) + np.where(s > length,
                                                        sg * (s - length) * np.sin(end), 0)
        return np.stack((x, y), -1)
    return f, lambda s: sg * np.clip(np.asarray(s, float), 0.0, length) / radius


def field(seed: int, kind: str, count: int, *, length: float = 60.0, width: float = 9.6,
          radius: float = 40.0):
    """A road with random boxes (random size and heading); the first 8 m stay clear.

    Returns the corridor, the obstacles, the start, and for the oracle the road polygon
    (extended 3 m beyond both ends) and the goal region beyond the end."""
    rng = np.random.default_rng(seed)
    f, head = frenet_map(kind, length, radius)
    s = np.linspace(0.0, length, int(length / 0.25) + 1)
    corridor = Corridor.from_reference(f(s, 0.0), np.full(len(s), width / 2),
                                       np.full(len(s), -width / 2))
    se = np.linspace(-3.0, length + 3.0, int((length + 6.0) / 0.1) + 1)
    road = Polygon(np.concatenate((f(se, -width / 2), f(se[::-1], width / 2))))
    gs = np.linspace(length + 0.5, length + 3.0, 6)
    goal = Polygon(np.concatenate((f(gs, -width / 2), f(gs[::-1], width / 2))))
    os_ = rng.uniform(8.0, length - 5.0, count)
    ol = rng.uniform(-width / 2, width / 2, count)
    oh = head(os_) + rng.uniform(-np.pi / 2, np.pi / 2, count)
    obs = Obstacles.from_boxes(f(os_, ol), oh, rng.uniform(1.0, 4.5, count),
                               rng.uniform(0.5, 1.8, count))
    return corridor, obs, f(0.0, 0.0), road, goal


def beside_obstacles(rm: Roadmap) -> NDArray[np.bool_]:
    """Which chosen vertices lie within ``PLACE_HOLD`` of a placed vertex that keeps a
    separation from an obstacle beside it (where placement may take the road margin)."""
    if not len(rm.separation):
        return np.zeros(len(rm.path), dtype=bool)
    near = np.abs(rm.s[:, None] - rm.s[rm.separation > 0][None, :]) <= PLACE_HOLD + 1e-9
    return np.asarray(near.any(axis=1))


def assert_consistent(rm: Roadmap) -> None:
    """Invariants of a result, re-derived from its own arrays."""
    m = len(rm.path)
    assert m == len(rm.xy) == len(rm.s) == len(rm.l) == len(rm.width)
    np.testing.assert_allclose(rm.graph_l, (rm.graph_lo + rm.graph_hi) / 2)
    # the placed vertices stand in their free intervals and bands; beside an obstacle
    # (separation > 0, held PLACE_HOLD before and after it) placement may take up to the
    # road margin beyond the road's end
    lo, hi = rm.graph_lo[rm.path], rm.graph_hi[rm.path]
    inside = (lo - 1e-9 <= rm.l) & (rm.l <= hi + 1e-9)
    give = rm.params.road_margin + 1e-9
    beside = beside_obstacles(rm)
    assert np.all(inside | (beside & (lo - give <= rm.l) & (rm.l <= hi + give)))
    if len(rm.band_lo):  # placed (RoadmapParams.place)
        assert np.all((rm.band_lo - 1e-9 <= rm.l) & (rm.l <= rm.band_hi + 1e-9))
    np.testing.assert_allclose(rm.width, (rm.graph_hi - rm.graph_lo)[rm.path])
    assert np.all(np.diff(rm.graph_line[rm.path]) == 1)
    assert rm.graph_line[rm.path[-1]] == rm.graph_line.max()
    arcs = {tuple(a) for a in rm.arcs.tolist()}
    assert all((a, b) in arcs for a, b in itertools.pairwise(rm.path.tolist()))
    assert np.all(np.diff(rm.graph_line[rm.arcs], axis=1) == 1)
    assert rm.length == pytest.approx(np.hypot(*np.diff(rm.xy, axis=0).T).sum())
    assert rm.bottleneck_width == pytest.approx(rm.width.min())
    assert rm.width[rm.bottleneck_index] == rm.bottleneck_width
    assert np.all(rm.graph_hi >= rm.graph_lo)
    assert len(rm.links) == m - 1 and len(rm.arc_direct) == len(rm.arcs)


def assert_free(rm: Roadmap, obs: Obstacles, road: Polygon, r: float,
                r_road: float | None = None) -> None:
    """The passage polyline keeps r from every obstacle and ``r_road`` from the road edge
    (shapely). By default ``r_road`` is the roadmap's road inflation; placed vertices
    beside an obstacle may take the road margin, less the reserve they leave
    (``PLACE_ROAD_RESERVE``), for their separation from it: there, and on the passage
    through them, the car's half width and that reserve; the other vertices keep the
    road inflation."""
    beside = beside_obstacles(rm)
    if r_road is None and beside.any():
        edge = road.exterior
        # 1 cm for the corridor's polyline approximation of curved boundaries
        assert all(edge.distance(shapely.Point(p)) >= rm.params.road_inflation - 0.01
                   for p in rm.xy[~beside])
        r_road = rm.params.vehicle_width / 2.0 + PLACE_ROAD_RESERVE
    r_road = rm.params.road_inflation if r_road is None else r_road
    line = LineString(rm.passage_xy) if len(rm.passage_xy) > 1 else shapely.Point(rm.xy[0])
    for poly in obs.polygons():
        assert line.distance(Polygon(poly)) >= r - 1e-6
    # 1 cm for the corridor's polyline approximation of curved boundaries
    assert road.buffer(-(r_road - 0.01)).contains(line)


# -- the paper's cases (Fig. 4) ----------------------------------------------------------
@pytest.mark.parametrize(("left", "right", "lanes"),
                         [(4.8, -4.8, 3), (6.0, -2.0, 3), (3.2, -3.2, 2), (6.4, -6.4, 4),
                          (1.6, -1.6, 1)])
def test_empty_road_keeps_the_centre_of_the_vehicles_lane(left: float, right: float,
                                                           lanes: int) -> None:
    """On an empty road of several lanes the path keeps the centre of the lane the vehicle
    starts in, whichever lane that is (not the middle of the whole road: on two or four
    lanes that is a lane line)."""
    corridor = straight(80.0, left, right)
    w = (left - right) / lanes
    for k in range(lanes):
        centre = right + (k + 0.5) * w
        start = (0.0, centre + 0.3 * w * (-1) ** k)  # off the centre, within the lane
        rm = plan_roadmap(corridor, Obstacles.empty(), start, PLACED)
        assert_consistent(rm)
        np.testing.assert_allclose(rm.l, centre, atol=1e-9)
        np.testing.assert_allclose(rm.width, left - right - 2 * R_ROAD, atol=1e-9)
        np.testing.assert_allclose(rm.s, np.arange(81.0))
        assert rm.length == pytest.approx(80.0)
        # level 3 may not leave the lane: the bands keep the footprint inside it
        assert np.all(rm.band_lo >= centre - (w - 1.8) / 2 - 1e-9)
        assert np.all(rm.band_hi <= centre + (w - 1.8) / 2 + 1e-9)


def test_empty_curved_road_runs_along_the_middle() -> None:
    corridor, obs, start, road, _ = field(0, "left", 0)
    rm = plan_roadmap(corridor, obs, start)
    assert np.max(np.abs(rm.l)) < 1e-6
    # the vertices lie on the analytic centre circle (radius 40 about (0, 40))
    np.testing.assert_allclose(np.hypot(rm.xy[:, 0], rm.xy[:, 1] - 40.0), 40.0, atol=2e-3)
    assert_free(rm, obs, road, R_DEFAULT)


@pytest.mark.parametrize("side", [1.0, -1.0])
def test_one_obstacle_is_passed_on_the_wider_side_in_the_lane_beside_it(side: float) -> None:
    """A car in the middle lane of three (9.6 m), a little to one side: the path passes on
    the wider side, in the centre of the lane there, which keeps more than keeping a lane
    beside a car needs (``enough_separation``), and stays in that lane."""
    corridor = straight(100.0)
    # a car at l = +-1 covers |l| in [0.1, 1.9]; grown by 1.2 it covers [-1.1, 3.1]
    obs = Obstacles.from_boxes([[40.0, side]], [0.0], [4.5], [1.8])
    rm = plan_roadmap(corridor, obs, (0.0, 0.0), PLACED)
    assert_consistent(rm)
    beside = np.abs(rm.s - 40.0) <= 2.25 + R_DEFAULT - 0.01
    wide_gap = (-4.8 + R_ROAD, -1.1) if side > 0 else (1.1, 4.8 - R_ROAD)
    gap = rm.path[rm.s == 40.0]
    np.testing.assert_allclose(rm.graph_l[gap], np.mean(wide_gap), atol=1e-9)
    np.testing.assert_allclose(rm.l[beside], -3.2 * side, atol=1e-9)
    assert rm.params.enough_separation <= 3.2 - 1.1
    assert rm.bottleneck_width == pytest.approx(wide_gap[1] - wide_gap[0])
    assert abs(rm.bottleneck_s - 40.0) <= 2.25 + R_DEFAULT
    # well before the obstacle the path keeps the start's lane, the middle one; after it,
    # the lane it changed to
    np.testing.assert_allclose(rm.l[rm.s < 20], 0.0, atol=1e-9)
    np.testing.assert_allclose(rm.l[rm.s > 45], -3.2 * side, atol=1e-9)
    # the separation holds PLACE_HOLD ahead of the first sweep line (s = 38) that the
    # obstacle's grown side bounds
    held = (rm.s >= 38.0 - PLACE_HOLD) & (rm.s <= 40.0)
    assert np.all(side * rm.l[held] <= -1.1 - rm.params.enough_separation + 1e-9)
    assert_free(rm, obs, open_road(corridor), R_DEFAULT)


@settings(max_examples=25, deadline=None)
@given(at=st.floats(30.0, 150.0), length=st.floats(4.0, 30.0))
def test_a_lane_kept_is_left_only_around_the_car_that_blocks_it(at: float, length: float
                                                                ) -> None:
    """Keep offsets hold the vehicle's centre in the right lane of a two-lane road (the
    lane it keeps, or the one that leads on), and a parked vehicle blocks that lane: the
    path passes it in the other lane, and keeps to its own lane farther from it than the
    release reaches (not the whole road, whose middle is the lane line), beyond the
    stretch after the start where the keep offsets do not bind."""
    plain = straight(260.0, 3.2, -3.2)
    half = RoadmapParams().vehicle_width / 2.0
    corridor = Corridor(plain.reference, plain.s, plain.left, plain.right,
                        keep_left=np.full(len(plain.s), -half),
                        keep_right=np.full(len(plain.s), -3.2 + half))
    obs = Obstacles.from_boxes([[at, -1.6]], [0.0], [length], [2.0])
    rm = plan_roadmap(corridor, obs, (0.0, -1.6))
    assert_consistent(rm)
    assert_free(rm, obs, open_road(corridor), R_DEFAULT)
    blocked = at - length / 2.0 - R_DEFAULT  # the first sweep line in the grown car
    far = ((rm.s >= KEEP_GRACE) & (rm.s < blocked - RELEASE_REACH - 1.0)) | (
        rm.s > at + length / 2.0 + RELEASE_AFTER + RELEASE_REACH + 1.0)
    assert far.any()
    assert np.all((rm.l[far] >= -3.2 + half - 1e-9) & (rm.l[far] <= -half + 1e-9))
    beside = np.abs(rm.s - at) <= length / 2.0
    assert np.all(rm.l[beside] > 0.0)


def _gate_field() -> tuple[Corridor, Obstacles]:
    """A 14 m road closed by a row of obstacles at s = 40..44 but for two gaps: a narrow
    one straight ahead (free width 3.0 - 2.4 = 0.6 m) and a wide one off to the left
    (4.5 - 2.4 = 2.1 m); behind, a second row with both gaps likewise."""
    corridor = straight(100.0, 7.0, -7.0)
    rows = []
    for s0 in (40.0, 60.0):
        rows += [[[s0, -7.5], [s0 + 4, -7.5], [s0 + 4, -1.5], [s0, -1.5]],
                 [[s0, 1.5], [s0 + 4, 1.5], [s0 + 4, 2.5], [s0, 2.5]]]
    return corridor, Obstacles.from_polygons([np.array(p, float) for p in rows])


def test_field_is_crossed_by_the_widest_passage_not_the_shortest() -> None:
    corridor, obs = _gate_field()
    rm = plan_roadmap(corridor, obs, (0.0, 0.0), RoadmapParams(wmax=3.5, place=True))
    assert_consistent(rm)
    at_rows = (np.abs(rm.s - 42.0) <= 2.0) | (np.abs(rm.s - 62.0) <= 2.0)
    np.testing.assert_allclose(rm.graph_l[rm.path[at_rows]], (2.5 + 1.2 + 7.0 - R_ROAD) / 2,
                               atol=1e-9)
    assert rm.bottleneck_width == pytest.approx(7.0 - R_ROAD - 2.5 - 1.2)
    assert_free(rm, obs, open_road(corridor), R_DEFAULT)


def test_with_small_wmax_the_field_is_crossed_by_the_shortest_passage() -> None:
    corridor, obs = _gate_field()
    rm = plan_roadmap(corridor, obs, (0.0, 0.0), RoadmapParams(wmax=0.5, place=True))
    assert_consistent(rm)
    at_rows = (np.abs(rm.s - 42.0) <= 2.0) | (np.abs(rm.s - 62.0) <= 2.0)
    np.testing.assert_allclose(rm.graph_l[rm.path[at_rows]], 0.0, atol=1e-9)
    # separations beyond wmax / 2 count as equal
    assert rm.params.enough_separation == pytest.approx(0.25)
    assert np.all(np.abs(rm.l[at_rows]) <= 0.3 - 0.25 + 1e-9)
    assert rm.bottleneck_width == pytest.approx(0.6)
    wide = plan_roadmap(corridor, obs, (0.0, 0.0), RoadmapParams(wmax=3.5, place=True))

    def searched(r: Roadmap) -> float:  # the length the search minimised (midpoints)
        return float(np.hypot(*np.diff(r.graph_xy[r.path], axis=0).T).sum())

    assert searched(rm) < searched(wide)


def test_start_picks_the_interval_the_vehicle_is_in() -> None:
    corridor, obs = _gate_field()
    rm = plan_roadmap(corridor, obs, (43.0, 5.0), RoadmapParams(wmax=0.5, place=True))
    assert rm.s[0] == 43.0
    assert rm.graph_lo[rm.path[0]] <= 5.0 <= rm.graph_hi[rm.path[0]]
    # off the line: the first line at or ahead of the vehicle
    rm = plan_roadmap(corridor, obs, (42.3, 0.2))
    assert rm.s[0] == 43.0 and rm.l[0] == pytest.approx(0.0)


def test_links_make_a_free_passage_where_the_midpoint_segment_is_not() -> None:
    # an obstacle whose grown front lies just ahead of a sweep line: the segment from the
    # road's middle to the gap beside it cuts the grown corner, yet the road is open
    corridor = straight(100.0)
    for front in np.arange(30.0, 31.0, 0.05):
        obs = Obstacles.from_boxes([[front + 2.25, 0.5]], [0.0], [4.5], [1.8])
        rm = plan_roadmap(corridor, obs, (0.0, 0.0), RoadmapParams(**EVEN))
        assert_consistent(rm)
        assert rm.bottleneck_width == pytest.approx(2.0)
        assert_free(rm, obs, open_road(corridor), R_DEFAULT)


# -- free intervals against shapely ------------------------------------------------------
def _shapely_intervals(corridor: Corridor, obs: Obstacles, s: float, r: float):
    lo, hi = (float(v) for v in corridor.bounds_at(s))
    h = float(corridor.heading_at(s))
    c = corridor.to_xy(s, 0.0)
    n = np.array([-np.sin(h), np.cos(h)])
    seg = LineString([c + (lo + r) * n, c + (hi - r) * n])
    grown = shapely.union_all([Polygon(p).buffer(r, quad_segs=256) for p in obs.polygons()])
    free = seg.difference(grown)
    parts = getattr(free, "geoms", [free])
    out = []
    for g in parts:
        if g.is_empty:
            continue
        a, b = np.asarray(g.coords)[[0, -1]]
        la, lb = sorted(((a - c) @ n, (b - c) @ n))
        out.append((la, lb))
    return sorted(out)


def test_free_intervals_match_shapely_with_nonconvex_and_large_polygons() -> None:
    corridor = straight(40.0, 8.0, -8.0)
    u_shape = np.array([[10, -4], [16, -4], [16, 2], [14, 2], [14, -2], [12, -2], [12, 2],
                        [10, 2]], float)  # open towards +l: a slot 2 m wide
    big = np.array([[22, -8.5], [30, -8.5], [30, 0.5], [22, 0.5]], float)  # wider than 2 r
    tri = np.array([[33, 3], [37, 5], [33.5, 7.5]], float)
    obs = Obstacles.from_polygons([u_shape, big, tri])
    params = RoadmapParams(vehicle_width=1.0, safety_margin=0.2, d=0.5,
                           road_margin=0.2)  # r = 0.7
    rm = plan_roadmap(corridor, obs, (0.0, 0.0), params)
    for k, s in enumerate(np.arange(0.0, 40.01, 0.5)):
        got = sorted(zip(rm.graph_lo[rm.graph_line == k], rm.graph_hi[rm.graph_line == k],
                         strict=True))
        want = _shapely_intervals(corridor, obs, s, 0.7)
        assert len(got) == len(want), s
        np.testing.assert_allclose(got, want, atol=1e-3)
    # the sweep line at s = 13 runs up the U's slot (2 m wide, 1 m from each wall > r):
    # free from the slot's grown floor at l = -2 + 0.7 to the grown road edge
    line = rm.graph_line == 26
    np.testing.assert_allclose(rm.graph_lo[line], [-8.0 + 0.7, -1.3])
    np.testing.assert_allclose(rm.graph_hi[line], [-4.7, 7.3])


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 10**6), kind=st.sampled_from(["straight", "left", "right"]),
       count=st.integers(1, 12))
def test_free_intervals_match_shapely_on_random_fields(seed: int, kind: str,
                                                        count: int) -> None:
    corridor, obs, start, _, _ = field(seed, kind, count, length=30.0, radius=25.0)
    params = RoadmapParams(d=3.0, **EVEN)
    try:
        rm = plan_roadmap(corridor, obs, start, params)
    except RoadBlockedError:
        return
    for k in range(int(rm.graph_line.max()) + 1):
        s = float(rm.graph_s[rm.graph_line == k][0])
        got = sorted(zip(rm.graph_lo[rm.graph_line == k], rm.graph_hi[rm.graph_line == k],
                         strict=True))
        want = [w for w in _shapely_intervals(corridor, obs, s, params.inflation)
                if w[1] - w[0] > 2e-3]
        got = [g for g in got if g[1] - g[0] > 2e-3]
        assert len(got) == len(want)
        np.testing.assert_allclose(got, want, atol=1e-3)


# -- against the raster oracle -----------------------------------------------------------
#: Raster step [m] of the oracle.
H = 0.1
#: How much the raster overstates the best clearance: a cell's clearance is the distance
#: to the nearest *blocked cell centre*, at most one cell diagonal (H sqrt 2) beyond the
#: blocked set, and a raster path runs between cell centres, up to half a diagonal
#: closer to an obstacle than its cells' centres. So a raster clearance c means a real
#: passage of clearance c - 1.5 H sqrt 2, and a real one of clearance c a raster one of
#: at least c - H sqrt 2 / 2.
RASTER_TOL = 1.5 * H * np.sqrt(2.0)


def exist_tol(d: float) -> float:
    """Margin [m] beyond the inflation above which the roadmap must find a passage.

    The raster's error plus 0.05 d: links between sweep lines are straight and tried at
    finitely many places (the midpoints, constant-offset links across the intervals'
    common range, and links between the same fractions of both intervals), so a passage
    whose lateral drift across a band exceeds its margin may be missed; such passages
    have a margin of order d times their slope. On 1000s of random fields with d <= 2 m
    no passage with a margin above the raster error was missed.
    """
    return RASTER_TOL + 0.05 * d


def check_against_oracle(seed: int, kind: str, count: int, d: float, wmax: float) -> None:
    corridor, obs, start, road, goal = field(seed, kind, count)
    params = RoadmapParams(d=d, wmax=wmax, **EVEN)
    r = params.inflation
    margin = best_clearance(road, obs.polygons(), start, goal, step=H).best_clearance - r
    try:
        rm = plan_roadmap(corridor, obs, start, params)
    except RoadBlockedError as err:
        assert margin <= exist_tol(d), f"oracle margin {margin:.3f} m but {err}"
        assert 0.0 <= err.station - float(corridor.offset) <= corridor.length
        return
    assert_consistent(rm)
    assert_free(rm, obs, road, r)
    # a free passage exists, so the raster finds one up to its error
    assert margin >= -RASTER_TOL
    # the widest passage of the raster crosses every sweep line in a free interval at
    # least 2 (margin - RASTER_TOL) wide: the roadmap's (capped) bottleneck is no narrower
    assert min(rm.bottleneck_width, wmax) >= min(2 * (margin - RASTER_TOL), wmax) - 1e-9
    if np.all(rm.arc_direct[[np.flatnonzero((rm.arcs == (a, b)).all(axis=1))[0]
                             for a, b in zip(rm.path[:-1], rm.path[1:], strict=True)]]):
        # the links are the midpoints' segments: from each placed vertex along its line
        # to the midpoint, across, and along the next line
        pts = rm.passage_xy
        mids = rm.graph_xy[rm.path]
        assert all(np.min(np.hypot(*(pts - q).T)) < 1e-9 for q in mids[1:-1])


#: Random obstacle fields for the oracle tests: seed, road shape, obstacle count, d, wmax.
FIELDS = dict(seed=st.integers(0, 10**6), kind=st.sampled_from(["straight", "left", "right"]),
              count=st.integers(0, 16), d=st.sampled_from([0.5, 1.0, 2.0]),
              wmax=st.sampled_from([1.0, 3.5, 100.0]))


@settings(max_examples=30, deadline=None)
@given(**FIELDS)
def test_roadmap_agrees_with_raster_oracle(seed: int, kind: str, count: int, d: float,
                                           wmax: float) -> None:
    check_against_oracle(seed, kind, count, d, wmax)


@pytest.mark.slow
@settings(max_examples=600, deadline=None)
@given(**FIELDS)
def test_roadmap_agrees_with_raster_oracle_long(seed: int, kind: str, count: int, d: float,
                                                wmax: float) -> None:
    check_against_oracle(seed, kind, count, d, wmax)


# -- blocked roads and bad input ---------------------------------------------------------
def test_blocked_road_names_station_and_edge() -> None:
    ref = np.array([[0.0, 0.0], [100.0, 0.0]])
    corridor = Corridor.from_reference(ref, [4.8, 4.8], [-4.8, -4.8], edges=("a", "b"),
                                       edge_starts=(0, 50), offset=200.0)
    wall = Obstacles.from_boxes([[70.0, 0.0]], [0.0], [1.0], [12.0])
    with pytest.raises(RoadBlockedError) as info:
        plan_roadmap(corridor, wall, (200.0 * 0 + 0.0, 0.0))
    err = info.value
    # the wall spans s = 69.5..70.5; grown by 1.2 m it closes sweep lines 69 and 70
    assert err.station == pytest.approx(200.0 + 69.0)
    assert err.edge == "b"
    assert "269.0 m" in str(err) and "'b'" in str(err)
    early = Obstacles.from_boxes([[20.0, 0.0]], [0.0], [1.0], [12.0])
    with pytest.raises(RoadBlockedError) as info:
        plan_roadmap(corridor, early, (0.0, 0.0))
    assert info.value.edge == "a" and info.value.station == pytest.approx(219.0)


def test_blocked_by_two_staggered_rows_reports_the_dead_end() -> None:
    # each row leaves a gap, but the second row's gap is on the other side and the
    # rows are too close to get across: the dead end starts at the second row
    corridor = straight(100.0, 4.8, -4.8)
    obs = Obstacles.from_polygons([
        np.array([[40, -5], [44, -5], [44, 1.5], [40, 1.5]], float),
        np.array([[44.5, -1.5], [48, -1.5], [48, 5], [44.5, 5]], float)])
    with pytest.raises(RoadBlockedError) as info:
        plan_roadmap(corridor, obs, (0.0, 0.0))
    assert 43.0 <= info.value.station <= 44.0
    assert info.value.edge is None


def test_narrow_road_without_room_for_the_vehicle_is_blocked() -> None:
    corridor = straight(50.0, 0.8, -0.8)  # 1.6 m < the vehicle's 1.8 m
    with pytest.raises(RoadBlockedError) as info:
        plan_roadmap(corridor, Obstacles.empty(), (0.0, 0.0))
    assert info.value.station == 0.0
    # exactly as wide as the vehicle with its road margins: one zero-width interval a line
    rm = plan_roadmap(straight(50.0, R_ROAD, -R_ROAD), Obstacles.empty(), (0.0, 0.0))
    assert rm.bottleneck_width == 0.0


@pytest.mark.parametrize("kwargs", [
    {"d": 0.0}, {"d": -1.0}, {"wmax": 0.0}, {"safety_margin": -0.1},
    {"vehicle_width": float("nan")}, {"vehicle_length": float("inf")},
    {"segment_length": 1.0, "d": 1.0}, {"d": "1"}, {"wmax": True}])
def test_bad_params_raise(kwargs: dict) -> None:
    with pytest.raises(ParameterError):
        RoadmapParams(**kwargs)


def test_bad_arguments_raise() -> None:
    corridor = straight(50.0)
    with pytest.raises(ParameterError):
        plan_roadmap(corridor, Obstacles.empty(), (0, 0), params={"d": 1.0})  # type: ignore
    with pytest.raises(GeometryError):
        plan_roadmap(corridor, [np.zeros((4, 2))], (0, 0))  # type: ignore[arg-type]
    with pytest.raises(GeometryError):
        plan_roadmap(np.zeros((5, 2)), Obstacles.empty(), (0, 0))  # type: ignore
    for bad in [(0.0,), (0.0, np.nan), (1.0, 2.0, 3.0)]:
        with pytest.raises(GeometryError):
            plan_roadmap(corridor, Obstacles.empty(), bad)


@pytest.mark.parametrize(("start", "ok"), [
    ((-5.0, 0.0), False), ((55.0, 0.0), False), ((10.0, 8.0), False), ((10.0, -7.9), False),
    ((10.0, 6.5), True), ((0.0, 0.0), True), ((50.0, 0.0), True)])
def test_start_off_the_corridor(start: tuple[float, float], ok: bool) -> None:
    corridor = straight(50.0)
    if ok:
        rm = plan_roadmap(corridor, Obstacles.empty(), start)
        assert rm.s[0] == pytest.approx(np.ceil(start[0]))
    else:
        with pytest.raises(GeometryError, match=r"station|off the road"):
            plan_roadmap(corridor, Obstacles.empty(), start)


def test_start_inside_a_grown_obstacle_still_plans() -> None:
    corridor = straight(60.0)
    obs = Obstacles.from_boxes([[5.0, 1.5]], [0.0], [4.5], [1.8])
    rm = plan_roadmap(corridor, obs, (5.0, -0.5))  # 1.1 m from the car: inside r = 1.2
    assert rm.s[0] == 5.0 and rm.graph_l[rm.path[0]] == pytest.approx((-4.8 + R_ROAD - 0.6) / 2)


def test_malformed_obstacles_raise() -> None:
    with pytest.raises(GeometryError):
        Obstacles.from_polygons([np.zeros((2, 2))])
    with pytest.raises(GeometryError):
        Obstacles.from_polygons([np.array([[0, 0], [1, 0], [np.nan, 1]])])
    with pytest.raises(GeometryError):
        Obstacles.from_boxes([[0.0, 0.0]], [0.0], [-1.0], [1.0])


# -- compiled helpers against independent references ---------------------------------------
def test_segment_distance_matches_shapely() -> None:
    from splineplan.roadmap import _segment_distance

    rng = np.random.default_rng(5)
    for _ in range(400):
        p, q, a, b = rng.integers(-3, 4, (4, 2)) * 0.5 + rng.choice([0.0, 1.0]) * rng.normal(
            0.0, 0.3, (4, 2))  # grid points too: touching, collinear and crossing cases
        got = _segment_distance(*p, *q, *a, *b)
        want = LineString([p, q]).distance(LineString([a, b])) if not (
            np.array_equal(p, q) or np.array_equal(a, b)) else shapely.distance(
            shapely.Point(p) if np.array_equal(p, q) else LineString([p, q]),
            shapely.Point(a) if np.array_equal(a, b) else LineString([a, b]))
        assert got == pytest.approx(want, abs=1e-12)


def test_search_is_widest_then_shortest_by_enumeration() -> None:
    # a layered graph (arcs from line k to k + 1) against all source-to-goal paths
    from splineplan.roadmap import _search

    rng = np.random.default_rng(2)
    for _ in range(60):
        nline = int(rng.integers(2, 6))
        per = rng.integers(1, 4, nline)
        vline = np.repeat(np.arange(nline), per).astype(np.int64)
        width = np.round(rng.uniform(0.0, 5.0, len(vline)), 1)
        arcs = np.array([(u, v) for u in range(len(vline)) for v in range(len(vline))
                         if vline[v] == vline[u] + 1 and rng.random() < 0.7],
                        dtype=np.int64).reshape(-1, 2)
        arcs = arcs[rng.permutation(len(arcs))]
        arc_len = np.round(rng.uniform(1.0, 3.0, len(arcs)), 1)
        wmax = 3.5
        best = None
        by_arc = {(int(u), int(v)): e for e, (u, v) in enumerate(arcs)}
        for combo in itertools.product(*[np.flatnonzero(vline == k) for k in range(1, nline)]):
            path = (0, *combo)
            steps = [by_arc.get((int(u), int(v))) for u, v in itertools.pairwise(path)]
            if None in steps:
                continue
            key = (-min(float(width[list(path)].min()), wmax), float(arc_len[steps].sum()))
            best = key if best is None or key < best else best
        path, steps, reached = _search(0, arcs, arc_len, width, vline, nline, wmax)
        if best is None:
            assert path is None and reached < nline - 1
            continue
        assert path is not None and steps is not None and reached == nline - 1
        np.testing.assert_array_equal(arcs[steps, 0], path[:-1])
        np.testing.assert_array_equal(arcs[steps, 1], path[1:])
        assert path[0] == 0 and vline[path[-1]] == nline - 1
        got = (-min(float(width[path].min()), wmax), float(arc_len[steps].sum()))
        assert got[0] == best[0] and got[1] == pytest.approx(best[1])


def test_bent_bands_match_the_array_formula() -> None:
    from splineplan.geometry import wrap_angle
    from splineplan.roadmap import _bent_bands

    rng = np.random.default_rng(3)
    for trial in range(30):
        n = int(rng.integers(2, 12))
        ref = np.cumsum(rng.uniform(0.5, 4.0, (n, 2)) * [1.0, rng.choice([0.0, 0.3])], axis=0)
        left = np.full(n, 3.0) if trial % 2 else rng.uniform(2.0, 4.0, n)
        corridor = Corridor.from_reference(ref, left, -left)
        stations = np.sort(rng.uniform(0.0, corridor.length, int(rng.integers(2, 20))))
        # the formula the compiled loop replaces
        s = corridor.s
        kink = np.zeros(len(s))
        if len(s) > 2:
            h = corridor.heading_at((s[:-1] + s[1:]) / 2.0)
            ds = np.diff(s)
            kink[1:-1] = ((np.abs(wrap_angle(np.diff(h))) > 1e-12)
                          | (np.abs(np.diff(np.diff(corridor.left) / ds)) > 1e-12)
                          | (np.abs(np.diff(np.diff(corridor.right) / ds)) > 1e-12))
        ck = np.concatenate(([0.0], np.cumsum(kink)))
        want = (ck[np.searchsorted(s, stations[1:], side="left")]
                - ck[np.searchsorted(s, stations[:-1], side="right")]) > 0
        np.testing.assert_array_equal(_bent_bands(corridor, stations), want)


def test_cull_finds_every_box_pair_within_reach() -> None:
    from splineplan.roadmap import _cull

    rng = np.random.default_rng(4)
    for _ in range(20):
        a = rng.uniform(0.0, 50.0, (int(rng.integers(1, 30)), 2))
        b = a + rng.normal(0.0, 3.0, a.shape)
        lo = rng.uniform(0.0, 50.0, (int(rng.integers(1, 30)), 2))
        bbox = np.hstack((lo, lo + rng.uniform(0.1, 8.0, lo.shape)))
        r = float(rng.uniform(0.0, 2.0))
        s_lo, s_hi = np.minimum(a, b) - r, np.maximum(a, b) + r
        want = [(i, j) for i in range(len(a)) for j in range(len(bbox))
                if s_lo[i, 0] <= bbox[j, 2] and s_hi[i, 0] >= bbox[j, 0]
                and s_lo[i, 1] <= bbox[j, 3] and s_hi[i, 1] >= bbox[j, 1]]
        i, j = _cull(a, b, bbox, r)
        assert list(zip(i.tolist(), j.tolist(), strict=True)) == want
