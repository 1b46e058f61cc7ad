"""Levels 2 and 3 along a long curved corridor: joins, timings, feasibility (shapely)."""

from __future__ import annotations

import numpy as np
import pytest
import shapely
from shapely import affinity
from shapely.geometry import Polygon, box
from test_trajectory import assert_wheels_keep_up

from splineplan.corridor import Corridor
from splineplan.obstacles import Obstacles
from splineplan.planner import CorridorPlan, continued, plan_corridor
from splineplan.roadmap import RoadmapParams
from splineplan.trajectory import Trajectory, TrajectoryParams


def curved_corridor() -> tuple[Corridor, Obstacles]:
    """A 700 m arc of radius 300 m, 9.6 m wide, with cars parked in the outer lanes."""
    th = np.linspace(0.0, 700.0 / 300.0, 400)
    ref = np.column_stack((300.0 * np.sin(th), 300.0 * (1.0 - np.cos(th))))
    cor = Corridor.from_reference(ref, np.full(400, 4.8), np.full(400, -4.8))
    st = np.array([100.0, 180.0, 300.0, 380.0, 560.0, 640.0])
    lat = np.array([3.2, -3.2, 3.2, -3.2, 3.2, -3.2])
    obs = Obstacles.from_boxes(cor.to_xy(st, lat), cor.heading_at(st), 4.5, 1.8)
    return cor, obs


def test_elongated_obstacles_cover_the_original_and_reach_further() -> None:
    obs = Obstacles.from_boxes(np.array([[10.0, 2.0]]), 0.3, 4.0, 2.0)
    out = obs.elongated(np.array([0.3]), 1.35)
    a, b = Polygon(obs.polygon(0)), Polygon(out.polygon(0))
    assert b.contains(a.buffer(-1e-9))
    assert abs(b.area - (a.area + 2 * 1.35 * 2.0)) < 1e-6
    assert out.ids == obs.ids


def test_long_curved_corridor_is_continuous_and_feasible() -> None:
    cor, obs = curved_corridor()
    rp = RoadmapParams()
    start = cor.to_xy(np.array([2.0]), np.array([-3.2]))[0]
    plan = plan_corridor(cor, obs, start, float(cor.heading_at(2.0)), roadmap_params=rp)
    assert isinstance(plan, CorridorPlan)
    roadmaps, tr = plan  # unpacks as before
    assert len(roadmaps) == 3
    assert plan.roadmap_seconds > 0 and plan.trajectory_seconds > 0
    # continuity: positions 0.5 m apart, heading and speed without jumps
    step = np.hypot(np.diff(tr.x), np.diff(tr.y))
    assert step.max() < 0.6
    assert np.abs(np.diff(np.unwrap(tr.heading))).max() < 0.05
    dv2 = np.diff(tr.speed**2) / (2 * np.maximum(np.diff(tr.s), 1e-9))
    assert dv2.max() <= 2.0 + 1e-6 and dv2.min() >= -4.0 - 1e-6
    assert tr.speed[-1] == 0.0 and tr.s[-1] > 680.0
    assert tr.feasible
    # shapely oracle: footprints vs obstacles grown by the margin and the road shrunk by it
    base = box(-rp.vehicle_length / 2, -rp.vehicle_width / 2,
               rp.vehicle_length / 2, rp.vehicle_width / 2)
    grown = [Polygon(p).buffer(rp.safety_margin - 1e-6) for p in obs.polygons()]
    road = Polygon(cor.polygon()).buffer(-(tr.road_margin - 1e-6), join_style=2)
    st = cor.to_sl(tr.xy)[:, 0]
    inner = (st > 4.0) & (st < cor.length - 4.0)  # the footprint overhangs the road's ends
    for x, y, h, ok in zip(tr.x, tr.y, tr.heading, inner, strict=True):
        fp = affinity.translate(affinity.rotate(base, h, origin=(0, 0), use_radians=True), x, y)
        assert not any(fp.intersects(g) for g in grown)
        if ok:
            assert road.contains(fp)


@pytest.mark.parametrize("station", [250.0, 420.0, 610.0])
def test_a_start_far_along_the_corridor_plans_from_there(station: float) -> None:
    """A vehicle that starts beyond the first segment (as after a replan far along a
    route) gets a plan from its own position to the corridor's end: starting at its pose,
    feasible on the parked-car arc (shapely), and as long as the rest of the corridor."""
    cor, obs = curved_corridor()
    rp = RoadmapParams()
    start = cor.to_xy(np.array([station]), np.array([0.0]))[0]
    plan = plan_corridor(cor, obs, start, float(cor.heading_at(station)), roadmap_params=rp)
    tr = plan.trajectory
    assert np.hypot(tr.x[0] - start[0], tr.y[0] - start[1]) < 1e-6
    assert tr.feasible and footprint_violations(tr, cor, obs, rp) == (0, 0)
    assert abs(tr.s[-1] - (cor.length - station)) < 0.05 * (cor.length - station)
    assert all(cor.to_sl(rm.xy)[:, 0].min() >= station - 1e-6 for rm in plan.roadmaps)


