"""Closed loop in the real SUMO (libsumo): bundled scenarios end to end, obstacles read from
SUMO, re-routing, appearing obstacles, and clear errors with the record written out."""

from __future__ import annotations

import csv
import dataclasses
import itertools
import json
import math
import re
import sys
import time
import xml.etree.ElementTree as ET
from collections.abc import Iterator
from pathlib import Path

import libsumo
import numpy as np
import pytest
import sumolib
from conftest import NETS, ROOT
from hypothesis import given, settings
from hypothesis import strategies as st
from shapely.geometry import LineString, Polygon
from test_speed import towed_by_ode

from splineplan.errors import (
    ScenarioError,
    SimulationError,
    UnknownEdgeError,
    VehicleClassError,
)
from splineplan.geometry import FloatArray
from splineplan.metrics import box_distances, footprint
from splineplan.network import load_network, route_corridor
from splineplan.roadmap import RoadmapParams, plan_roadmap
from splineplan.route import shortest_route
from splineplan.scenario import load_scenario
from splineplan.sim import SimResult, simulate, stopped_vehicle_obstacles

SCENARIOS = ROOT / "scenarios"
#: Long runs, in the slow tests: Monaco (needs ../shared/data) and the city among busy traffic.
LONG = {"monaco", "city_traffic"}
#: Scenarios with several planned vehicles: tests/test_multi.py.
MULTI = {"two_side_by_side"}
BUNDLED = sorted(p.stem for p in SCENARIOS.glob("*.toml") if p.stem not in LONG | MULTI)


def _run(name: str, out: Path, **kw: object) -> SimResult:
    return simulate(load_scenario(SCENARIOS / f"{name}.toml"), out_dir=out, progress=False,
                    **kw)  # type: ignore[arg-type]


def _fcd(path: Path) -> dict[float, dict[str, tuple[float, float, float, float]]]:
    """SUMO's own record: per time, per vehicle (x, y, angle, speed) of the front bumper."""
    out: dict[float, dict[str, tuple[float, float, float, float]]] = {}
    for step in ET.parse(path).getroot().iter("timestep"):
        t = round(float(step.get("time", "nan")), 3)
        out[t] = {v.get("id", ""): (float(v.get("x", "nan")), float(v.get("y", "nan")),
                                    float(v.get("angle", "nan")), float(v.get("speed", "nan")))
                  for v in step.iter("vehicle")}
    return out


def _vehicle_sizes(*paths: Path) -> dict[str, tuple[float, float]]:
    """Length and width [m] of each vehicle, trip and flow of SUMO route files, by id."""
    types: dict[str, tuple[float, float]] = {}
    out: dict[str, tuple[float, float]] = {}
    for path in paths:
        root = ET.parse(path).getroot()
        for t in root.iter("vType"):
            types[t.get("id", "")] = (float(t.get("length", "5")), float(t.get("width", "1.8")))
        for tag in ("vehicle", "trip", "flow"):
            for v in root.iter(tag):
                out[v.get("id", "")] = types.get(v.get("type", ""), (5.0, 1.8))
    return out


def _sumo_box(x: float, y: float, angle: float, length: float, width: float) -> Polygon:
    """A vehicle's rectangle from SUMO's front-bumper position and navigational angle,
    computed here without the package's geometry."""
    a = math.radians(angle)
    fwd = np.array([math.sin(a), math.cos(a)])  # 0 = north, clockwise
    left = np.array([-fwd[1], fwd[0]])
    front = np.array([x, y])
    rear = front - length * fwd
    pts = [rear - width / 2 * left, front - width / 2 * left, front + width / 2 * left,
           rear + width / 2 * left]
    return Polygon(pts)


@pytest.fixture(scope="module")
def runs(tmp_path_factory: pytest.TempPathFactory) -> dict[str, SimResult]:
    """Every bundled scenario (Monaco aside), run once for the whole module."""
    base = tmp_path_factory.mktemp("runs")
    return {name: _run(name, base / name) for name in BUNDLED}


@pytest.mark.parametrize("name", BUNDLED)
def test_bundled_scenario_end_to_end(runs: dict[str, SimResult], name: str) -> None:
    r = runs[name]
    m = r.metrics
    assert r.arrived, r.reason
    assert m["status"] == "arrived" and m["arrived"] is True
    assert m["collisions"] == 0, m["collision_events"][:3]
    assert m["time_off_road"] == 0.0
    margin = m["safety_margin"]
    if m["min_clearance_obstacles"] is not None:
        assert m["min_clearance_obstacles"] >= margin - 1e-6
    assert m["position_error_max"] < 1e-3  # SUMO put the ego where the plan said
    assert m["route"][-1] == load_scenario(SCENARIOS / f"{name}.toml").ego.goal_edge
    assert m["distance"] > 0.9 * m["route_length"] - 30.0
    assert m["planning_time"]["count"] == m["replan_count"] >= 1
    for f in ("metrics.json", "trajectory.csv", "fcd.xml"):
        assert (r.out_dir / f).stat().st_size > 0
    on_disk = json.loads((r.out_dir / "metrics.json").read_text())
    assert on_disk["status"] == "arrived" and on_disk["seed"] == m["seed"]


