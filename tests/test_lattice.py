"""Level 2's passage for a car that turns: staggered obstacles that close the road to a car
parallel to it, passed diagonally; judged by shapely and by the kinematic oracle."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from shapely.geometry import Polygon
from test_junction_turns import menger_curvature
from test_trajectory import shapely_check_corridor

from benchmarks.bench_oracle import extended_road, goal_region
from benchmarks.kinematic_oracle import Search, drive, error
from splineplan.corridor import Corridor
from splineplan.errors import RoadBlockedError
from splineplan.lattice import turning_passages
from splineplan.obstacles import Obstacles
from splineplan.planner import elongate_for_roadmap, plan_corridor
from splineplan.roadmap import RoadmapParams, plan_roadmap
from splineplan.trajectory import TrajectoryParams

TP = TrajectoryParams(s_max=15.0)
RP = RoadmapParams()
START = np.array([1.0, -1.6])
SEARCH = Search(step=0.05)


def staggered(gap: float, truck: float = 1.7, car: float = -1.9) -> tuple[Corridor, Obstacles]:
    """A two-lane road (6.4 m, 120 m): a truck (10 x 2.5 m) at lateral offset ``truck``
    ending at 60 m, and a car (4.5 x 1.8 m) at ``car`` starting ``gap`` [m] after it."""
    cor = Corridor.from_boundaries(left=[[0.0, 3.2], [120.0, 3.2]],
                                   right=[[0.0, -3.2], [120.0, -3.2]])
    obs = Obstacles.from_boxes([[55.0, truck], [60.0 + gap + 2.25, car]], [0.0, 0.0],
                               [10.0, 4.5], [2.5, 1.8], ids=["truck", "car"])
    return cor, obs


def oracle_drives(cor: Corridor, obs: Obstacles, margin: float) -> bool:
    """Whether the oracle finds a path from the start keeping ``margin`` [m]."""
    return drive(extended_road(cor), [Polygon(p) for p in obs.polygons()],
                 (float(START[0]), float(START[1]), 0.0), goal_region(cor), margin=margin,
                 search=SEARCH).found


def assert_drivable(tr: object, cor: Corridor, obs: Obstacles) -> None:
    """Feasible, and so by shapely (footprints keep the margin, on the road) and by the
    curvature of the path's own points (1 % for the three-point circle's sampling)."""
    assert tr.feasible  # type: ignore[attr-defined]
    assert shapely_check_corridor(tr, cor, obs, RP) == (0, 0)  # type: ignore[arg-type]
    x, y = np.asarray(tr.x), np.asarray(tr.y)  # type: ignore[attr-defined]
    assert menger_curvature(x, y).max() <= 1.01 * TP.kappa_max


@pytest.mark.parametrize("gap", [3.0, 4.0])
def test_staggered_obstacles_are_passed_diagonally(gap: float) -> None:
    """Level 2's stretched obstacles overlap across the road between a truck and a car
    staggered ``gap`` metres apart, so the sweep line finds the road closed; the oracle
    drives through keeping 0.5-0.8 m. The planner now plans a feasible passage (before:
    "road blocked")."""
    cor, obs = staggered(gap)
    with pytest.raises(RoadBlockedError):
        plan_roadmap(cor, elongate_for_roadmap(cor, obs, RP), START, RP)
    assert oracle_drives(cor, obs, RP.safety_margin + 0.05)
    plan = plan_corridor(cor, obs, START, 0.0, params=TP, start_speed=10.0, end_speed=None)
    assert_drivable(plan.trajectory, cor, obs)
    # the passage goes between the two: right of the truck, then left of the car
    tr = plan.trajectory
    sl = cor.to_sl(np.column_stack((tr.x, tr.y)))
    keep = RP.vehicle_width / 2 + RP.safety_margin
    assert sl[np.argmin(np.abs(sl[:, 0] - 55.0)), 1] < 1.7 - 1.25 - keep
    assert sl[np.argmin(np.abs(sl[:, 0] - (62.25 + gap))), 1] > -1.9 + 0.9 + keep


def test_passages_keep_the_margins_and_the_turning_limit_at_their_nodes() -> None:
    """Each node of a passage keeps the margins with the car's rectangle at the heading of
    the step into it (shapely), and the heading turns by no more than the turning limit
    allows between nodes."""
    cor, obs = staggered(3.5)
    passages = list(turning_passages(cor, obs, START, 0.0, RP, TP.kappa_max, 0.0, 62.0))
    assert passages
    road = Polygon(cor.polygon())
    grown = [Polygon(p).buffer(RP.safety_margin - 1e-6) for p in obs.polygons()]
    for rm in passages:
        xy = np.asarray(rm.xy)
        step = np.diff(xy, axis=0)
        head = np.arctan2(step[:, 1], step[:, 0])
        assert np.abs(np.diff(head)).max() <= TP.kappa_max * RP.d + 1e-9
        inner = (rm.s[1:] > RP.vehicle_length) & (rm.s[1:] < cor.length - RP.vehicle_length)
        for (x, y), h in zip(xy[1:][inner], head[inner], strict=True):
            c, s = np.cos(h), np.sin(h)
            hl, hw = RP.vehicle_length / 2, RP.vehicle_width / 2
            foot = Polygon([(x + c * a - s * b, y + s * a + c * b)
                            for a, b in ((hl, hw), (-hl, hw), (-hl, -hw), (hl, -hw))])
            assert not any(foot.intersects(g) for g in grown)
            assert road.buffer(1e-6).contains(foot)


def test_a_gap_too_narrow_for_the_car_stays_blocked() -> None:
    """Staggered 2 m apart, no path keeps the margin (the oracle's best is about 0.19 m):
    still "road blocked"."""
    cor, obs = staggered(2.0)
    assert not oracle_drives(cor, obs, RP.safety_margin)
    with pytest.raises(RoadBlockedError):
        plan_corridor(cor, obs, START, 0.0, params=TP, start_speed=10.0, end_speed=None)


def test_a_wall_across_the_road_gives_no_passage() -> None:
    """Two cars side by side across the whole road: no node on the lines beside them
    keeps the margin, so no passage is looked for beyond those lines."""
    cor = Corridor.from_boundaries(left=[[0.0, 3.2], [120.0, 3.2]],
                                   right=[[0.0, -3.2], [120.0, -3.2]])
    obs = Obstacles.from_boxes([[60.0, 1.6], [60.0, -1.6]], [0.0, 0.0], 4.5, 1.8)
    assert list(turning_passages(cor, obs, START, 0.0, RP, TP.kappa_max, 0.0, 57.0)) == []


@settings(max_examples=8, deadline=None)
@given(gap=st.floats(1.5, 5.0), truck=st.floats(0.8, 1.9), car=st.floats(-2.3, -0.9))
def test_a_plan_between_staggered_obstacles_is_drivable(gap: float, truck: float,
                                                        car: float) -> None:
    """A truck and a car staggered at random across a two-lane road: whatever passage the
    planner takes (level 2's, or the lattice's where level 2 finds the road closed), a
    plan it calls feasible is drivable by shapely and by its positions' curvature."""
    cor, obs = staggered(gap, truck, car)
    try:
        tr = plan_corridor(cor, obs, START, 0.0, params=TP, start_speed=10.0,
                           end_speed=None).trajectory
    except RoadBlockedError:
        return
    if tr.feasible:
        assert_drivable(tr, cor, obs)


def test_blocked_agrees_with_the_oracle_between_staggered_obstacles() -> None:
    """On 12 seeded random draws of a truck and a car staggered across a two-lane road,
    "road blocked" where the oracle keeps the margin plus 0.05 m (and its error) at most
    once. Not never: level 3 does not follow every passage the lattice finds (of 100 such
    draws, one: a truck at 1.78 m and a car at -1.44 m, 3.03 m apart); the issue's target
    is 99 % of the passable fields."""
    rng = np.random.default_rng(0)
    missed = blocked = 0
    for _ in range(12):
        cor, obs = staggered(rng.uniform(1.5, 5.0), rng.uniform(0.8, 1.9),
                             rng.uniform(-2.3, -0.9))
        try:
            plan_corridor(cor, obs, START, 0.0, params=TP, start_speed=10.0, end_speed=None)
        except RoadBlockedError:
            blocked += 1
            missed += oracle_drives(cor, obs, RP.safety_margin + 0.05 + error(SEARCH))
    assert blocked >= 3  # the draws hold closed roads, not only open ones
    assert missed <= 1