def test_a_plan_goes_on_from_the_current_one_where_it_joins() -> None:
    """A replan that keeps the current plan up to a join and goes on with a new plan from
    the join's pose: one trajectory from the vehicle's sample, through the join without a
    jump in position, heading or speed, its speed profile run again from the vehicle's
    speed, and feasible (shapely) on the parked-car arc as both parts are."""
    cor, obs = curved_corridor()
    rp, tp = RoadmapParams(), TrajectoryParams()
    start = cor.to_xy(np.array([2.0]), np.array([-3.2]))[0]
    tr = plan_corridor(cor, obs, start, float(cor.heading_at(2.0)), roadmap_params=rp,
                       start_speed=8.0).trajectory
    first, join = 40, 200
    after = plan_corridor(cor, obs, tr.xy[join], float(tr.heading[join]), roadmap_params=rp,
                          start_speed=float(tr.speed[join])).trajectory
    out = continued(tr, first, join, after, tp, 9.0, 0.0)
    assert np.allclose(out.xy[0], tr.xy[first]) and out.s[0] == 0.0 and out.t[0] == 0.0
    assert np.allclose(out.xy[: join - first + 1], tr.xy[first:join + 1])
    assert np.allclose(out.xy[join - first:], after.xy)
    assert abs(out.s[-1] - (tr.s[join] - tr.s[first] + after.s[-1])) < 1e-6
    assert np.hypot(np.diff(out.x), np.diff(out.y)).max() < 0.6
    assert np.abs(np.diff(np.unwrap(out.heading))).max() < 0.05
    assert out.speed[0] == 9.0 and out.speed[-1] == 0.0
    dv2 = np.diff(out.speed**2) / (2 * np.maximum(np.diff(out.s), 1e-9))
    assert dv2.max() <= tp.a_max + 1e-6 and dv2.min() >= -tp.b_max - 1e-6
    assert out.feasible == (tr.feasible and after.feasible)
    assert out.feasible and footprint_violations(out, cor, obs, rp) == (0, 0)


def footprint_violations(tr: Trajectory, cor: Corridor, obs: Obstacles, rp: RoadmapParams,
                         end_room: float = 4.0) -> tuple[int, int]:
    """Samples whose footprint (shapely) touches an obstacle grown by the safety margin, and
    samples (``end_room`` [m] from the corridor's ends) whose footprint leaves the road shrunk
    by the trajectory's road margin."""
    hl, hw = rp.vehicle_length / 2, rp.vehicle_width / 2
    c, s = np.cos(tr.heading)[:, None], np.sin(tr.heading)[:, None]
    u, v = np.array([-hl, hl, hl, -hl]), np.array([-hw, -hw, hw, hw])
    rings = np.stack((tr.x[:, None] + c * u - s * v, tr.y[:, None] + s * u + c * v), axis=-1)
    feet = shapely.polygons(rings)
    grown = shapely.union_all([Polygon(p).buffer(rp.safety_margin - 1e-6)
                               for p in obs.polygons()])
    road = Polygon(cor.polygon()).buffer(-(tr.road_margin - 1e-6), join_style=2)
    st = cor.to_sl(tr.xy)[:, 0]
    inner = (st > end_room) & (st < cor.length - end_room)
    return (int(shapely.intersects(feet, grown).sum()),
            int((~shapely.contains(road, feet[inner])).sum()))


@pytest.mark.parametrize("seed", [0, 2])
def test_one_km_obstacle_field_is_feasible_and_continuous_at_the_joins(seed: int) -> None:
    """1 km of parked-car rows (the benchmark's density) in 300 m segments: level 2's widest
    path there zigzags across lanes between rows, and a join can fall into a lane change;
    the joined curve still keeps the margin (shapely) and is continuous at the joins."""
    from benchmarks.fields import obstacle_field

    cor, obs, start = obstacle_field(1000.0, 130, seed=seed)
    rp = RoadmapParams()
    roadmaps, tr = plan_corridor(cor, obs, start, 0.0, roadmap_params=rp)
    assert len(roadmaps) == 4
    assert tr.feasible
    assert footprint_violations(tr, cor, obs, rp) == (0, 0)
    assert np.abs(tr.curvature).max() <= TrajectoryParams().kappa_max + 1e-9
    # each later segment starts on the curve, with the curve's heading and speed there
    for rm in roadmaps[1:]:
        d = np.hypot(tr.x - rm.start_xy[0], tr.y - rm.start_xy[1])
        j = int(np.argmin(d))
        assert d[j] < 1e-9 and 0 < j < len(tr.x) - 1
        turn = np.abs(np.diff(np.unwrap(tr.heading[j - 1:j + 2])))
        assert turn.max() < 0.05
        assert abs(tr.speed[j + 1] - tr.speed[j - 1]) < 0.5
    step = np.hypot(np.diff(tr.x), np.diff(tr.y))
    assert step.max() < 0.6 and step.min() > 0.3
    # heading changes as the turning limit allows, joins included
    assert np.all(np.abs(np.diff(np.unwrap(tr.heading))) <= step / 5.0 * 1.05 + 1e-3)
    dv2 = np.diff(tr.speed**2) / (2 * np.maximum(np.diff(tr.s), 1e-9))
    assert dv2.max() <= 2.0 + 1e-6 and dv2.min() >= -4.0 - 1e-6
    assert tr.s[-1] > 990.0 and tr.speed[-1] == 0.0
    assert_wheels_keep_up(tr)  # the joins included