@pytest.mark.parametrize("name", ["one_obstacle", "obstacle_field_d", "appearing_obstacle"])
def test_clearance_from_sumo_record(runs: dict[str, SimResult], name: str) -> None:
    """Independent of the loop's own checks: SUMO's FCD output, rectangles built here and
    distances by shapely. The ego keeps the safety margin from every stopped vehicle."""
    r = runs[name]
    sc = load_scenario(SCENARIOS / f"{name}.toml")
    sizes = {}
    for rou in sc.routes:
        root = ET.parse(rou).getroot()
        types = {t.get("id"): (float(t.get("length", "5")), float(t.get("width", "1.8")))
                 for t in root.iter("vType")}
        sizes.update({v.get("id"): types[v.get("type")] for v in root.iter("vehicle")})
    fcd = _fcd(r.out_dir / "fcd.xml")
    best = math.inf
    seen = 0
    for vehicles in fcd.values():
        if "ego" not in vehicles:
            continue
        ego = _sumo_box(*vehicles["ego"][:3], sc.ego.length, sc.ego.width)
        for vid, (x, y, angle, speed) in vehicles.items():
            if vid == "ego" or speed > 0.1:
                continue
            seen += 1
            best = min(best, ego.distance(_sumo_box(x, y, angle, *sizes[vid])))
    assert seen > 0
    assert best >= sc.roadmap.safety_margin - 1e-3
    assert best == pytest.approx(r.metrics["min_clearance_obstacles"], abs=0.05)


def test_driven_path_matches_sumo_record(runs: dict[str, SimResult]) -> None:
    """The trajectory.csv centre poses, moved to the front bumper, are SUMO's positions."""
    r = runs["obstacle_field_c"]
    fcd = _fcd(r.out_dir / "fcd.xml")
    with (r.out_dir / "trajectory.csv").open() as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) > 100
    worst = 0.0
    compared = 0
    for row in rows[::10]:
        # SUMO labels an FCD time step with the time at its start; getTime() after the step
        # (our rows' t) is one step later
        t = round(float(row["t"]) - 0.1, 3)
        if t not in fcd or "ego" not in fcd[t]:
            continue
        h = float(row["heading"])
        front = np.array([float(row["x"]), float(row["y"])]) + 2.25 * np.array(
            [math.cos(h), math.sin(h)])
        x, y, angle, _ = fcd[t]["ego"]
        worst = max(worst, float(np.hypot(*(front - [x, y]))))
        compared += 1
        # SUMO's sublane model recomputes the angle from the lateral motion: close, not equal
        diff = (90.0 - math.degrees(h) - angle + 180.0) % 360.0 - 180.0
        assert abs(diff) < 3.0
    assert compared > 30
    assert worst < 0.01  # FCD rounds to 2 decimals


def test_a_closure_found_from_inside_the_junction_before_it_is_driven_to(
        monaco_net: Path, tmp_path: Path) -> None:
    """Monaco, -1362#1 to --427879: level 2 finds the hairpin into edge 1376#2 closed when
    the ego's front is already in the junction towards it, where SUMO has the vehicle on
    the internal lane to 1376#2 and refuses a new route that leaves it (the run failed:
    "Route replacement failed ... junction-internal edge leading elsewhere"). The ego
    keeps its way into 1376#2, re-routes from there, and arrives."""
    sc = load_scenario(SCENARIOS / "monaco.toml")
    ego = dataclasses.replace(sc.ego, start_edge="-1362#1", goal_edge="--427879",
                              start_pos=20.0, start_lane=0)
    sc = dataclasses.replace(sc, ego=ego, egos=(ego,),
                             sim=dataclasses.replace(sc.sim, duration=600.0))
    r = simulate(sc, out_dir=tmp_path, progress=False)
    assert r.status == "arrived", r.reason
    assert "1376#2" in r.metrics["route"]
    assert r.metrics["collisions"] == 0


def _free_drive(network: Path, start: str, goal: str, out: Path) -> SimResult:
    """The city scenario's ego alone on ``network`` from 20 m along ``start`` to ``goal``."""
    sc = load_scenario(SCENARIOS / "city.toml")
    ego = dataclasses.replace(sc.ego, start_edge=start, goal_edge=goal, start_pos=20.0,
                              start_lane=0, goal_pos=None, depart=0.0)
    sc = dataclasses.replace(sc, network=network, routes=(), additional=(), ego=ego,
                             egos=(ego,), sim=dataclasses.replace(sc.sim, duration=200.0))
    return simulate(sc, out_dir=out, progress=False)


def _driven(r: SimResult) -> dict[str, FloatArray]:
    """The driven path's times, centres, curvature and accelerations, from the run's
    trajectory.csv."""
    with (r.out_dir / "trajectory.csv").open() as fh:
        rows = list(csv.DictReader(fh))
    return {k: np.array([float(row[k]) for row in rows])
            for k in ("t", "x", "y", "curvature", "a_lon", "a_lat")}


def _driven_wheel_rate(d: dict[str, FloatArray], wheelbase: float) -> FloatArray:
    """The rate [rad/s] at which the kinematic single-track car's front wheels turn on
    the driven path (its rear axle towed half the wheelbase behind the centre, integrated
    in the plane: :func:`test_speed.towed_by_ode`), per step where the car moved."""
    s = np.concatenate(([0.0], np.cumsum(np.hypot(np.diff(d["x"]), np.diff(d["y"])))))
    moved = np.concatenate(([True], np.diff(s) > 1e-6))
    s, t, kappa = s[moved], d["t"][moved], d["curvature"][moved]
    slip0 = float(np.arcsin(np.clip(kappa[0] * wheelbase / 2.0, -1.0, 1.0)))
    angle = towed_by_ode(s, lambda x: np.interp(x, s, kappa), wheelbase, slip0)
    return np.abs(np.diff(angle)) / np.diff(t)


