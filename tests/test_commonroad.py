"""CommonRoad scenarios in, certified solutions out (:mod:`splineplan.commonroad`).

Each bundled public scenario (tests/data/commonroad, sources in its README) is solved and
the solution judged by commonroad-drivability-checker itself: no collision with any obstacle
at its time, the car inside the road boundary, ``trajectory_feasibility`` with the KS model
(and, stricter, with the wheel angle reached at every step, as in
``test_commonroad_judge``), the planning problem's goal reached, and the start state right.
"""

from __future__ import annotations

import subprocess
import sys
import tarfile
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from conftest import ROOT

from splineplan.corridor import ROAD_END_GAP

cr = pytest.importorskip("splineplan.commonroad")
pytest.importorskip("commonroad_dc.feasibility.feasibility_checker",
                    reason="commonroad-drivability-checker is a test extra")

DATA = ROOT / "tests" / "data" / "commonroad"


@pytest.fixture(scope="module")
def solved() -> dict[str, cr.CommonRoadPlan]:
    """Each bundled scenario that has a solution, solved once for the module."""
    out = {}
    for name in ("ZAM_Urban-3_1", "ZAM_Urban-2_1", "USA_US101-16_1_T-1", "USA_Lanker-1_16_T-1",
                 "RUS_Bicycle-11_1_T-1"):
        out[name] = cr.plan(cr.read(DATA / f"{name}.xml"))
    return out


def _strictly_feasible(res: cr.CommonRoadPlan) -> bool:
    """``trajectory_feasibility`` whose reconstructed inputs also reach every state's wheel
    angle (CommonRoad's own criteria compare only the pose)."""
    from commonroad_dc.feasibility import feasibility_checker as fc
    from commonroad_dc.feasibility.vehicle_dynamics import VehicleDynamics, VehicleType
    from test_commonroad_judge import _reach_steering, _with_steering

    ok, _ = fc.trajectory_feasibility(
        cr.solution_trajectory(res), VehicleDynamics.KS(VehicleType(res.vehicle.type_id)),
        res.problem.dt, objective=_reach_steering, criteria=_with_steering)
    return bool(ok)


@pytest.mark.parametrize("name", ["ZAM_Urban-3_1", "ZAM_Urban-2_1", "USA_US101-16_1_T-1",
                                  "USA_Lanker-1_16_T-1", "RUS_Bicycle-11_1_T-1"])
def test_solutions_pass_the_drivability_checker(solved: dict[str, cr.CommonRoadPlan],
                                                name: str) -> None:
    res = solved[name]
    cert = cr.certify(res)
    assert cert == cr.Certificate(True, True, True, True, True)
    assert res.goal_reached
    assert _strictly_feasible(res)
    # the solution ends at the first state that reaches the goal
    goal = res.problem.planning_problem.goal
    assert goal.is_reached(res.states[-1])
    assert not any(goal.is_reached(s) for s in res.states[:-1])


def test_static_obstacles_are_passed_with_room(solved: dict[str, cr.CommonRoadPlan]) -> None:
    """The hand-made scenarios' static obstacles stand in the lane: the car goes round
    them, keeping level 2's safety margin from its footprint (less the centimetres between
    the planner's centre and CommonRoad's reference point)."""
    import shapely

    for name in ("ZAM_Urban-3_1", "ZAM_Urban-2_1"):
        res = solved[name]
        assert len(res.problem.scenario.static_obstacles) >= 1
        polys = [shapely.Polygon(p) for p in cr.static_obstacles(res.problem.scenario).polygons()]
        gaps = [min(box.distance(p) for p in polys) for box in _ks_boxes(res)]
        assert min(gaps) > 0.1


