"""Levels 2 and 3 keep the paper's separation: the trajectory's clearance to the obstacles
against the best any path of the car can keep.

Where the best is known in closed form (a passage between two parked cars on a straight
road: half the gap less the car's width), the quick tests judge by it; the slow test judges
random fields by the kinematic oracle (``benchmarks/kinematic_oracle.py``: hybrid A* with
the car's footprint and turning limit, shares no code with the planner).
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from shapely.geometry import Polygon
from test_trajectory import assert_wheels_keep_up

from benchmarks.bench_oracle import extended_road, goal_region, random_field
from benchmarks.kinematic_oracle import Search, best_clearance, error
from splineplan.corridor import Corridor
from splineplan.errors import RoadBlockedError
from splineplan.obstacles import Obstacles
from splineplan.planner import plan_corridor
from splineplan.roadmap import RoadmapParams
from splineplan.trajectory import TrajectoryParams

CAR_W = 1.8
#: The oracle benchmark's vehicle: starts at 10 m/s, may drive 15 m/s.
#: Level 2 with its chosen vertices placed for the separation and the lane.
PLACED = RoadmapParams(place=True)
TP = TrajectoryParams(s_max=15.0)


def straight(width: float, length: float = 120.0) -> Corridor:
    h = width / 2.0
    return Corridor.from_boundaries(left=[[0.0, h], [length, h]],
                                    right=[[0.0, -h], [length, -h]])


@settings(max_examples=8, deadline=None)
@given(gap=st.floats(2.6, 3.6), centre=st.floats(-1.0, 1.0), at=st.floats(50.0, 80.0),
       lane=st.sampled_from([-3.2, 3.2]))
def test_a_passage_between_two_cars_keeps_its_separation(gap: float, centre: float,
                                                          at: float, lane: float) -> None:
    """Two cars side by side on a 3-lane road (9.6 m) leave a gap of ``gap`` [m] centred
    at ``centre``; the vehicle comes from an outer lane at 10 m/s. The best clearance any
    path keeps from both is ``(gap - 1.8) / 2`` (the car centred in the gap, parallel to
    it); the trajectory is feasible and keeps at least 0.85 of it (the issue's target)."""
    cor = straight(9.6)
    y = (centre - gap / 2 - CAR_W / 2, centre + gap / 2 + CAR_W / 2)
    obs = Obstacles.from_boxes([[at, y[0]], [at, y[1]]], [0.0, 0.0], 4.5, CAR_W)
    plan = plan_corridor(cor, obs, [1.0, lane], 0.0, params=TP, roadmap_params=PLACED,
                         start_speed=10.0,
                         end_speed=None)
    tr = plan.trajectory
    best = (gap - CAR_W) / 2
    assert tr.feasible
    assert float(np.min(tr.clearance_obstacles)) >= 0.85 * best


@pytest.mark.parametrize("gap", [2.6, 2.8, 3.0])
def test_a_passage_beside_the_roads_edge_keeps_its_separation(gap: float) -> None:
    """A car parked on a two-lane road (6.4 m) leaves ``gap`` [m] to the right edge and
    too little on its left; the vehicle comes in the right lane at 10 m/s. The best
    clearance any path keeps from the car is ``gap - 1.8`` (the footprint on the road's
    edge). Placed, level 2 gives the road margin to that separation (leaving
    ``PLACE_ROAD_RESERVE`` to the edge) and holds it 4 m before and after the car, and
    level 3's moves keep ``keep_separation`` beyond the safety margin where the curve
    kept it: the trajectory is feasible and on the road, keeps at least 0.6 m and 0.75 of
    the best (the paper's midpoints kept 0.33-0.5 of it, placement without the road
    margin 0.5-0.62), the wheels keep up, and the car does not crawl through it."""
    cor = straight(6.4)
    obs = Obstacles.from_boxes([[60.0, -3.2 + gap + CAR_W / 2]], [0.0], 4.5, CAR_W)
    tr = plan_corridor(cor, obs, [1.0, -1.6], 0.0, params=TP, roadmap_params=PLACED,
                       start_speed=10.0, end_speed=None).trajectory
    best = gap - CAR_W
    clear = float(np.min(tr.clearance_obstacles))
    assert tr.feasible and float(np.min(tr.clearance_road)) >= 0.0
    assert clear >= PLACED.safety_margin + TP.keep_separation - 0.01
    assert clear >= 0.75 * best
    assert_wheels_keep_up(tr, TP)
    assert tr.speed.min() >= 3.0


@pytest.mark.parametrize(("width", "lane"), [(6.4, -1.6), (6.4, 1.6), (9.6, -3.2), (12.8, 1.6)])
def test_one_car_in_the_lane_is_passed_in_the_next_lanes_centre(width: float,
                                                                lane: float) -> None:
    """A car parked at the centre of the vehicle's lane on a free road: the trajectory
    passes it at least as far as keeping the next lane's centre does (lane width less
    the car's width, 1.4 m), at full speed, and keeps the centre of a lane on either
    side of it. The lane change is smooth enough for the steering rate at that speed:
    the car never drops below its start speed (10 m/s) to turn the wheels, and they turn
    no faster than the car can turn them."""
    cor = straight(width)
    obs = Obstacles.from_boxes([[60.0, lane]], [0.0], 4.5, CAR_W)
    plan = plan_corridor(cor, obs, [1.0, lane], 0.0, params=TP, roadmap_params=PLACED,
                         start_speed=10.0,
                         end_speed=None)
    tr = plan.trajectory
    assert tr.feasible
    assert float(np.min(tr.clearance_obstacles)) >= 3.2 - CAR_W - 0.01
    assert tr.min_speed_after == pytest.approx(TP.s_max)
    assert tr.speed.min() >= 10.0 - 1e-6
    assert_wheels_keep_up(tr, TP)
    lat = cor.to_sl(tr.xy)[:, 1]
    lanes = -width / 2 + 1.6 + 3.2 * np.arange(round(width / 3.2))
    for s_ in (20.0, 110.0):  # well before and after it
        j = int(np.argmin(np.abs(tr.s - s_)))
        assert np.min(np.abs(lanes - lat[j])) < 0.1


def test_an_empty_multi_lane_road_keeps_the_lanes_centre() -> None:
    """On an empty 4-lane road (12.8 m) the trajectory from an off-centre start settles on
    the centre of the vehicle's lane, not the road's middle (a lane line)."""
    cor = straight(12.8, 200.0)
    tr = plan_corridor(cor, None, [1.0, 2.0], 0.0, params=TP, roadmap_params=PLACED,
                       start_speed=10.0,
                       end_speed=None).trajectory
    assert tr.feasible
    lat = cor.to_sl(tr.xy)[:, 1]
    far = tr.s > 40.0
    np.testing.assert_allclose(lat[far], 1.6, atol=0.05)


def test_without_placing_the_vertices_are_the_papers_midpoints() -> None:
    """``RoadmapParams(place=False)`` (the default): the same widest-then-shortest path,
    its vertices at the free intervals' midpoints (on the empty 4-lane road: the road's
    middle)."""
    from splineplan.roadmap import plan_roadmap

    cor = straight(12.8, 200.0)
    placed = plan_roadmap(cor, None, start_xy=[1.0, 2.0], params=PLACED)
    mid = plan_roadmap(cor, None, start_xy=[1.0, 2.0], params=RoadmapParams(place=False))
    np.testing.assert_array_equal(mid.path, placed.path)
    np.testing.assert_allclose(mid.xy, np.asarray(mid.graph_xy)[mid.path])
    assert np.allclose(mid.l[5:], 0.0, atol=1e-9) and np.allclose(placed.l[-5:], 1.6, atol=0.05)


@pytest.mark.slow
@settings(max_examples=6, deadline=None)
@given(seed=st.integers(0, 2**32 - 1))
def test_tight_passages_keep_most_of_the_oracles_best_clearance(seed: int) -> None:
    """The oracle benchmark's random fields (2-4 lanes, straight or curved, cars, trucks
    and cones): where the oracle's best clearance lies between the margin and 1 m and the
    planner is feasible, the planner keeps at least 0.6 of it, less the oracle's error.

    The issue's target is 0.85 on every such field; the benchmark (``python -m benchmarks
    oracle``, benchmarks/RESULTS.md) records how many reach it. Before the vertices were
    placed for the separation the planner kept 0.44-0.6 of it.
    """
    rng = np.random.default_rng(seed)
    cor, obs = random_field(rng)
    lo, hi = cor.bounds_at(np.array([1.0]))
    start = cor.to_xy(np.array([1.0]), np.array([rng.uniform(lo[0] + 1.2, hi[0] - 1.2)]))[0]
    heading = float(cor.heading_at(1.0))
    try:
        tr = plan_corridor(cor, obs, start, heading, roadmap_params=PLACED,
                           params=TP, start_speed=10.0, end_speed=None).trajectory
    except RoadBlockedError:
        return
    if not tr.feasible:
        return
    search = Search(step=0.05)
    best = best_clearance(extended_road(cor), [Polygon(p) for p in obs.polygons()],
                          (float(start[0]), float(start[1]), heading), goal_region(cor),
                          upper=1.2, search=search)
    if not 0.35 <= best <= 1.0:
        return
    assert float(np.min(tr.clearance_obstacles)) >= 0.6 * best - error(search)