@settings(max_examples=50, deadline=None)
@given(radius=st.floats(4.2, 200.0), f=st.floats(0.0, 1.0), turn=st.sampled_from([-1, 1]))
def test_the_vehicle_is_put_on_the_plans_curve_between_its_samples(radius: float, f: float,
                                                                   turn: int) -> None:
    """Between two path samples 0.5 m apart on an arc (positions and headings), the point
    where the loop puts the vehicle lies on the arc to within a hundredth of the chord's
    sagitta (the chord itself: up to the sagitta inside it, a millimetre on a 30 m
    radius), and at the samples themselves exactly."""
    from splineplan.closedloop.control import _on_curve

    step = 0.5
    s = [0.0, step]
    ang = [turn * (-math.pi / 2.0 + k / radius) for k in s]
    x = [radius * math.cos(a) for a in ang]
    y = [turn * radius + radius * math.sin(a) for a in ang]
    h = [turn * k / radius for k in s]
    px, py = _on_curve(0, f, s, x, y, h)
    sagitta = radius * (1.0 - math.cos(step / (2.0 * radius)))
    assert abs(math.hypot(px, py - turn * radius) - radius) <= 0.01 * sagitta + 1e-12
    assert _on_curve(0, 0.0, s, x, y, h) == pytest.approx((x[0], y[0]), abs=1e-12)
    assert _on_curve(0, 1.0, s, x, y, h) == pytest.approx((x[1], y[1]), abs=1e-12)


@pytest.mark.parametrize(("start", "goal"), [("C3D3", "B1A1"), ("B2B1", "A3A2"),
                                             ("B2C2", "D0D1")])
def test_a_free_drive_never_brakes_harder_than_the_vehicle_may(tmp_path: Path, start: str,
                                                              goal: str) -> None:
    """The grid, no traffic, no lights: nothing asks for an emergency stop, so the
    driven speed never falls faster than ``b_max`` (5 % for the speed's rounding). A
    replan whose curve, made inside a junction's turn, leaves the car straight along its
    heading and then must turn harder asked for the emergency rate (8 m/s^2 on each of
    these three routes before); such a replan is put off while the plan reaches far
    enough, and the car keeps its limits."""
    r = _free_drive(NETS / "grid.net.xml", start, goal, tmp_path)
    assert r.status == "arrived", r.reason
    tp = load_scenario(SCENARIOS / "city.toml").trajectory
    d = _driven(r)
    assert d["a_lon"].min() >= -1.05 * tp.b_max
    assert np.abs(d["a_lat"]).max() <= 1.05 * tp.mu * tp.g
    assert np.abs(d["curvature"]).max() <= 1.02 / tp.min_turn_radius
    assert _driven_wheel_rate(d, tp.wheelbase).max() <= 1.05 * tp.max_steering_rate


def test_a_route_planned_feasibly_is_driven_within_the_turning_limit(tmp_path: Path
                                                                    ) -> None:
    """The city, D3E3 to C2B2, alone: its plan from level 1 to level 3 keeps the car's
    limits, and so does the closed loop, whose plans now ease the bends equation (3)
    leaves too sharp as the plan does (before: a driven curvature of 0.28 1/m, a 3.6 m
    radius, where the car turns on 4.2 m)."""
    from splineplan.pipeline import plan

    net = load_network(NETS / "city.net.xml")
    assert plan(net, "D3E3", "C2B2").trajectory.feasible
    r = _free_drive(NETS / "city.net.xml", "D3E3", "C2B2", tmp_path)
    assert r.status == "arrived", r.reason
    tp = load_scenario(SCENARIOS / "city.toml").trajectory
    d = _driven(r)
    assert np.abs(d["curvature"]).max() <= 1.02 / tp.min_turn_radius
    assert np.abs(d["a_lat"]).max() <= 1.05 * tp.mu * tp.g
    assert r.metrics["collisions"] == 0 and r.metrics["time_off_road"] == 0.0


def test_a_replan_too_late_in_a_bend_goes_on_from_the_current_plan(tmp_path: Path) -> None:
    """The city, B1B2 to E3E2, alone: on D3E3, before the turn into E3E2 (tighter than
    the car can take), routine replans bent beyond the turning limit and beyond the
    current plan, or asked for harder braking than ``b_max``, and were put off until the
    plan ran out; the last one keeps the current plan up to where it runs straightest
    and plans on from there (the replan says where), and the driven path keeps the car's
    limits."""
    r = _free_drive(NETS / "city.net.xml", "B1B2", "E3E2", tmp_path)
    assert r.status == "arrived", r.reason
    joined = [p for p in r.replans if p.ok and "on from the plan" in p.detail]
    assert joined and all(p.reason == "horizon" for p in joined)
    tp = load_scenario(SCENARIOS / "city.toml").trajectory
    d = _driven(r)
    assert np.abs(d["curvature"]).max() <= 1.02 / tp.min_turn_radius
    assert np.abs(d["a_lat"]).max() <= 1.05 * tp.mu * tp.g
    assert r.metrics["collisions"] == 0 and r.metrics["time_off_road"] == 0.0


