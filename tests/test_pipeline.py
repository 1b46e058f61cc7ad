"""The three levels in one call, the obstacle-file reader and the ``plan`` command."""

from __future__ import annotations

import csv
import itertools
import json
import logging
from pathlib import Path

import numpy as np
import pytest
import sumolib
from conftest import GRID_TURNS

from splineplan.cli import main
from splineplan.corridor import ROAD_END_GAP
from splineplan.network import load_network, read_obstacles, route_corridor
from splineplan.obstacles import Obstacles
from splineplan.pipeline import plan
from splineplan.route import shortest_route
from splineplan.trajectory import TrajectoryParams

ROOT = Path(__file__).resolve().parent.parent
NETS = ROOT / "sumo_nets"
SCENARIOS = ROOT / "scenarios"


@pytest.fixture(scope="module")
def grid():
    return load_network(NETS / "grid.net.xml")


def test_plan_follows_level_one_and_joins_continuously(grid) -> None:
    result = plan(grid, "A0B0", "D3C3")
    assert result.route == shortest_route(grid, "A0B0", "D3C3")
    assert result.blocked == ()
    tr = result.trajectory
    # one continuous curve: no jumps between samples, time increasing, ends at rest
    steps = np.hypot(np.diff(tr.x), np.diff(tr.y))
    assert steps.max() < 2.0
    assert np.all(np.diff(tr.t) > 0)
    assert tr.speed[-1] == pytest.approx(0.0, abs=1e-6)
    # it runs the whole route: from the start of the first edge to the end of the last
    assert tr.s[-1] == pytest.approx(result.corridor.length, rel=0.05)
    assert min(result.route_seconds, result.roadmap_seconds, result.trajectory_seconds) > 0
    assert result.total_seconds == pytest.approx(
        result.route_seconds + result.roadmap_seconds + result.trajectory_seconds)


@pytest.mark.parametrize("end_pos", [12.0, 60.0, 125.0])
def test_plan_ends_at_the_arrival_position_sumolib_places(grid, end_pos: float) -> None:
    """``end_pos`` is SUMO's ``arrivalPos``: the plan stops there, on the last edge."""
    whole = plan(grid, "A0B0", "B0B1")
    result = plan(grid, "A0B0", "B0B1", end_pos=end_pos)
    lane = sumolib.net.readNet(str(NETS / "grid.net.xml")).getEdge("B0B1").getLanes()[0]
    goal = np.asarray(sumolib.geomhelper.positionAtShapeOffset(lane.getShape(), end_pos))
    tr = result.trajectory
    assert tr.feasible and tr.speed[-1] == pytest.approx(0.0, abs=1e-6)
    # the centre stops across the lanes from that position: within half the road's width
    # (two lanes of 3.2 m) of the lane's centre, and not before or beyond it
    end = np.array([tr.x[-1], tr.y[-1]])
    along = np.array([np.cos(tr.heading[-1]), np.sin(tr.heading[-1])])
    assert abs(float((end - goal) @ along)) < 1.0
    assert float(np.hypot(*(end - goal))) < 3.5
    assert result.corridor.length < whole.corridor.length - (129.2 - end_pos) + 5.0
    # the same route, only shorter
    assert result.route == whole.route


@pytest.mark.parametrize("end_pos", [None, 70.0])
def test_a_plan_to_a_dead_end_stops_with_the_front_inside_the_road(end_pos) -> None:
    """``e2`` of the straight network ends at a dead end (sumolib: its only way on is
    the turnaround): the car stops with its front bumper ``ROAD_END_GAP`` short of the
    lane's end, not with its centre there; an arrival position well before it holds."""
    net = load_network(NETS / "straight.net.xml")
    edge = sumolib.net.readNet(str(NETS / "straight.net.xml"),
                               withInternal=True).getEdge("e2")
    assert all(c.getDirection() == "t" for c in edge.getOutgoing() for c in
               edge.getConnections(c)) and net.dead_end("e2") and not net.dead_end("e1")
    result = plan(net, "e0", "e2", end_pos=end_pos)
    tr = result.trajectory
    assert tr.feasible and tr.speed[-1] == pytest.approx(0.0, abs=1e-6)
    shape = np.asarray(edge.getLanes()[0].getShape())
    along = (shape[-1] - shape[-2]) / np.hypot(*(shape[-1] - shape[-2]))
    front = np.array([tr.x[-1], tr.y[-1]]) + 2.25 * np.array(
        [np.cos(tr.heading[-1]), np.sin(tr.heading[-1])])
    to_end = float((shape[-1] - front) @ along)
    if end_pos is None:
        # the gap, to the corridor's sampling (a few centimetres)
        assert ROAD_END_GAP - 0.05 <= to_end <= ROAD_END_GAP + 0.5
    else:
        goal = np.asarray(sumolib.geomhelper.positionAtShapeOffset(shape.tolist(), end_pos))
        assert abs(float((np.array([tr.x[-1], tr.y[-1]]) - goal) @ along)) < 1.0


