"""The kinematic oracle (benchmarks/kinematic_oracle.py) on cases whose answer is known, and as
the judge of level 3: a trajectory the planner calls feasible is one a car of its size and
turning limit can drive (the oracle finds a path keeping the margin, less its error)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from shapely import affinity
from shapely.geometry import Polygon, box
from test_trajectory import random_field, real_plan

from benchmarks.bench_oracle import extended_road
from benchmarks.kinematic_oracle import Car, Search, best_clearance, drive, error
from splineplan.errors import RoadBlockedError

CAR = Car()
MARGIN = 0.3
#: A coarser search where it must exhaust the space to say "no".
COARSE = Search(step=0.05, cell=0.5, headings=36)


def footprint(pose: np.ndarray, car: Car = CAR) -> Polygon:
    base = box(-car.length / 2, -car.width / 2, car.length / 2, car.width / 2)
    return affinity.translate(affinity.rotate(base, float(pose[2]), origin=(0, 0),
                                              use_radians=True), float(pose[0]), float(pose[1]))


def assert_path_is_drivable(path: np.ndarray, road: Polygon, obstacles: list[Polygon],
                            margin: float, search: Search = COARSE) -> None:
    """By shapely: each pose's footprint inside the road (to the oracle's error) and
    ``margin`` from the obstacles (less that error); consecutive poses one move apart
    turn no more than the turning limit allows."""
    tol = error(search) + 0.05  # and the arcs are checked every 0.25 m
    for pose in path[1:]:
        fp = footprint(pose)
        assert fp.difference(road).area < tol * CAR.length
        for o in obstacles:
            assert fp.distance(o) >= margin - tol
    turn = np.abs(np.diff(path[:, 2]))
    assert np.all(turn <= search.move / CAR.min_turn_radius + 1e-9)


@pytest.mark.parametrize("curved", [False, True])
def test_an_empty_road_is_drivable_and_its_path_is_clear(curved: bool) -> None:
    if curved:  # a quarter circle of radius 30 m, 7 m wide
        th = np.linspace(-math.pi / 2, 0.0, 60)
        outer = np.column_stack((33.5 * np.cos(th), 33.5 * np.sin(th) + 33.5))
        inner = np.column_stack((26.5 * np.cos(th), 26.5 * np.sin(th) + 33.5))
        road = Polygon(np.vstack((outer, inner[::-1])))
        start, goal = (3.0, 3.65, 0.1), box(26.5, 28.0, 33.5, 33.5)
    else:
        road, start, goal = box(0, -1.75, 60, 1.75), (4.0, 0.0, 0.0), box(55, -2, 60, 2)
    r = drive(road, [], start, goal)
    assert r.found
    assert goal.contains(Polygon(footprint(r.path[-1])).centroid)
    assert_path_is_drivable(r.path, road, [], MARGIN, Search())


def test_a_barrier_across_the_road_is_never_passed() -> None:
    road, goal = box(0, -4.8, 60, 4.8), box(55, -4.8, 60, 4.8)
    assert not drive(road, [box(30, -5, 30.5, 5)], (4.0, 0.0, 0.0), goal).found
    # nor a row of cars across it with 0.5 m between them
    row = [box(30, y, 34.5, y + 1.8) for y in (-4.8, -2.5, -0.2, 2.1)]
    assert not drive(road, row, (4.0, 0.0, 0.0), goal).found


@pytest.mark.parametrize("extra, passes", [(0.15, True), (-0.15, False)])
def test_a_gap_passes_only_with_the_car_and_its_margins(extra: float, passes: bool) -> None:
    road, goal = box(0, -4.8, 40, 4.8), box(36, -4.8, 40, 4.8)
    gap = CAR.width + 2 * MARGIN + extra
    walls = [box(20, -4.8, 22, -gap / 2), box(20, gap / 2, 22, 4.8)]
    r = drive(road, walls, (4.0, 0.0, 0.0), goal, search=COARSE)
    assert r.found == passes
    if passes:
        assert_path_is_drivable(r.path, road, walls, MARGIN, COARSE)


@pytest.mark.parametrize("width, passes", [(9.0, False), (16.0, True)])
def test_turning_back_needs_the_turning_circle(width: float, passes: bool) -> None:
    """Forward only: a U-turn needs about ``2 R + width`` of road (8.4 + 1.8 m and some
    for the corners); 9 m is too narrow, 16 m is enough."""
    road = box(0, -width / 2, 30, width / 2)
    goal = box(0, -width / 2, 4, width / 2)
    r = drive(road, [], (12.0, -width / 4, 0.0), goal, margin=0.0, search=COARSE)
    assert r.found == passes


def test_best_clearance_beside_a_wall() -> None:
    """On a 9.6 m road whose left part, from 0.5 m left of the centre, is a wall, a car
    driving along the right edge keeps 4.8 - 1.8 - (-0.5)... : its left side 3.5 m from
    the wall, and no more."""
    road, goal = box(0, -4.8, 40, 4.8), box(36, -4.8, 40, 4.8)
    wall = box(0, 0.5, 40, 4.8)
    best = best_clearance(road, [wall], (4.0, -3.9 + 0.05, 0.0), goal, upper=4.0,
                          search=COARSE)
    assert 3.5 - error(COARSE) - 0.1 <= best <= 3.5 + error(COARSE)


@settings(max_examples=6, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(1, 6), curved=st.booleans())
def test_a_feasible_trajectory_is_one_the_car_can_drive(seed: int, n: int, curved: bool
                                                        ) -> None:
    """Random obstacle fields: where level 3 says feasible, the oracle finds a path for
    the car with its turning limit that keeps the safety margin (less its error)."""
    rng = np.random.default_rng(seed)
    cor, obs, start = random_field(rng, curved, n, gap=rng.uniform(2.6, 3.5))
    try:
        _, tr = real_plan(cor, obs, start, float(cor.heading_at(1.0)))
    except RoadBlockedError:
        return
    if not tr.feasible:
        return
    search = Search(step=0.05)
    road = extended_road(cor)
    cars = [Polygon(p) for p in obs.polygons()]
    end = cor.to_xy(np.array([cor.length - 6.0, cor.length]), np.array([0.0, 0.0]))
    heading = float(cor.heading_at(cor.length))
    goal = affinity.rotate(box(-3.0, -5.0, 3.0, 5.0), heading, origin=(0, 0),
                           use_radians=True)
    goal = affinity.translate(goal, *end.mean(axis=0))
    r = drive(road, cars, (float(tr.x[0]), float(tr.y[0]), float(tr.heading[0])), goal,
              margin=MARGIN - error(search), search=search)
    assert r.found, f"planner feasible, oracle finds no path ({r.expanded} nodes)"