def test_blocked_road_reroutes(runs: dict[str, SimResult]) -> None:
    r = runs["blocked_road"]
    reroutes = [p for p in r.replans if p.reason == "reroute"]
    assert reroutes and "B1C1" in reroutes[0].detail
    assert r.metrics["avoided_edges"] == ["B1C1"]
    assert "B1C1" not in r.route and r.route[0] == "A1B1" and r.route[-1] == "C1D1"
    # the ego turned off before the closed road: it never drove on B1C1
    net = sumolib.net.readNet(str(NETS / "grid.net.xml"))
    lane = net.getLane("B1C1_0")
    xy = np.column_stack((r.driven["x"], r.driven["y"]))
    d = [sumolib.geomhelper.distancePointToPolygon(tuple(p), lane.getShape()) for p in xy]
    assert min(d) > 3.0


def test_route_length_after_a_reroute_counts_from_the_start(runs: dict[str, SimResult]
                                                            ) -> None:
    """After the re-route, ``route`` and ``route_length`` are the route driven from the
    ego's start (not from where it re-routed): the length re-added from sumolib's own edge
    and junction-lane lengths, and at least the distance the ego's centre drove (it starts
    half a length behind the start position and stops before the goal edge's end)."""
    r = runs["blocked_road"]
    m = r.metrics
    sc = load_scenario(SCENARIOS / "blocked_road.toml")
    assert [p for p in r.replans if p.reason == "reroute"]
    edges = m["route"]
    assert edges[0] == sc.ego.start_edge and edges[-1] == sc.ego.goal_edge
    assert tuple(edges) == r.route
    net = sumolib.net.readNet(str(NETS / "grid.net.xml"), withInternal=True)
    total = sum(net.getEdge(e).getLength() for e in edges) - sc.ego.start_pos
    for a, b in itertools.pairwise(edges):
        path, cost = net.getShortestPath(net.getEdge(a), net.getEdge(b), withInternal=True,
                                         vClass=sc.ego.vclass)
        normal = [e.getID() for e in path if not e.getID().startswith(":")]
        assert normal == [a, b]  # the direct connection, through the junction's lanes
        total += cost - net.getEdge(a).getLength() - net.getEdge(b).getLength()
    assert m["route_length"] == pytest.approx(total, abs=0.05)
    assert m["route_length"] >= m["distance"] - 1.0


def test_sumo_sees_the_planned_speed(runs: dict[str, SimResult]) -> None:
    """SUMO's speed of the ego (its FCD record) is the closed loop's speed, also across
    lane changes and junctions, where SUMO would otherwise infer a speed from the moves
    along its lanes' lengths, capped by the lanes' speed limits (up to 3.2 m/s off the
    plan in this run before the speed was set)."""
    r = runs["blocked_road"]
    fcd = _fcd(r.out_dir / "fcd.xml")
    worst, compared = 0.0, 0
    for t, v in zip(r.driven["t"], r.driven["speed"], strict=True):
        rec = fcd.get(round(float(t) - 0.1, 3), {}).get("ego")  # see the test above
        if rec is not None:
            worst = max(worst, abs(rec[3] - float(v)))
            compared += 1
    assert compared > 400
    assert worst < 0.01  # FCD rounds to 2 decimals


@pytest.mark.parametrize("name", BUNDLED)
def test_sumo_log_has_no_false_alarms_for_the_ego(runs: dict[str, SimResult], name: str
                                                  ) -> None:
    """SUMO's log says "emergency braking" for the ego only where the closed loop braked at
    its emergency limit (twice b_max, the ego's emergencyDecel in SUMO), never with the
    decelerations of 9 to 37 m/s^2 SUMO inferred from the moves before; an "implied speed"
    above the maximum at most once: SUMO measures a move along its lane's length, which
    on a curved junction lane differs from the distance the ego moved beside the lane's
    centre line (README, Conventions)."""
    sc = load_scenario(SCENARIOS / f"{name}.toml")
    lines = (runs[name].out_dir / "sumo.log").read_text().splitlines()
    ego = [ln for ln in lines if f"Vehicle '{sc.ego.id}'" in ln]
    brakes = [float(re.search(r"decel=([0-9.]+)", ln)[1])  # type: ignore[index]
              for ln in ego if "emergency braking" in ln]
    implied = [ln for ln in ego if "implied speed" in ln]
    assert all(d <= 2.0 * sc.trajectory.b_max + 0.01 for d in brakes), ego
    assert len(implied) <= 1, implied


def test_gui_without_display_fails_at_once(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                           capsys: pytest.CaptureFixture[str]) -> None:
    """No display: one line, status 2, before anything starts (no output folder)."""
    from splineplan.cli import main

    if sys.platform.startswith(("win", "darwin")):
        pytest.skip("sumo-gui needs no DISPLAY there")
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    out = tmp_path / "run"
    t0 = time.perf_counter()
    code = main(["simulate", str(SCENARIOS / "empty_road.toml"), "--gui", "--out", str(out)])
    assert time.perf_counter() - t0 < 5.0
    assert code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("splineplan simulate: error: ")
    assert "--gui" in err[0] and "DISPLAY" in err[0]
    assert not out.exists()