def test_a_lane_change_and_an_intersection_turn(solved: dict[str, cr.CommonRoadPlan]) -> None:
    """Level 1 on the lanelet graph: the freeway's goal is in the next lane (a lane
    change), the Lankershim goal beyond a turn at an intersection."""
    lane = solved["USA_US101-16_1_T-1"]
    assert lane.route.lane_changes >= 1
    net = lane.problem.scenario.lanelet_network
    first = net.find_lanelet_by_id(lane.route.lanelets[0])
    assert lane.route.lanelets[1] in (first.adj_left, first.adj_right)
    turn = solved["USA_Lanker-1_16_T-1"]
    heading = np.unwrap([s.orientation for s in turn.states])
    assert np.ptp(heading) > 0.5  # it turns through the junction


def test_the_solution_file_reads_back(tmp_path: Path,
                                      solved: dict[str, cr.CommonRoadPlan]) -> None:
    from commonroad.common.solution import (
        CommonRoadSolutionReader,
        CostFunction,
        VehicleModel,
        VehicleType,
    )

    res = solved["ZAM_Urban-3_1"]
    path = cr.write_solution(res, tmp_path / "out")
    sol = CommonRoadSolutionReader.open(str(path))
    pps = sol.planning_problem_solutions[0]
    assert pps.vehicle_model == VehicleModel.KS
    assert pps.vehicle_type == VehicleType.BMW_320i
    assert pps.cost_function == CostFunction.SM1
    assert len(pps.trajectory.state_list) == len(res.states)
    assert np.allclose(pps.trajectory.state_list[-1].position, res.states[-1].position)


@pytest.mark.parametrize("vehicle_type", [1, 3])
def test_other_vehicle_types(vehicle_type: int) -> None:
    """The Ford Escort and the VW Vanagon, with their own wheelbase and steering limits."""
    res = cr.plan(cr.read(DATA / "ZAM_Urban-3_1.xml"), vehicle_type=vehicle_type)
    assert res.vehicle.type_id == vehicle_type
    assert cr.certify(res).passed


def test_the_vehicle_is_commonroads() -> None:
    """BMW 320i: CommonRoad's wheelbase, steering rate and body for levels 2 and 3."""
    car = cr.vehicle(2)
    assert car.wheelbase == pytest.approx(2.578, abs=1e-3)
    assert car.max_steering_rate == pytest.approx(0.4)
    tp = car.trajectory_params(20.0)
    assert tp.wheelbase == car.wheelbase and tp.max_steering_rate == car.max_steering_rate
    rp = car.roadmap_params()
    assert (rp.vehicle_length, rp.vehicle_width) == (car.length, car.width)