def test_plan_refuses_an_arrival_position_off_the_edge_or_behind_the_start(grid) -> None:
    from splineplan.errors import ParameterError

    with pytest.raises(ParameterError, match="outside edge 'B0B1'"):
        plan(grid, "A0B0", "B0B1", end_pos=1e4)
    with pytest.raises(ParameterError, match="not ahead of start_pos"):
        plan(grid, "A0B0", "A0B0", start_pos=100.0, end_pos=50.0)


def test_plan_reroutes_around_a_road_closed_by_stopped_cars(grid) -> None:
    cars = read_obstacles(grid, SCENARIOS / "blocked_road.rou.xml")
    direct = shortest_route(grid, "A1B1", "C1D1")
    assert "B1C1" in direct.edges
    result = plan(grid, "A1B1", "C1D1", cars)
    assert result.blocked == ("B1C1",)
    assert "B1C1" not in result.route.edges
    assert result.route == shortest_route(grid, "A1B1", "C1D1", avoid=["B1C1"])
    # the new trajectory keeps clear of the stopped cars
    assert float(np.min(cars.distance(result.trajectory.xy))) > 1.0


def test_plan_avoids_the_edge_entered_through_a_closed_junction(grid) -> None:
    """An obstacle inside junction C1 (its outline shrunk by 1.5 m): where level 2 finds the
    road closed within the junction, the edge it leads onto is avoided (not the edge
    before it), and the new route keeps clear of the junction."""
    from shapely.geometry import Polygon

    from splineplan.errors import RoadBlockedError
    from splineplan.obstacles import Obstacles
    from splineplan.roadmap import RoadmapParams, plan_roadmap

    sn = sumolib.net.readNet(str(NETS / "grid.net.xml"))
    inner = Polygon(sn.getNode("C1").getShape()).buffer(-1.5, join_style=2)
    block = Obstacles.from_polygons([np.asarray(inner.exterior.coords)])
    cor = route_corridor(grid, shortest_route(grid, "C0C1", "C1D1"))
    rp = RoadmapParams()
    with pytest.raises(RoadBlockedError) as info:
        plan_roadmap(cor, block, cor.to_xy(10.0, 0.0), rp)
    assert info.value.junction == ("C0C1", "C1D1") and info.value.closed_edge == "C1D1"
    assert "junction" in str(info.value)
    result = plan(grid, "A1B1", "D1D0", block)
    assert "C1D1" in result.blocked
    assert not {e for e in result.route.edges if "C1" in (e[:2], e[2:])}
    assert float(np.min(block.distance(result.trajectory.xy))) > 3.0


def test_read_obstacles_puts_stopped_cars_front_bumper_at_end_pos(grid) -> None:
    cars = read_obstacles(grid, SCENARIOS / "blocked_road.rou.xml")
    assert len(cars) == 2
    sn = sumolib.net.readNet(str(NETS / "grid.net.xml"))
    for i, lane_id in enumerate(("B1C1_0", "B1C1_1")):
        lane = sn.getLane(lane_id)
        front = np.array(sumolib.geomhelper.positionAtShapeOffset(lane.getShape(), 60.0))
        poly = cars.polygon(i)
        centre = poly.mean(axis=0)
        # the box's front edge midpoint is the bumper: the centre plus half a length ahead
        heading = np.array(lane.getShape()[-1]) - np.array(lane.getShape()[0])
        heading /= np.hypot(*heading)
        assert centre + 0.5 * np.ptp(poly @ heading) * heading == pytest.approx(front, abs=0.05)