def test_appearing_obstacle_replans_in_time(runs: dict[str, SimResult]) -> None:
    r = runs["appearing_obstacle"]
    hits = [p for p in r.replans if p.reason == "obstacles" and "appearing" in p.detail]
    assert hits, [(p.time, p.reason, p.detail) for p in r.replans]
    assert 18.0 <= hits[0].time <= 18.5  # the car enters at t = 18 s
    assert hits[0].ok
    # the ego was driving when the car appeared, and drove past it
    i = int(np.searchsorted(r.driven["t"], 18.0))
    assert r.driven["speed"][i] > 10.0
    assert r.metrics["min_clearance_obstacles"] >= 0.3 - 1e-6


def test_moving_traffic_slows_the_ego(runs: dict[str, SimResult]) -> None:
    free = runs["empty_road"].metrics["travel_time"]
    busy = runs["moving_traffic"]
    assert busy.metrics["travel_time"] > free + 5.0
    assert busy.driven["speed_limited"].sum() > 50
    assert busy.metrics["min_clearance_vehicles"] > 0.5


def test_city_scenario_drives_the_level1_route(runs: dict[str, SimResult]) -> None:
    r = runs["city"]
    net = load_network(NETS / "city.net.xml")
    sc = load_scenario(SCENARIOS / "city.toml")
    route = shortest_route(net, sc.ego.start_edge, sc.ego.goal_edge, start_pos=sc.ego.start_pos)
    assert r.route == route.edges and "bridge_east" in r.route
    assert r.metrics["route_length"] == pytest.approx(route.length)
    assert r.metrics["depart_time"] == pytest.approx(sc.ego.depart + 0.1)


def test_car_alongside_is_planned_around(tmp_path: Path) -> None:
    """The first 120 s of the city among busy traffic: on two-lane roads cars come up
    alongside on the other lane. The ego's widest path would drift to the middle of the
    road (into them); each such car becomes a swept obstacle and the ego keeps its side.
    Checked on SUMO's own record, with shapely."""
    sc = load_scenario(SCENARIOS / "city_traffic.toml")
    short = dataclasses.replace(sc, sim=dataclasses.replace(sc.sim, duration=120.0))
    r = simulate(short, out_dir=tmp_path, progress=False)
    m = r.metrics
    assert r.status == "timeout" and m["collisions"] == 0, m["collision_events"][:3]
    assert m["time_off_road"] == 0.0
    beside = {p.detail.split("'")[1] for p in r.replans
              if p.reason == "traffic" and p.ok and "beside the ego" in p.detail}
    assert beside
    assert m["min_clearance_vehicles"] > 0.2
    fcd = _fcd(tmp_path / "fcd.xml")
    size = _vehicle_sizes(SCENARIOS / "city.rou.xml", SCENARIOS / "city_traffic.rou.xml")
    gaps = {car: [_sumo_box(*v["ego"][:3], sc.ego.length, sc.ego.width).distance(
                      _sumo_box(*v[car][:3], *size[car.split(".")[0]]))
                  for v in fcd.values() if "ego" in v and car in v] for car in beside}
    assert max(len(g) for g in gaps.values()) > 30
    assert min(min(g) for g in gaps.values() if g) > 0.2
    # SUMO's messages (its start, its warnings about the background traffic, its end) went
    # to its log, the console stays clean
    log = (tmp_path / "sumo.log").read_text()
    assert "started via libsumo" in log and "Warning:" in log and "Simulation ended" in log
    assert m["wall_time_sumo"] > 0 and m["wall_time_planner"] > 0 and m["wall_time_loop"] > 0
    assert m["wall_time_sumo"] + m["wall_time_planner"] + m["wall_time_loop"] == pytest.approx(
        m["wall_time"])


@pytest.mark.slow
def test_city_among_busy_traffic(tmp_path: Path) -> None:
    r = _run("city_traffic", tmp_path)
    m = r.metrics
    assert r.arrived, r.reason
    assert m["collisions"] == 0, m["collision_events"][:3]
    assert m["time_off_road"] == 0.0


@pytest.mark.slow
def test_monaco_end_to_end(monaco_net: Path, tmp_path: Path) -> None:
    r = _run("monaco", tmp_path)
    assert r.arrived, r.reason
    assert r.metrics["collisions"] == 0


def test_monaco_missing_is_a_clear_error(tmp_path: Path) -> None:
    text = (SCENARIOS / "monaco.toml").read_text().replace("../../shared/data/",
                                                           "../no_such_folder/")
    p = tmp_path / "scen" / "monaco.toml"
    p.parent.mkdir()
    p.write_text(text)
    with pytest.raises(ScenarioError, match=r"network file not found: .*monaco\.net\.xml\.gz"):
        load_scenario(p)


# ---- obstacles read from SUMO ------------------------------------------------------------

@pytest.fixture()
def grid_sumo() -> Iterator[None]:
    libsumo.start(["sumo", "-n", str(NETS / "city.net.xml"), "--no-step-log", "true"])
    try:
        yield
    finally:
        libsumo.close()