def test_the_core_imports_no_commonroad() -> None:
    """splineplan works without the extra: the planner and the CLI import nothing of
    commonroad, and without it the adapter says so in one line."""
    code = ("import sys; import splineplan.cli, splineplan.planner, splineplan.pipeline; "
            "assert not [m for m in sys.modules if m.startswith(('commonroad', 'vehiclemodels'))]; "
            "sys.modules['commonroad'] = None\n"
            "from splineplan import commonroad as cr\n"
            "from splineplan.errors import SplineplanError\n"
            "try:\n    cr.read('x.xml')\nexcept SplineplanError as e:\n    print(e)\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         cwd=ROOT, check=True)
    assert out.stdout.strip() == ("CommonRoad support needs the commonroad extra: "
                                  "pip install 'splineplan[commonroad]'")


def test_the_command_writes_the_solution_and_the_picture(tmp_path: Path) -> None:
    from splineplan.cli import main

    out = tmp_path / "out"
    assert main(["commonroad", str(DATA / "ZAM_Urban-3_1.xml"), "--out", str(out),
                 "--plot"]) == 0
    names = sorted(p.name for p in out.iterdir())
    assert names == ["ZAM_Urban-3_1.png", "solution_KS2:SM1:ZAM_Urban-3_1:2018b.xml"]


def test_the_picture_frames_what_the_car_drives() -> None:
    """The figure of a plan is framed on the driven part, the goal and the static
    obstacles near them, not on the whole route: on ZAM_Urban-2_1 the route runs 209 m and
    the solution drives about 60 m of it, and each of those must be readable."""
    from splineplan.plot import FRAME_PAD, FRAME_REACH, plot_commonroad

    res = cr.plan(cr.read(DATA / "ZAM_Urban-2_1.xml"))
    net = res.problem.scenario.lanelet_network
    route = [cr.lanelet_outline(net.find_lanelet_by_id(i)) for i in res.route.lanelets]
    drove = cr.driven(res)
    fig = plot_commonroad(cr.lanelet_polygons(res.problem.scenario), res.obstacles, drove,
                          route=route, goal=cr.goal_outlines(res.goal))
    ax = fig.axes[0]
    (x0, x1), (y0, y1) = ax.get_xlim(), ax.get_ylim()
    xy = np.column_stack((drove.x, drove.y))
    assert x0 <= xy[:, 0].min() and xy[:, 0].max() <= x1
    assert y0 <= xy[:, 1].min() and xy[:, 1].max() <= y1
    lo, hi = xy.min(axis=0) - FRAME_REACH, xy.max(axis=0) + FRAME_REACH
    for poly in res.obstacles.polygons():
        if np.all((poly >= lo) & (poly <= hi)):
            assert x0 <= poly[:, 0].min() and poly[:, 0].max() <= x1
    route_span = np.ptp(np.vstack(route)[:, 0])
    assert x1 - x0 < 0.6 * route_span
    assert x1 - x0 >= np.ptp(xy[:, 0]) + 2 * FRAME_PAD - 1e-9


def test_the_path_passes_through_a_goal_box_beside_its_lane() -> None:
    """A goal where a recorded car was is often a box narrower than a lane, or in the lane
    beside the path's: the car's centre must pass through it. On a straight three-lane road
    (9.6 m), from the right lane, a 2 x 1.6 m goal box in the left lane 80 m ahead: the
    trajectory's centre passes through the box (shapely) with the goal's keep offsets, and
    stays in its own lane without them."""
    from shapely.geometry import Point, box

    from splineplan.corridor import Corridor
    from splineplan.planner import plan_corridor

    line = np.column_stack((np.linspace(0.0, 200.0, 201), np.zeros(201)))
    road = Corridor.from_reference(line, np.full(201, 4.8), np.full(201, -4.8))
    goal_box = box(79.0, 2.4, 81.0, 4.0)
    goal = cr.Goal(steps=((0, 10**6),), shapes=(goal_box,), speed=(None,),
                   orientation=(None,), lanelets=())
    start = np.array([5.0, -3.2])

    def through(corridor: Corridor) -> bool:
        tr = plan_corridor(corridor, None, start, 0.0, start_speed=10.0).trajectory
        assert tr.feasible
        return any(goal_box.contains(Point(x, y)) for x, y in tr.xy)

    assert not through(road)
    kept = cr.goal_keep(road, goal)
    assert through(kept)
    lo, hi = kept.keep_at(np.array([80.0, 0.0]))
    assert lo[0] == pytest.approx(2.4 + cr.GOAL_INSET)
    assert hi[0] == pytest.approx(4.0 - cr.GOAL_INSET)
    assert hi[1] - lo[1] > 20.0  # far from the goal the whole road will do


ARCHIVE = ROOT / "benchmarks" / "data" / "commonroad_scenarios.tar.xz"


@pytest.fixture(scope="module")
def archived(tmp_path_factory: pytest.TempPathFactory) -> Callable[[str], cr.Problem]:
    """A scenario of the benchmark's archive (sources in benchmarks/data/README.md)."""
    folder = tmp_path_factory.mktemp("commonroad")

    def read(name: str) -> cr.Problem:
        path = folder / f"{name}.xml"
        with tarfile.open(ARCHIVE) as tar:
            member = tar.extractfile(f"{name}.xml")
            assert member is not None
            path.write_bytes(member.read())
        return cr.read(path)

    return read


def _ks_boxes(res: cr.CommonRoadPlan) -> list[Any]:
    """The car's rectangle at each state, where CommonRoad's checker puts it."""
    import shapely

    hl, hw = res.vehicle.length / 2, res.vehicle.width / 2
    out = []
    for st in res.states:
        c, s = np.cos(st.orientation), np.sin(st.orientation)
        out.append(shapely.Polygon([st.position + a * np.array([c, s]) + b * np.array([-s, c])
                                    for a, b in ((-hl, -hw), (hl, -hw), (hl, hw), (-hl, hw))]))
    return out


def _gaps(res: cr.CommonRoadPlan, obstacle_id: int) -> list[float]:
    """Distance [m] from the car's rectangle (CommonRoad's) to a dynamic obstacle's at
    each state where the obstacle is there."""
    ob = res.problem.scenario.obstacle_by_id(obstacle_id)
    gaps = []
    for st, box in zip(res.states, _ks_boxes(res), strict=True):
        other = ob.occupancy_at_time(st.time_step)
        if other is not None:
            gaps.append(box.distance(other.shape.shapely_object))
    return gaps


def test_a_goal_that_asks_for_speed_where_a_cyclist_stops_is_met_before_it(
        archived: Callable[[str], cr.Problem], monkeypatch: pytest.MonkeyPatch) -> None:
    """RUS_Bicycle-2_1: a cyclist crosses towards the lane and stops with half a metre of
    its wheel in it, where the goal asks for 5-15 m/s within 2-3.1 s. Driving as fast as
    allowed waits behind it, too slow in the goal's window; the meeting profile is in the
    goal at its speed before the cyclist, certified, keeping the moving obstacles' margin
    (less the centimetres between the planner's body and CommonRoad's)."""
    problem = archived("RUS_Bicycle-2_1_T-1")
    res = cr.plan(problem)
    assert cr.certify(res).passed
    lo, hi = res.goal.speed[0]  # type: ignore[misc]
    assert lo <= res.states[-1].velocity <= hi
    assert min(_gaps(res, 1)) > cr.MOVING_MARGIN / 2
    monkeypatch.setattr(cr._Timing, "meet", lambda *args: None)
    waited = cr.plan(archived("RUS_Bicycle-2_1_T-1"))
    assert "1" in waited.yielded and not waited.goal_reached


def test_a_goal_just_behind_a_stopping_cyclist_is_met_with_the_moving_margin(
        archived: Callable[[str], cr.Problem], monkeypatch: pytest.MonkeyPatch) -> None:
    """RUS_Bicycle-4_1: a cyclist slows to a stop in the lane, and the goal asks for speed
    (with a time window) just behind it, where the recorded car was. The solution is
    certified and keeps the margin from the cyclist throughout (less the centimetres
    between the planner's body and CommonRoad's); with half a metre of margin the goal
    could not be reached."""
    res = cr.plan(archived("RUS_Bicycle-4_1_T-1"))
    assert cr.certify(res).passed
    assert min(_gaps(res, 1)) > cr.MOVING_MARGIN / 2
    monkeypatch.setattr(cr, "MOVING_MARGIN", 0.5)
    assert not cr.plan(archived("RUS_Bicycle-4_1_T-1")).goal_reached


def test_a_goal_that_asks_for_speed_behind_traffic_is_met(
        archived: Callable[[str], cr.Problem], monkeypatch: pytest.MonkeyPatch) -> None:
    """USA_US101-17_1: the goal asks for 18.28-24.28 m/s, behind a car that the speed plan
    follows. Keeping half a metre from the traffic, no speed cap gets there faster than
    18.27 m/s. The meeting profile (slower first, then the goal's speed at a step of its
    window) reaches it, certified, clear of the traffic."""
    monkeypatch.setattr(cr, "MOVING_MARGIN", 0.5)
    problem = archived("USA_US101-17_1_T-1")
    res = cr.plan(problem)
    assert cr.certify(res).passed
    lo, hi = res.goal.speed[0]  # type: ignore[misc]
    assert lo <= res.states[-1].velocity <= hi
    monkeypatch.setattr(cr._Timing, "meet", lambda *args: None)
    assert not cr.plan(archived("USA_US101-17_1_T-1")).goal_reached


def test_a_plan_that_misses_its_goal_stops_inside_the_road(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """A goal no car can reach in time (RUS_Bicycle-11's box two steps after the start) on
    a road that ends: the plan runs on to the road's end and stops with the car's front
    inside it, so the solution stays road-compliant by CommonRoad's own check."""
    import shapely
    from commonroad.common.util import Interval

    problem = cr.read(DATA / "RUS_Bicycle-11_1_T-1.xml")
    problem.planning_problem.goal.state_list[0].time_step = Interval(1, 2)
    res = cr.plan(problem)
    assert not res.goal_reached
    net = problem.scenario.lanelet_network
    assert not net.find_lanelet_by_id(res.route.chain[-1]).successor  # the road ends
    cert = cr.certify(res)
    assert cert.road_compliant and cert.collision_free and not cert.goal_reached
    end = net.find_lanelet_by_id(res.route.chain[-1]).center_vertices[-1]
    front = _ks_boxes(res)[-1]
    assert front.distance(shapely.Point(end)) >= ROAD_END_GAP - 0.05


@pytest.mark.parametrize("limit", [11.0, 8.0])
def test_posted_speed_limits_are_kept_where_asked(limit: float) -> None:
    """A ``MAX_SPEED`` sign posted on every lanelet of a scenario whose plan drives faster
    (11 m/s; 8 m/s, below the start's 9.53 m/s, braked to within the first two of the
    checker's steps of 0.25 s): with ``speed_limits`` no state (after those, where it
    brakes) is faster than the sign allows, and the solution still passes the
    drivability checker; without it the sign is not read."""
    from commonroad.scenario.traffic_sign import (
        TrafficSign,
        TrafficSignElement,
        TrafficSignIDZamunda,
    )

    problem = cr.read(DATA / "ZAM_Urban-2_1.xml")
    net = problem.scenario.lanelet_network
    free = cr.plan(problem)
    assert max(s.velocity for s in free.states) > 12.0
    every = {ll.lanelet_id for ll in net.lanelets}
    signs = [TrafficSignElement(TrafficSignIDZamunda.MAX_SPEED, [v])
             for v in (str(limit), "16.0")]
    first = net.find_lanelet_by_id(free.route.lanelets[0]).center_vertices[0]
    net.add_traffic_sign(TrafficSign(problem.scenario.generate_object_id(), signs, every,
                                     np.array(first)), every)
    assert cr.posted_speed_limits(net) == dict.fromkeys(every, limit)
    kept = cr.plan(problem, speed_limits=True)
    braking = 2 if limit < kept.states[0].velocity else 0  # steps it may take to brake
    assert max(s.velocity for s in kept.states[braking:]) <= limit + 1e-6
    assert cr.certify(kept).passed
    assert max(s.velocity for s in cr.plan(problem).states) > 12.0


@pytest.mark.parametrize("name", ["DEU_Muc-22_1_T-1", "DEU_Ffb-2_2_T-1"])
def test_a_turn_is_taken_as_fast_as_the_single_track_cars_steering_allows(
        archived: Callable[[str], cr.Problem], name: str) -> None:
    """The wheels of CommonRoad's car (the rear axle towed behind the centre) lag the
    path's curvature, so they turn more slowly than a steady turn at each point would ask:
    the speed the steering rate allows is the towed wheels'. ``DEU_Muc-22_1``: the goal's
    window opens 19.4 s after the start, past two tight turns, which the car now takes
    fast enough (with the steady turn's limit it crawled through at 1.6 m/s and came 3 s
    late). ``DEU_Ffb-2_2``: the path starts into a curve that the steady turn's limit
    entered below the start's speed (the start state was wrong, and the goal late).
    Certified, and the wheel angle of every state reached at the rate (0.4 rad/s) the
    checker allows."""
    res = cr.plan(archived(name))
    assert cr.certify(res).passed
    assert _strictly_feasible(res)