def test_read_obstacles_errors(grid, tmp_path: Path) -> None:
    from splineplan.errors import NetworkError

    with pytest.raises(NetworkError, match="not found"):
        read_obstacles(grid, tmp_path / "missing.add.xml")
    bad = tmp_path / "bad.rou.xml"
    bad.write_text('<routes><vehicle id="v"><stop lane="nowhere_0" endPos="5"/></vehicle>'
                   "</routes>")
    with pytest.raises(NetworkError, match="nowhere_0"):
        read_obstacles(grid, bad)


def test_plan_command_writes_trajectory_plan_and_picture(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out, png = tmp_path / "plan", tmp_path / "plan.png"
    rc = main(["plan", str(NETS / "straight.net.xml"), "e0", "e2", "--obstacles",
               str(SCENARIOS / "one_obstacle.rou.xml"), "--out", str(out), "--plot", str(png)])
    assert rc == 0
    text = capsys.readouterr().out
    assert "route: e0 e1 e2" in text and "level 3" in text
    with (out / "trajectory.csv").open() as fh:
        rows = list(csv.DictReader(fh))
    assert {"t", "x", "y", "heading", "speed", "curvature"} <= set(rows[0])
    saved = json.loads((out / "plan.json").read_text())
    assert saved["meta"]["route"] == ["e0", "e1", "e2"]
    assert png.stat().st_size > 10_000


def test_plan_command_places_the_vertices_for_the_separation(tmp_path: Path) -> None:
    """``--place``: level 2 places the vertices (recorded in plan.json with each vertex's
    separation) and the trajectory keeps at least the separation of the paper's
    midpoints from the parked car."""
    clear = {}
    for flag in ([], ["--place"]):
        out = tmp_path / ("placed" if flag else "midpoints")
        rc = main(["plan", str(NETS / "straight.net.xml"), "e0", "e2", "--obstacles",
                   str(SCENARIOS / "one_obstacle.rou.xml"), "--out", str(out), *flag])
        saved = json.loads((out / "plan.json").read_text())
        assert rc == 0 and saved["trajectory"]["feasible"]
        rm = saved["roadmaps"][0]
        assert rm["params"]["place"] == bool(flag)
        assert (len(rm["separation"]) == len(rm["s"])) == bool(flag)
        clear[bool(flag)] = saved["trajectory"]["min_clearance"]
    assert clear[True] >= clear[False]


def test_plan_command_says_which_limit_an_infeasible_plan_breaks_and_where(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """The README's city example: a warning exactly when the plan is infeasible, one line
    per broken limit (as plan.json lists them), each naming the station and the route's
    edge or junction there."""
    out = tmp_path / "plan"
    rc = main(["plan", str(NETS / "city.net.xml"), "SWA0", "G1G2", "--out", str(out)])
    err = capsys.readouterr().err
    saved = json.loads((out / "plan.json").read_text())
    found, route = saved["trajectory"]["violations"], saved["meta"]["route"]
    assert rc == 0 and saved["trajectory"]["feasible"] == (not found)
    if not found:
        assert "not feasible" not in err
        return
    lines = err.strip().splitlines()
    assert "not feasible" in lines[0]
    assert len(lines) == 1 + min(len(found), 5) + (len(found) > 5)
    for line, v in zip(lines[1:], found, strict=False):
        assert v["kind"] in ("obstacle", "road", "curvature")
        assert ("curvature" if v["kind"] == "curvature" else "footprint") in line
        assert "station" in line and any(e in line for e in route)


def test_plan_command_errors_are_one_line(tmp_path: Path,
                                          capsys: pytest.CaptureFixture[str]) -> None:
    rc = main(["plan", str(NETS / "straight.net.xml"), "e0", "e2", "--obstacles",
               str(tmp_path / "missing.xml")])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and len(err) == 1 and "missing.xml" in err[0]


# Routes on Monaco that once failed: lane shapes overlapping at a join (1729#3 -> 1729#4,
# 1727#1 -> 1727#2-AddedOnRampEdge) and a shortest route ending in a turnaround
# (-> -1645#2).
MONACO_ROUTES = [("-756#1", "1729#4"), ("2131#10", "-1645#2"), ("-427882#3", "-1778#0")]


def test_monaco_routes_plan_forward(monaco_net) -> None:
    from splineplan.pipeline import turnarounds

    net = load_network(monaco_net)
    for a, b in MONACO_ROUTES:
        result = plan(net, a, b)
        assert result.route.edges[0] == a and result.route.edges[-1] == b
        assert turnarounds(net, result.route) == ()
        cor = result.corridor
        assert np.all(cor.left - cor.right >= 3.0 - 1e-9)
        tr = result.trajectory
        assert np.hypot(np.diff(tr.x), np.diff(tr.y)).max() < 2.0
        assert tr.s[-1] == pytest.approx(cor.length, rel=0.05)


def test_a_turnaround_segment_is_planned_once(monaco_net, caplog) -> None:
    """Monaco -1511#1 -> -2423 must turn back from 2423 onto -2423 (a dead end), 1.75 km
    in. The segments before the turnaround's are planned as without the hint; the
    turnaround's segment is planned once, without moves, and reported infeasible, with
    the curvature beyond the turning limit at the turnaround."""
    from splineplan.pipeline import turnarounds
    from splineplan.planner import plan_corridor

    net = load_network(monaco_net)
    result = plan(net, "-1511#1", "-2423")
    route, cor = result.route, result.corridor
    back = [(route.edges[i], route.edges[i + 1]) for i in turnarounds(net, route)]
    assert back == [("2423", "-2423")]
    tr = result.trajectory
    assert not tr.feasible
    at = float(cor.edge_ends[route.edges.index("2423")])
    st = cor.to_sl(tr.xy)[:, 0]
    turning = np.abs(st - at) < 15.0
    assert np.abs(tr.curvature[turning]).max() > TrajectoryParams().kappa_max
    start = cor.to_xy(0.0, 0.0)
    heading = float(cor.heading_at(0.0))
    tries, plans = [], []
    for hint in (back, ()):
        caplog.clear()
        with caplog.at_level(logging.DEBUG, logger="splineplan.trajectory"):
            plans.append(plan_corridor(cor, Obstacles.empty(), start, heading,
                                       turnarounds=hint))
        tries.append(sum("the other:" in r.getMessage() for r in caplog.records))
    hinted, plain = plans
    # without the hint the turnaround's segment also tries the other control polygon,
    # and equation (3)'s moves
    assert tries[0] < tries[1]
    assert hinted.trajectory.iterations.tried < plain.trajectory.iterations.tried
    np.testing.assert_array_equal(hinted.trajectory.x, tr.x)
    # the same curve up to the turnaround's segment (it starts at most 300 m before it)
    ahead = np.flatnonzero(st < at - 300.0 - 30.0)
    assert len(ahead) > 1000
    np.testing.assert_array_equal(plain.trajectory.x[ahead], tr.x[ahead])
    np.testing.assert_array_equal(plain.trajectory.y[ahead], tr.y[ahead])
    assert not plain.trajectory.feasible


def test_a_lane_kink_the_car_can_drive_is_planned_feasible(monaco_net) -> None:
    """A replan of the Monaco scenario at 8.9 m/s, 5 m before a 37 degree kink of the
    single lane of -2081#1: the least-bending polygon's curve used to leave the lane by
    0.15 m and the other polygon's to turn tighter than the car. The polygon that spreads
    the turn over the lane gives a feasible curve, truly: its footprint stays on SUMO's
    paving (shapely, within 0.05 m for the lanes' buffers) and it keeps the turning limit."""
    from oracle import paved_area
    from shapely import affinity
    from shapely.geometry import MultiPoint, box

    from splineplan.planner import plan_corridor

    net = load_network(monaco_net)
    route = shortest_route(net, "-1718#11", "1756#0", turnarounds=False, start_pos=20.0)
    cor = route_corridor(net, route)
    xy = np.array([4381.620244, 1866.317861])
    s0 = float(cor.to_sl(xy[None])[0, 0])
    window = cor.slice(s0 - 4.5, s0 + 100.0)
    plan = plan_corridor(window, Obstacles.empty(), xy, -2.742427499, start_speed=8.9427917,
                         end_speed=None)
    tr = plan.trajectory
    assert tr.feasible, tr.violations
    assert float(np.max(np.abs(tr.curvature))) <= TrajectoryParams().kappa_max * (1 + 1e-6)
    paved = paved_area(monaco_net, MultiPoint(tr.xy).buffer(10.0)).buffer(0.05)
    base = box(-2.25, -0.9, 2.25, 0.9)
    for x, y, h in zip(tr.x, tr.y, tr.heading, strict=True):
        fp = affinity.translate(affinity.rotate(base, h, origin=(0, 0), use_radians=True), x, y)
        assert paved.contains(fp)


@pytest.mark.parametrize(("start", "goal"), GRID_TURNS)
def test_junction_turns_are_feasible_and_stay_on_the_pavement(grid, start: str,
                                                              goal: str) -> None:
    """Through SUMO's junctions the trajectory keeps the turning limit and the margin, and
    the vehicle's footprint stays on the paved area (shapely, from sumolib's lanes and
    junction outlines)."""
    from oracle import paved_area
    from shapely import affinity
    from shapely.geometry import box
    from shapely.ops import unary_union

    result = plan(grid, start, goal)
    tr = result.trajectory
    rp = result.roadmaps[0].params
    assert tr.feasible
    assert float(np.max(np.abs(tr.curvature))) <= TrajectoryParams().kappa_max + 1e-9
    base = box(-rp.vehicle_length / 2, -rp.vehicle_width / 2,
               rp.vehicle_length / 2, rp.vehicle_width / 2)
    swept = unary_union([
        affinity.translate(affinity.rotate(base, h, origin=(0, 0), use_radians=True), x, y)
        for x, y, h in zip(tr.x[::2], tr.y[::2], tr.heading[::2], strict=True)])
    outside = swept.difference(paved_area(NETS / "grid.net.xml"))
    assert outside.area < 0.05, outside.area


@pytest.mark.parametrize(("net_name", "start", "goal"), [
    ("grid.net.xml", "A1B1", "B1B0"),
    ("grid.net.xml", "A2A3", "D0D1"),
    ("grid.net.xml", "B1C1", "C2D2"),
    ("city.net.xml", "SWA0", "G1G2"),
])
def test_junctions_are_entered_from_a_lane_that_leads_on(net_name: str, start: str,
                                                         goal: str) -> None:
    """Where the route leaves an edge, the vehicle's centre is on a lane that has a
    connection to the next route edge (SUMO maps the vehicle into the junction, and its
    signals and right of way hold, only from those): checked against sumolib's lanes and
    connections, not the package's."""
    from shapely.geometry import LineString, Point

    result = plan(load_network(NETS / net_name), start, goal)
    snet = sumolib.net.readNet(str(NETS / net_name), withInternal=True)
    tr = result.trajectory
    xy = np.column_stack((tr.x, tr.y))
    edges = result.route.edges
    for a, b in itertools.pairwise(edges[1:]):
        lanes = snet.getEdge(a).getLanes()
        onward = {c.getFromLane().getIndex() for c in snet.getEdge(a).getOutgoing()[
            snet.getEdge(b)]}
        # the trajectory sample nearest to where the lanes end, 2 m before it
        end = LineString(lanes[0].getShape()).interpolate(-2.0)
        i = int(np.argmin(np.hypot(*(xy - np.array(end.coords[0])).T)))
        at = Point(xy[i])
        dist = {ln.getIndex(): LineString(ln.getShape()).distance(at) for ln in lanes}
        nearest = min(dist, key=dist.__getitem__)
        assert nearest in onward, (a, b, nearest, onward)


def test_car_parked_in_the_turning_lane_is_passed_without_rerouting(grid) -> None:
    """A car stopped in the only lane that turns right, 8 m before the junction: the
    vehicle passes it in the other lane and turns from there rather than re-routing."""
    from splineplan.obstacles import Obstacles

    assert {c.from_lane for c in grid.connections_between("B1C1", "C1C0")} == {0}
    shape = grid.lanes_of("B1C1")[0].shape
    d = (shape[-1] - shape[0]) / np.hypot(*(shape[-1] - shape[0]))
    car = Obstacles.from_boxes((shape[-1] - 8.0 * d)[None], [float(np.arctan2(d[1], d[0]))],
                               [4.5], [1.8], reference="front")
    result = plan(grid, "A1B1", "C1C0", car)
    assert result.route.edges == ("A1B1", "B1C1", "C1C0") and result.blocked == ()
    assert float(np.min(car.distance(result.trajectory.xy))) > 1.0