def test_stopped_vehicles_become_obstacles(grid_sumo: None) -> None:
    # B0B1, B1C1 and C1D1 are slanted: the angle convention matters
    net = sumolib.net.readNet(str(NETS / "city.net.xml"))
    placed = {"s0": ("B1C1", 0, 40.0, 4.5, 1.8), "s1": ("B0B1", 0, 25.0, 12.0, 2.5),
              "s2": ("C1D1", 1, 70.0, 6.0, 2.1)}
    for vid, (edge, lane, pos, length, width) in placed.items():
        libsumo.vehicletype.copy("DEFAULT_VEHTYPE", f"t_{vid}")
        libsumo.vehicletype.setLength(f"t_{vid}", length)
        libsumo.vehicletype.setWidth(f"t_{vid}", width)
        libsumo.route.add(f"r_{vid}", [edge])
        libsumo.vehicle.add(vid, f"r_{vid}", typeID=f"t_{vid}", departPos=str(pos),
                            departLane=str(lane), departSpeed="0")
        libsumo.vehicle.setStop(vid, edge, pos=pos, laneIndex=lane, duration=1000.0)
    libsumo.route.add("r_mover", ["B1C1", "C1D1"])
    libsumo.vehicle.add("mover", "r_mover", departSpeed="10")
    for _ in range(10):
        libsumo.simulationStep()
    obs = stopped_vehicle_obstacles(libsumo)
    assert set(obs.ids) == set(placed)  # the moving car is no obstacle
    for i, vid in enumerate(obs.ids):
        edge, lane, _, length, width = placed[vid]
        poly = Polygon(obs.polygon(i))
        assert poly.area == pytest.approx(length * width)
        # SUMO's position is the middle of the front bumper, its angle 0 = north, clockwise
        fx, fy = libsumo.vehicle.getPosition(vid)
        ang = math.radians(libsumo.vehicle.getAngle(vid))
        corners = obs.polygon(i)
        front_mid = corners[1:3].mean(axis=0)  # corners run from rear right, counter-clockwise
        assert front_mid == pytest.approx([fx, fy], abs=1e-6)
        axis = corners[1] - corners[0]
        assert axis / np.linalg.norm(axis) == pytest.approx([math.sin(ang), math.cos(ang)],
                                                            abs=1e-9)
        # independent: the rectangle's centre is on the lane's centre line (sumolib), half
        # a length behind SUMO's lane position
        shape = net.getLane(f"{edge}_{lane}").getShape()
        lane_pos = libsumo.vehicle.getLanePosition(vid)
        cx, cy = sumolib.geomhelper.positionAtShapeOffset(shape, lane_pos - length / 2.0)
        assert np.array(poly.centroid.coords[0]) == pytest.approx([cx, cy], abs=0.05)
        assert _sumo_box(fx, fy, libsumo.vehicle.getAngle(vid), length, width).symmetric_difference(
            poly).area < 1e-6
    # a roadmap along B1C1 and C1D1 (two lanes each) passes them
    mine = load_network(NETS / "city.net.xml")
    route = shortest_route(mine, "B1C1", "C1D1")
    corridor = route_corridor(mine, route)
    params = RoadmapParams(d=1.0, safety_margin=0.3)
    start = corridor.to_xy([3.0], [0.0])[0]
    rm = plan_roadmap(corridor, obs, start, params)
    path = np.asarray(rm.xy)
    for i in range(len(obs)):
        poly = Polygon(obs.polygon(i))
        d = [poly.distance(Polygon(footprint(p, 0.0, 1e-3, 1e-3))) for p in path]
        assert min(d) >= params.inflation - 1e-6


def test_box_distances_match_shapely() -> None:
    rng = np.random.default_rng(7)
    a = footprint([0.0, 0.0], 0.4, 4.5, 1.8)
    others = np.stack([footprint(rng.uniform(-8, 8, 2), rng.uniform(-3, 3),
                                 rng.uniform(1, 12), rng.uniform(0.5, 3)) for _ in range(300)])
    want = [Polygon(a).distance(Polygon(b)) for b in others]
    assert box_distances(a, others) == pytest.approx(want, abs=1e-9)
    # crossing without a corner inside, and containment
    cross = footprint([0, 0], math.pi / 2, 10, 1)
    inner = footprint([0, 0], 0.0, 1, 0.5)
    assert box_distances(footprint([0, 0], 0, 10, 1), np.stack([cross, inner])).tolist() == [0, 0]


# ---- bad input and failures: a clear error, and the record written ------------------------

def _status(out: Path) -> dict[str, object]:
    m: dict[str, object] = json.loads((out / "metrics.json").read_text())
    assert (out / "trajectory.csv").exists()
    return m


def test_missing_network(tmp_path: Path) -> None:
    sc = load_scenario(SCENARIOS / "empty_road.toml")
    bad = dataclasses.replace(sc, network=tmp_path / "gone.net.xml")
    with pytest.raises(ScenarioError, match=r"gone\.net\.xml"):
        simulate(bad, out_dir=tmp_path / "out", progress=False)
    m = _status(tmp_path / "out")
    assert m["status"] == "failed" and "gone.net.xml" in str(m["reason"])


def test_unknown_edge(tmp_path: Path) -> None:
    sc = load_scenario(SCENARIOS / "empty_road.toml")
    bad = dataclasses.replace(sc, ego=dataclasses.replace(sc.ego, goal_edge="nowhere"))
    with pytest.raises(UnknownEdgeError, match="'nowhere'"):
        simulate(bad, out_dir=tmp_path, progress=False)
    assert _status(tmp_path)["status"] == "failed"


def test_start_edge_forbidden_to_the_class(tmp_path: Path) -> None:
    sc = load_scenario(SCENARIOS / "city.toml")
    bad = dataclasses.replace(sc, ego=dataclasses.replace(sc.ego, start_edge="bike_A2B3"))
    with pytest.raises(VehicleClassError, match="bike_A2B3"):
        simulate(bad, out_dir=tmp_path, progress=False)
    assert "bike_A2B3" in str(_status(tmp_path)["reason"])


def test_ego_removed_by_someone_else(tmp_path: Path) -> None:
    sc = load_scenario(SCENARIOS / "one_obstacle.toml")

    def remove(t: float) -> None:
        if abs(t - 5.0) < 1e-6:
            libsumo.vehicle.remove(sc.ego.id)

    with pytest.raises(SimulationError, match="'ego' left the simulation at t=5"):
        simulate(sc, out_dir=tmp_path, progress=False, on_step=remove)
    m = _status(tmp_path)
    assert m["status"] == "failed" and "left the simulation" in str(m["reason"])
    with (tmp_path / "trajectory.csv").open() as fh:
        rows = list(csv.DictReader(fh))
    assert 40 <= len(rows) <= 50 and float(rows[-1]["t"]) <= 5.0
    # libsumo was closed: a new run starts
    libsumo.start(["sumo", "-n", str(NETS / "straight.net.xml"), "--no-step-log", "true"])
    libsumo.close()


@pytest.mark.parametrize(("content", "needle"), [
    ("<additional><poly id='p' </additional>", "not well-formed XML"),
    ("<additional><busStop id='b' lane='no_lane' startPos='0' endPos='10'/></additional>",
     "SUMO failed to start"),
])
def test_sumo_failing_to_start(tmp_path: Path, content: str, needle: str) -> None:
    add = tmp_path / "bad.add.xml"
    add.write_text(content)
    sc = load_scenario(SCENARIOS / "empty_road.toml")
    bad = dataclasses.replace(sc, additional=(add,))
    with pytest.raises(SimulationError, match=needle):
        simulate(bad, out_dir=tmp_path / "out", progress=False)
    m = _status(tmp_path / "out")
    assert m["status"] == "failed" and needle in str(m["reason"])


@pytest.mark.parametrize("driver", ["sumo", "sublane"])
def test_sumo_driver_baseline(tmp_path: Path, driver: str) -> None:
    r = _run("one_obstacle", tmp_path, driver=driver)
    m = r.metrics
    assert r.arrived and m["driver"] == driver and m["replan_count"] == 0
    assert m["planning_time"]["count"] == 0 and m["distance"] > 500.0
    assert m["travel_time"] > 30.0 and m["teleports"] == 0 == m["ego_teleports"]
    # the same safety record as for the planner: SUMO's driver passed the stopped car
    assert m["collisions"] == 0 and 0.0 < m["min_clearance_obstacles"] < 5.0
    assert m["position_error_max"] is None  # nothing was asked of SUMO
    # SUMO's own record of the run agrees with ours on where its driver went
    fcd = _fcd(r.out_dir / "fcd.xml")
    t_end = round(float(r.driven["t"][-1]) - 0.1, 3)
    x, y, _, _ = fcd[t_end]["ego"]
    assert (x, y) == pytest.approx((r.driven["sumo_x"][-1], r.driven["sumo_y"][-1]), abs=0.01)


def test_sumo_driver_stuck_is_a_timeout(tmp_path: Path) -> None:
    """SUMO's lane-based driver waits behind the stopped cars (nothing is teleported): the
    run ends at its duration, not arrived, and says so."""
    sc = load_scenario(SCENARIOS / "blocked_road.toml")
    short = dataclasses.replace(sc, sim=dataclasses.replace(sc.sim, duration=40.0))
    r = simulate(short, out_dir=tmp_path, driver="sumo", progress=False)
    m = r.metrics
    assert r.status == "timeout" and not m["arrived"]
    assert "standing still" in r.reason and "B1C1" in r.reason
    assert m["teleports"] == 0 and m["collisions"] == 0
    assert json.loads((tmp_path / "metrics.json").read_text())["status"] == "timeout"


def test_driver_is_checked(tmp_path: Path) -> None:
    from splineplan.errors import ParameterError

    with pytest.raises(ParameterError, match="'planner', 'sumo', 'sublane'"):
        _run("empty_road", tmp_path, driver="human")


def test_stopped_car_never_closes_the_open_road() -> None:
    """One car stopped in the middle lane of the three-lane road leaves two lanes open,
    wherever it stands and wherever the planning window starts (the loop's windows, with
    the obstacle elongated by level 2's vehicle model): level 2 never reports the road
    closed."""
    from splineplan.errors import RoadBlockedError
    from splineplan.obstacles import Obstacles
    from splineplan.planner import plan_corridor

    sc = load_scenario(SCENARIOS / "one_obstacle.toml")
    net = load_network(sc.network)
    corridor = route_corridor(net, shortest_route(net, "e0", "e2"))
    closed = []
    for station in np.arange(25.0, 575.0, 7.3):  # across both junctions, off the d grid
        xy = corridor.to_xy([station], [0.0])
        obs = Obstacles.from_boxes(xy, corridor.heading_at([station]), [4.5], [1.8],
                                   reference="center", ids=["car"])
        for back in (12.0, 41.7):
            s0 = max(station - back, 0.0)
            window = corridor.slice(s0, min(s0 + sc.sim.lookahead, corridor.length))
            start = window.to_xy([4.0], [0.0])[0]
            try:
                plan_corridor(window, obs, start, float(window.heading_at([4.0])[0]),
                              roadmap_params=sc.roadmap, params=sc.trajectory,
                              start_speed=10.0, end_speed=None)
            except RoadBlockedError as err:
                closed.append((float(station), back, str(err)))
    assert not closed, closed[:3]


def test_cli_simulate(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from splineplan.cli import main

    out = tmp_path / "run"
    code = main(["simulate", str(SCENARIOS / "one_obstacle.toml"), "--out", str(out),
                 "--seed", "5", "--plot", "--no-progress"])
    assert code == 0
    text = capsys.readouterr().out
    assert "one_obstacle: arrived" in text and "collisions 0" in text
    assert json.loads((out / "metrics.json").read_text())["seed"] == 5
    assert (out / "route.png").stat().st_size > 10_000
    plans = sorted((out / "plans").glob("*.png"))
    assert len(plans) >= 3
    code = main(["simulate", str(tmp_path / "missing.toml")])
    assert code == 2
    assert "scenario file not found" in capsys.readouterr().err


@settings(max_examples=40, deadline=None)
@given(st.floats(-12.0, 12.0), st.floats(-0.6, 0.6), st.floats(0.0, 40.0))
def test_the_place_where_a_footprint_reaches_a_foes_lane_is_shapelys(
        offset: float, turn: float, u: float) -> None:
    """Where the ego's footprint, along a straight path, first comes within 0.15 m of a
    car driving on a junction lane (the city's B0, westbound straight through), as the
    give-way stop uses it: the same samples as shapely's distance from the footprints to
    that lane's centre line, buffered by the car's half width (within 5 cm)."""
    from types import SimpleNamespace

    from splineplan.closedloop.control import PATH_MARGIN, Control

    net = load_network(NETS / "city.net.xml")
    lane = net.lane(":B0_1_0")
    centre = LineString(lane.shape)
    mid = np.asarray(centre.interpolate(0.5, normalized=True).coords[0])
    # a path crossing the lane: northwards, shifted along it and turned
    h = math.pi / 2.0 + turn
    s = np.arange(0.0, 60.0, 0.5)
    start = mid + np.array([offset, -30.0])
    xy = start + np.column_stack((np.cos(h) * s, np.sin(h) * s))
    ego = SimpleNamespace(length=4.5, width=1.8)
    me = SimpleNamespace(net=net, sc=SimpleNamespace(ego=ego), u=u, full_s=s, full_xy=xy,
                         full_heading=np.full(len(s), h), _reach={}, _bands={})
    me._touching = lambda *a: Control._touching(me, *a)  # type: ignore[attr-defined]
    me._lane_band = lambda *a: Control._lane_band(me, *a)  # type: ignore[attr-defined]
    got = Control._lane_reach(me, ":B0_1_0", 1.8)  # type: ignore[arg-type]
    dist = np.array([Polygon(footprint(p, h, 4.5, 1.8)).distance(centre) - 0.9 for p in xy])
    ahead = s >= u
    sure = np.flatnonzero(ahead & (dist <= PATH_MARGIN - 0.05))
    maybe = np.flatnonzero(ahead & (dist <= PATH_MARGIN + 0.05))
    if not len(maybe):
        assert math.isinf(got)
        return
    assert s[maybe[0]] - u <= got + 1e-9
    if len(sure):
        assert got <= s[sure[0]] - u + 1e-9


@pytest.mark.parametrize("phase", [0.0, 1.0, 2.0, 4.0])
def test_a_left_turn_gives_way_to_the_stream_that_has_it(tmp_path: Path, phase: float
                                                          ) -> None:
    """The ego turns left at the city's priority junction B0 (A0B0 -> B0B1) across a
    westbound stream, a car every 6 s at 50 km/h, which has the way. Whatever the phase at
    which it comes, it gives way (SUMO's right of way, ``getJunctionFoes``) and crosses in a
    gap: no collision, and the margin kept to every car. Without it, one phase in two ended
    in a crash in the middle of the junction. At phase 1 s the ego creeps up to its stop
    1 m before the conflict area; it must keep waiting there (it once went on into the
    stream's way as soon as it was within that metre, and stood 0.28 m from a car)."""
    (tmp_path / "stream.rou.xml").write_text(
        '<routes>\n  <vType id="car" length="4.5" width="1.8" vClass="passenger" '
        'speedDev="0"/>\n  <flow id="west" type="car" from="C0B0" to="B0A0" begin="0" '
        'end="200" period="6" departSpeed="max"/>\n</routes>\n')
    (tmp_path / "turn.toml").write_text(
        f'name = "turn"\nnetwork = "{(NETS / "city.net.xml").as_posix()}"\n'
        f'routes = ["stream.rou.xml"]\n\n[ego]\nstart_edge = "A0B0"\nstart_pos = 60.0\n'
        f'start_lane = 0\ngoal_edge = "B0B1"\ndepart = {10.0 + phase}\n\n'
        f'[sim]\nduration = 90.0\nseed = 1\n')
    r = simulate(load_scenario(tmp_path / "turn.toml"), out_dir=tmp_path / "run",
                 progress=False)
    m = r.metrics
    assert r.arrived, r.reason
    assert m["collisions"] == 0, m["collision_events"][:3]
    assert m["min_clearance_vehicles"] >= m["safety_margin"]
