"""Several planned vehicles in one SUMO run (libsumo, small networks): sharing a road by
separation, yielding to another's published plan, SUMO's own scenario with a share of 0,
and bad input."""

from __future__ import annotations

import csv
import functools
import json
import math
import subprocess
import xml.etree.ElementTree as ET
from pathlib import Path
from typing import Any

import libsumo
import numpy as np
import pytest
import sumolib
from conftest import NETS, ROOT
from hypothesis import assume, given, settings
from hypothesis import strategies as st
from shapely.geometry import LineString, Point, Polygon

from splineplan import cli
from splineplan.closedloop.control import SIDE_CLEAR, Control
from splineplan.errors import ParameterError, ScenarioError
from splineplan.scenario import load_scenario, sumo_scenario
from splineplan.sim import simulate
from splineplan.sumo.world import JunctionFoe

SCENARIOS = ROOT / "scenarios"


def _rows(path: Path) -> list[dict[str, Any]]:
    """A ``trajectory.csv``'s rows: numbers, and its text columns as text."""
    with path.open() as fh:
        return [{k: v if k in ("lane", "why_slow") else float(v) for k, v in r.items()}
                for r in csv.DictReader(fh)]


def _two(tmp_path: Path, a: str, b: str, *, duration: float = 60.0) -> Path:
    """A scenario on the grid with planned vehicles ``a`` and ``b`` (TOML table bodies)."""
    p = tmp_path / "two.toml"
    p.write_text(f'network = "{NETS / "grid.net.xml"}"\n[[ego]]\nid = "a"\n{a}\n'
                 f'[[ego]]\nid = "b"\n{b}\n[sim]\nduration = {duration}\nseed = 1\n')
    return p


def _p_among_sumo(tmp_path: Path, net: str, routes: str, duration: float) -> tuple[Any, Any]:
    """SUMO's run of the route file ``routes`` (its text) on ``net`` (of ``sumo_nets/``)
    with vehicle ``p`` planned: the scenario and the run's result."""
    rou = tmp_path / "r.rou.xml"
    rou.write_text(routes)
    sc = sumo_scenario(net=NETS / net, routes=(rou,), duration=duration)
    return sc, simulate(sc, out_dir=tmp_path / "out", vehicles=("p",), seed=1, progress=False)


def _p_and_q(tmp_path: Path, p: tuple[str, float], q: tuple[str, float],
             duration: float) -> tuple[Any, Any]:
    """Two cars on the city's network, 'p' planned and 'q' SUMO's, each given by its
    route's edges and depart position [m], departing at full speed: the scenario and the
    run's result (:func:`_p_among_sumo`)."""
    cars = "".join(f"""<vehicle id="{v}" depart="0" departPos="{pos:g}" departSpeed="max"
  type="car"><route edges="{edges}"/></vehicle>
""" for v, (edges, pos) in (("p", p), ("q", q)))
    routes = f"""<routes>
<vType id="car" length="4.5" width="1.8" vClass="passenger"/>
{cars}</routes>"""
    return _p_among_sumo(tmp_path, "city.net.xml", routes, duration)


def test_two_planned_vehicles_side_by_side(tmp_path: Path) -> None:
    """Two planned vehicles start side by side on a two-lane road and drive the same way:
    both arrive, and their footprints keep the safety margin (SUMO's FCD, measured by the
    run's pairwise check) while they drive beside each other."""
    sc = load_scenario(SCENARIOS / "two_side_by_side.toml")
    r = simulate(sc, out_dir=tmp_path, progress=False)
    assert r.arrived, r.reason
    assert set(r.vehicles) == {"a", "b"}
    margin = sc.roadmap.safety_margin
    for vid, v in r.vehicles.items():
        assert v.metrics["collisions"] == 0 and v.metrics["time_off_road"] == 0.0, vid
        assert (tmp_path / vid / "metrics.json").is_file()
    pairs = r.metrics["pairs"]
    assert pairs["min_gap_planned"]["value"] >= margin - 1e-3
    assert pairs["collision_pairs_planned"] == []
    # they did drive beside each other: at some time, less than a car length apart along
    # the road and more than a car width apart across it
    a = {round(row["t"], 1): row for row in _rows(tmp_path / "a" / "trajectory.csv")}
    b = {round(row["t"], 1): row for row in _rows(tmp_path / "b" / "trajectory.csv")}
    beside = [t for t in a.keys() & b.keys()
              if abs(a[t]["station"] - b[t]["station"]) < sc.ego.length
              and abs(a[t]["lateral"] - b[t]["lateral"]) > sc.ego.width + margin]
    assert len(beside) >= 10
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["planned"] == 2 and summary["arrived"] == 2
    assert (tmp_path / "tripinfo.xml").stat().st_size > 0


def test_planned_vehicle_yields_to_published_plan(tmp_path: Path) -> None:
    """At a crossing, the vehicle planned second ('b') waits for the published plan of the
    first ('a'): it replans while waiting, crosses after 'a' has, keeps the margin, and
    never brakes harder than its comfortable limit (it yields in time)."""
    path = _two(tmp_path, 'start_edge = "A1B1"\nstart_pos = 30.0\ngoal_edge = "B1C1"',
                'start_edge = "B0B1"\nstart_pos = 30.0\ngoal_edge = "B1B2"')
    sc = load_scenario(path)
    r = simulate(sc, out_dir=tmp_path / "out", progress=False)
    assert r.arrived, r.reason
    b = r.vehicles["b"].metrics
    waits = [p for p in b["replans"] if p["reason"] == "cooperation"]
    assert waits and all("'a'" in p["detail"] for p in waits)
    assert r.metrics["pairs"]["min_gap_planned"]["value"] >= sc.roadmap.safety_margin - 1e-3
    # at its comfortable braking limit (5 % for the step where a new plan takes over from
    # the old), far from the emergency braking (twice that) of a late reaction
    assert b["max_longitudinal_acceleration"] <= 1.05 * sc.trajectory.b_max
    # where the paths cross: 'a' drives east at a constant y, 'b' north at a constant x;
    # 'a' has cleared b's way (its rear beyond b's side) before b's front reaches a's way
    a_rows = _rows(tmp_path / "out" / "a" / "trajectory.csv")
    b_rows = _rows(tmp_path / "out" / "b" / "trajectory.csv")
    y_a, x_b = a_rows[0]["y"], b_rows[0]["x"]
    clear = (sc.ego.length + sc.ego.width) / 2.0
    a_out = min(row["t"] for row in a_rows if row["x"] > x_b + clear)
    b_in = min(row["t"] for row in b_rows if row["y"] > y_a - clear)
    assert a_out <= b_in
    # the record says why 'b' was slow before it crossed, and which lane it was on
    held = {row["why_slow"] for row in b_rows if row["t"] < b_in}
    assert "waiting for the published plan of 'a'" in held
    assert {row["lane"] for row in b_rows} >= {"B0B1_0", "B1B2_0"}


def test_a_turn_waits_for_published_plans_before_the_junction(tmp_path: Path) -> None:
    """A left turn ('b', planned last) across two oncoming planned vehicles ('c' and 'a'):
    its plan waits for theirs where its path crosses them, inside the junction; it waits
    before the junction instead, as SUMO's drivers do, and crosses after both."""
    p = tmp_path / "three.toml"
    egos = (("a", "B2B1", 50.0, "B1B0"), ("c", "B2B1", 75.0, "B1B0"),
            ("b", "B0B1", 90.0, "B1A1"))
    p.write_text(f'network = "{NETS / "grid.net.xml"}"\n' + "".join(
        f'[[ego]]\nid = "{v}"\nstart_edge = "{e}"\nstart_pos = {pos}\ngoal_edge = "{g}"\n'
        for v, e, pos, g in egos) + "[sim]\nduration = 60\nseed = 1\n")
    sc = load_scenario(p)
    r = simulate(sc, out_dir=tmp_path / "out", progress=False)
    assert r.arrived, r.reason
    b_rows = _rows(tmp_path / "out" / "b" / "trajectory.csv")
    stood = [row for row in b_rows if row["speed"] < 0.1 and row["t"] > 1.0]
    assert stood  # it waited
    assert not any(str(row["lane"]).startswith(":") for row in stood)
    assert any(str(row["why_slow"]).startswith("keeping the junction clear while it waits "
                                               "for the published plan of") for row in stood)
    assert r.metrics["pairs"]["min_gap_planned"]["value"] >= sc.roadmap.safety_margin - 1e-3


def _small_cfg(tmp_path: Path, end: float = 60.0) -> Path:
    cfg = tmp_path / "city.sumocfg"
    cfg.write_text(f"""<configuration><input>
  <net-file value="{NETS / 'city.net.xml'}"/>
  <route-files value="{SCENARIOS / 'city.rou.xml'}"/>
</input><time><begin value="0"/><end value="{end:g}"/><step-length value="0.1"/></time>
</configuration>""")
    return cfg


def _trips(path: Path) -> list[dict[str, str]]:
    return [dict(t.attrib) for t in ET.parse(path).getroot().iter("tripinfo")]


def test_share_zero_reproduces_sumo(tmp_path: Path) -> None:
    """No planned vehicle: the run is SUMO's own, the same tripinfo as SUMO's binary on the
    same configuration and seed."""
    cfg = _small_cfg(tmp_path, end=90.0)
    r = simulate(sumo_scenario(cfg), out_dir=tmp_path / "ours", share=0.0, seed=3,
                 progress=False)
    assert r.metrics["planned"] == 0
    plain = tmp_path / "plain.xml"
    subprocess.run([sumolib.checkBinary("sumo"), "-c", str(cfg), "--seed", "3",
                    "--tripinfo-output", str(plain), "--no-step-log", "true"],
                   check=True, capture_output=True)
    # the same trips; the devices differ by name only (ours also writes FCD)
    ours = _trips(tmp_path / "ours" / "tripinfo.xml")
    theirs = _trips(plain)
    assert len(ours) >= 10
    for t in (*ours, *theirs):
        t.pop("devices")
    assert ours == theirs


def test_share_plans_a_seeded_draw(tmp_path: Path) -> None:
    """A share draws the same passenger vehicles for the same seed; each planned one starts
    where SUMO inserted it and heads for its route's last edge."""
    cfg = _small_cfg(tmp_path, end=40.0)
    r1 = simulate(sumo_scenario(cfg), out_dir=tmp_path / "one", share=0.5, seed=5,
                  progress=False)
    r2 = simulate(sumo_scenario(cfg), out_dir=tmp_path / "two", share=0.5, seed=5,
                  progress=False)
    assert r1.vehicles and set(r1.vehicles) == set(r2.vehicles)
    assert not any(v.startswith("bus") for v in r1.vehicles)  # passenger vehicles only
    for v in r1.vehicles.values():
        assert v.metrics["collisions"] == 0
        assert v.metrics["depart_time"] is not None


def test_a_vehicle_inserted_on_an_edge_shorter_than_itself_drives_off(tmp_path: Path) -> None:
    """SUMO inserts a 5 m car on a first edge 1 m long with its front at the edge's end, so
    that its centre lies 1.5 m behind its route's start (Monaco's random trips have such
    edges). The planned vehicle plans on its route extended back and arrives; before, it
    could plan no start outside the corridor and stood there for the whole run."""
    (tmp_path / "n.nod.xml").write_text(
        '<nodes><node id="a" x="0" y="0"/><node id="b" x="1" y="0"/>'
        '<node id="c" x="200" y="0"/></nodes>')
    (tmp_path / "n.edg.xml").write_text(
        '<edges><edge id="ab" from="a" to="b" numLanes="1" speed="13.89"/>'
        '<edge id="bc" from="b" to="c" numLanes="1" speed="13.89"/></edges>')
    subprocess.run([sumolib.checkBinary("netconvert"), "-n", str(tmp_path / "n.nod.xml"),
                    "-e", str(tmp_path / "n.edg.xml"), "-o", str(tmp_path / "n.net.xml")],
                   check=True, capture_output=True)
    (tmp_path / "r.rou.xml").write_text(
        '<routes><vType id="car" vClass="passenger" length="5"/><vehicle id="v" type="car" '
        'depart="0" departSpeed="max"><route edges="ab bc"/></vehicle></routes>')
    cfg = tmp_path / "short.sumocfg"
    cfg.write_text('<configuration><input><net-file value="n.net.xml"/>'
                   '<route-files value="r.rou.xml"/></input><time><end value="60"/>'
                   '<step-length value="0.1"/></time></configuration>')
    r = simulate(sumo_scenario(cfg), out_dir=tmp_path / "out", vehicles=("v",),
                 progress=False)
    m = r.vehicles["v"].metrics
    assert m["status"] == "arrived"
    assert m["distance"] > 190.0
    # off the road only until its rear has come onto the first edge (3.5 m at 13.89 m/s)
    assert m["time_off_road"] <= 0.5


# ---- bad input ------------------------------------------------------------------------------

def _cli(*args: str) -> int:
    return cli.main(["simulate", *args, "--no-progress"])


def test_unknown_vehicle_id_and_type(tmp_path: Path, capsys: pytest.CaptureFixture[str]
                                     ) -> None:
    cfg = _small_cfg(tmp_path)
    assert _cli(str(cfg), "--vehicles", "nobody", "--out", str(tmp_path / "o")) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "unknown vehicle id 'nobody'" in err[0]
    assert _cli(str(cfg), "--vtype", "truck", "--out", str(tmp_path / "o")) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "unknown vehicle type 'truck'" in err[0]
    # a flow's vehicle is known by <flow id>.<n>
    with pytest.raises(ScenarioError, match=r"'same\.x\.y'"):
        simulate(sumo_scenario(cfg), out_dir=tmp_path / "p", vehicles=("same.x.y",),
                 progress=False)


@pytest.mark.parametrize("share", ["1.5", "-0.1", "nan"])
def test_share_outside_unit_interval(tmp_path: Path, share: str,
                                     capsys: pytest.CaptureFixture[str]) -> None:
    cfg = _small_cfg(tmp_path)
    with pytest.raises(SystemExit) as exc:
        _cli(str(cfg), "--share", share, "--out", str(tmp_path / "o"))
    assert exc.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--share" in err[0]
    with pytest.raises(ParameterError, match="--share"):
        simulate(sumo_scenario(cfg), out_dir=tmp_path / "p", share=2.0, progress=False)


def test_sumocfg_sumo_rejects(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    cfg = tmp_path / "bad.sumocfg"
    cfg.write_text(f"""<configuration><input>
  <net-file value="{NETS / 'city.net.xml'}"/>
</input><processing><no-such-option value="1"/></processing></configuration>""")
    assert _cli(str(cfg), "--share", "0.5", "--out", str(tmp_path / "o")) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "SUMO failed to start" in err[0]
    summary = json.loads((tmp_path / "o" / "summary.json").read_text())
    assert summary["status"] == "failed" and "SUMO failed to start" in summary["reason"]


def test_planned_vehicle_removed_by_sumo(tmp_path: Path) -> None:
    """One of two planned vehicles is removed from outside: it fails, saying so in one
    line; the other drives on and arrives; all outputs are written."""
    sc = load_scenario(SCENARIOS / "two_side_by_side.toml")

    def remove(t: float) -> None:
        if abs(t - 5.0) < 1e-6:
            libsumo.vehicle.remove("b")

    r = simulate(sc, out_dir=tmp_path, progress=False, on_step=remove)
    b = r.vehicles["b"]
    assert b.status == "failed" and "'b' left the simulation at t=5.0 s" in b.reason
    assert "\n" not in b.reason
    assert r.vehicles["a"].arrived and r.status == "failed"
    rows = _rows(tmp_path / "b" / "trajectory.csv")
    assert rows and rows[-1]["t"] <= 5.0
    assert json.loads((tmp_path / "summary.json").read_text())["statuses"] == {
        "arrived": 1, "failed": 1}


def test_single_ego_keeps_its_layout(tmp_path: Path) -> None:
    """One [ego] table: the outputs stay in the folder itself (no summary)."""
    r = simulate(load_scenario(SCENARIOS / "empty_road.toml"), out_dir=tmp_path,
                 progress=False)
    assert r.arrived and not r.vehicles
    assert (tmp_path / "metrics.json").is_file() and not (tmp_path / "summary.json").exists()


def test_duplicate_ego_ids(tmp_path: Path) -> None:
    p = tmp_path / "dup.toml"
    p.write_text(f'network = "{NETS / "grid.net.xml"}"\n'
                 '[[ego]]\nstart_edge = "A0B0"\ngoal_edge = "C0D0"\nid = "x"\n'
                 '[[ego]]\nstart_edge = "A1B1"\ngoal_edge = "C1D1"\nid = "x"\n')
    with pytest.raises(ScenarioError, match="two planned vehicles with id 'x'"):
        load_scenario(p)




def test_ego_tables_default_ids_and_dimensions(tmp_path: Path) -> None:
    """[[ego]] tables without ids are 'ego', 'ego2', ...; each planned vehicle's level 2
    uses its own footprint and level 3 at most its own top speed."""
    p = tmp_path / "three.toml"
    p.write_text(f'network = "{NETS / "grid.net.xml"}"\n'
                 '[[ego]]\nstart_edge = "A0B0"\ngoal_edge = "C0D0"\n'
                 '[[ego]]\nstart_edge = "A1B1"\ngoal_edge = "C1D1"\nlength = 6.0\n'
                 'max_speed = 10.0\n'
                 '[[ego]]\nstart_edge = "A2B2"\ngoal_edge = "C2D2"\n')
    sc = load_scenario(p)
    assert [e.id for e in sc.egos] == ["ego", "ego2", "ego3"] and sc.ego is sc.egos[0]
    second = sc.for_vehicle(sc.egos[1])
    assert second.roadmap.vehicle_length == 6.0 and second.trajectory.s_max == 10.0
    assert sc.for_vehicle(sc.egos[2]).trajectory.s_max == sc.trajectory.s_max


def test_planned_vehicle_keeps_to_its_lane_among_sumo_traffic(tmp_path: Path) -> None:
    """On a street of two lanes one way, a planned vehicle among SUMO's cars drives within
    one lane (SUMO has it on one lane only, and the drivers of the other lane do not see
    a part of it that reaches into theirs), so that SUMO's cars passing it in the other
    lane never touch it."""
    cars = "\n".join(
        f'<vehicle id="c{k}" depart="{2.0 * k:g}" departLane="1" departPos="5" '
        f'departSpeed="max" type="car"><route edges="A1B1 B1C1 C1D1"/></vehicle>'
        for k in range(1, 6))
    routes = f"""<routes>
<vType id="car" length="4.5" width="1.8" vClass="passenger" lcStrategic="-1"
       lcSpeedGain="0" lcKeepRight="0"/>
<vehicle id="p" depart="0" departLane="0" departPos="20" type="car">
  <route edges="A1B1 B1C1 C1D1"/></vehicle>
{cars}
</routes>"""
    sc, r = _p_among_sumo(tmp_path, "grid.net.xml", routes, 45.0)
    d = r.vehicles["p"].driven
    # the corridor of a street spans both lanes, its reference the line between them:
    # within a lane, the centre keeps half the car's width from that line
    half = sc.ego.width / 2.0
    on_street = [abs(float(lat)) for lat, lane, st in zip(d["lateral"], d["lane"],
                                                          d["station"], strict=True)
                 if not str(lane).startswith(":") and st > 25.0]
    assert len(on_street) > 100
    assert min(on_street) >= half - 0.05
    assert r.metrics["pairs"]["collision_pairs_planned"] == []
    assert r.vehicles["p"].metrics["time_off_road"] == 0.0


def test_planned_vehicle_turns_into_the_lane_its_connection_leads_to(tmp_path: Path) -> None:
    """At the city's junction A1 a planned car turns left into the two-lane street east
    while a SUMO car turns right into it from the other side: SUMO's connections put the
    left turn on the street's left lane and the right turn on its right one. The planned
    car comes out on the left lane and stays there (it would otherwise cut across the
    right turn), and the two never touch."""
    _, r = _p_and_q(tmp_path, ("A2A1 A1B1", 80.0), ("A0A1 A1B1", 90.0), 40.0)
    d = r.vehicles["p"].driven
    after = [str(lane) for lane in d["lane"] if str(lane).startswith("A1B1")]
    assert len(after) > 20
    assert set(after) == {"A1B1_1"}
    assert r.metrics["pairs"]["collision_pairs_planned"] == []
    q_lanes = {str(v.get("lane")) for v in ET.parse(tmp_path / "out" / "fcd.xml").iter("vehicle")
               if v.get("id") == "q"}
    assert "A1B1_0" in q_lanes


@pytest.mark.parametrize("car_pos", [50.0, 62.0])
def test_planned_vehicle_gives_way_to_a_bus_body_sweeping_through_a_turn(
        tmp_path: Path, car_pos: float) -> None:
    """At the city's junction E0 a 12 m bus turns left from the west while a planned car
    turns right from the north: SUMO's connections are no foes, but the bus's body cuts
    across the inside of its turn, over the car's way. The planned car waits until the
    body has passed, and keeps the safety margin from it (without this it was hit)."""
    _p_keeps_off_bus(tmp_path, ("D0E0 E0E1", 60.0, "8"), ("E1E0 E0D0", car_pos), 25.0)


@pytest.mark.parametrize(("p_pos", "q_pos"), [(60.0, 120.0), (50.0, 100.0), (80.0, 130.0)])
def test_planned_vehicle_passes_a_car_waiting_with_its_front_in_its_way(
        tmp_path: Path, p_pos: float, q_pos: float) -> None:
    """At the city's junction E1 a planned car goes straight on (E0E1 -> E1E2) while
    SUMO's car 'q' turns left off the bridge: q waits for it at its internal junction,
    the end of its first junction lane, which puts its front 0.6 m into the planned car's
    lane. The planned car stood behind that front for good (at five of six timings
    tried, these three among them; in the city's traffic SUMO teleported such a car
    after 300 s, and the junction jammed). Now a vehicle that has held it standing
    inside a junction for 5 s, standing across its way itself, is an obstacle for level
    2: the car plans round q's front and passes it with the margin."""
    _p_arrives_clear(tmp_path, _routes(("q", "car", "bridge_west E1E0", q_pos, "max"),
                                       ("p", "car", "E0E1 E1E2", p_pos, "max")), 40.0)


@pytest.mark.parametrize(("bus_pos", "car_pos"), [(100.0, 30.0), (105.0, 30.0), (104.0, 35.0)])
def test_planned_vehicle_and_a_bus_creeping_into_the_junction_do_not_wait_for_each_other(
        tmp_path: Path, bus_pos: float, car_pos: float) -> None:
    """At the city's priority junction C3 a planned car turns left from C2C3, a major
    link, as a 12 m bus sets off straight across from B3C3, a minor one: SUMO's bus does
    not see the car come and creeps into the junction, then waits for it there, while
    the car gave way to the creeping body. Before, the car then stood in the bus's way or
    short of it, and both stood for good (the car never arrived, at each of five
    timings). Now a slow body is followed until it has left the junction, speeding up
    as SUMO's drivers do there, and a bus that stands across the car's way is planned
    round: at these three timings the car arrives, and their footprints keep half the
    safety margin. (At the other two the bus stands with its front against the car's
    path, and no curve of the car gets round it.)"""
    _p_arrives_clear(tmp_path, _routes(("b", "bus", "B3C3 C3D3", bus_pos, "0"),
                                       ("p", "car", "C2C3 C3B3", car_pos, "max",
                                        'departLane="1"')), 40.0)


@pytest.mark.parametrize(("bus_pos", "car_pos"), [(78.0, 74.0), (78.0, 78.0), (82.0, 82.0)])
def test_planned_vehicle_keeps_off_a_bus_rear_swinging_round_a_corner(
        tmp_path: Path, bus_pos: float, car_pos: float) -> None:
    """At the city's square corner E3 a planned car turns left from E2E3 into E3D3 as a
    12 m bus turns right from D3E3 into E3E2. SUMO turns the bus to the direction from its
    back to its front, so its rectangle reaches past its back out over E3D3, where the car
    drives on. Before, the car predicted the body centred on that chord, 1.3 m short of
    the rear, and the bus's rear hit it at these timings; now the body is SUMO's
    rectangle: the car arrives, and their footprints keep half the safety margin."""
    _p_keeps_off_bus(tmp_path, ("D3E3 E3E2", bus_pos, "max"), ("E2E3 E3D3", car_pos), 30.0)


def _p_keeps_off_bus(tmp_path: Path, bus: tuple[str, float, str], car: tuple[str, float],
                     duration: float) -> None:
    """A 12 m bus 'b' (route edges, depart position [m], depart speed) and the planned car
    'p' (route edges, depart position [m]) on the city's network:
    :func:`_p_arrives_clear`."""
    _p_arrives_clear(tmp_path, _routes(("b", "bus", bus[0], bus[1], bus[2]),
                                       ("p", "car", car[0], car[1], "max")), duration)


def _routes(*vehicles: tuple[str, ...] | tuple[Any, ...]) -> str:
    """A route file's text: a 4.5 x 1.8 m car type ``car``, a 12 x 2.5 m bus type ``bus``,
    and ``vehicles`` departing at 0 s, each (id, type, route edges, depart position [m],
    depart speed, and any more attributes)."""
    rows = "".join(
        f'<vehicle id="{v[0]}" depart="0" departPos="{float(v[3]):g}" departSpeed="{v[4]}" '
        f'type="{v[1]}" {" ".join(v[5:])}><route edges="{v[2]}"/></vehicle>\n'
        for v in vehicles)
    return ('<routes>\n<vType id="car" length="4.5" width="1.8" vClass="passenger"/>\n'
            '<vType id="bus" length="12" width="2.5" vClass="bus"/>\n' + rows + "</routes>")


def _p_arrives_clear(tmp_path: Path, routes: str, duration: float) -> None:
    """SUMO's run of ``routes`` on the city's network with 'p' planned
    (:func:`_p_among_sumo`): p arrives, its footprint never touches another's and keeps
    half the safety margin from every other."""
    sc, r = _p_among_sumo(tmp_path, "city.net.xml", routes, duration)
    pairs = r.metrics["pairs"]
    assert pairs["collision_pairs_planned"] == []
    assert pairs["min_gap_planned"]["value"] >= 0.5 * sc.roadmap.safety_margin
    assert r.vehicles["p"].status == "arrived"


@pytest.mark.parametrize(("p_pos", "q_pos"), [(80.0, 0.0), (85.0, 0.0), (90.0, 5.0)])
def test_planned_vehicle_gives_way_to_foes_sumo_does_not_report(
        tmp_path: Path, p_pos: float, q_pos: float) -> None:
    """At the city's priority junction C0 a planned car ('p') turns left from D0C0, a
    minor link, as SUMO's car 'q' comes from RNC0, whose links have the right of way
    over it. ``getJunctionFoes`` reports no foe of the links from D0C0 (SUMO 1.28), so
    the world finds them itself: p gives way, and q passes (SUMO's FCD: q is out of the
    junction before p enters it). Before, p drove on, and q hit it or both stood in the
    junction for good."""
    sc, r = _p_and_q(tmp_path, ("D0C0 C0RN", p_pos), ("RNC0 C0B0", q_pos), 40.0)
    pairs = r.metrics["pairs"]
    assert pairs["collision_pairs_planned"] == []
    assert pairs["min_gap_planned"]["value"] >= sc.roadmap.safety_margin
    assert r.vehicles["p"].status == "arrived"
    inside: dict[str, list[float]] = {"p": [], "q": []}
    for step in ET.parse(tmp_path / "out" / "fcd.xml").iter("timestep"):
        for v in step.iter("vehicle"):
            if v.get("lane", "").startswith(":C0_"):
                inside[v.get("id", "")].append(float(step.get("time", "nan")))
    assert inside["p"] and inside["q"]
    assert max(inside["q"]) < min(inside["p"])  # q went first


@pytest.mark.parametrize(("p_pos", "bus_pos"), [(80.0, 55.0), (85.0, 65.0), (95.0, 75.0)])
def test_planned_vehicle_keeps_off_a_bus_body_that_has_left_the_junction(
        tmp_path: Path, p_pos: float, bus_pos: float) -> None:
    """At the city's junction D0 a 12 m bus turns right from D1D0 onto D0C0 while a
    planned car waits inside the junction to turn left onto the same lane. After the
    bus's front has left the junction its body still sweeps through it: the car waits
    for it there, off its way, and then follows the bus. Before, its body was predicted
    only while its front was in the junction, and the car drove into it."""
    _p_keeps_off_bus(tmp_path, ("D1D0 D0C0", bus_pos, "max"), ("SED0 D0C0", p_pos), 30.0)


def test_planned_vehicle_changes_lanes_only_into_a_gap(tmp_path: Path) -> None:
    """A planned car in the left lane of a two-lane street must change to the right lane
    for its right turn at the end, while SUMO's cars stream past in the right lane at
    13-14 m/s, 2 s apart: it waits in its lane for a gap and changes into it. While its
    footprint reaches over the line between the lanes, it keeps a quarter of a metre
    from every car in the right lane (shapely footprints from SUMO's FCD; without the
    wait it let a car pass 0.1 m from its side)."""
    cars = [(2.0 * k, f'<vehicle id="c{k}" depart="{2.0 * k:g}" departLane="0" departPos="5" '
             'departSpeed="max" type="car"><route edges="A1B1 B1C1 C1D1"/></vehicle>')
            for k in range(8)]
    cars.append((4.0, '<vehicle id="p" depart="4" departLane="1" departPos="20" '
                      'departSpeed="max" type="car"><route edges="A1B1 B1C1 C1C0"/></vehicle>'))
    routes = ('<routes>\n<vType id="car" length="4.5" width="1.8" vClass="passenger" '
              'lcStrategic="-1" lcSpeedGain="0" lcKeepRight="0"/>\n'
              + "\n".join(v for _, v in sorted(cars, key=lambda c: c[0])) + "\n</routes>")
    _, r = _p_among_sumo(tmp_path, "grid.net.xml", routes, 60.0)
    assert r.metrics["pairs"]["collision_pairs_planned"] == []
    assert r.vehicles["p"].status == "arrived"
    net = sumolib.net.readNet(str(NETS / "grid.net.xml"))
    line = LineString(net.getLane("B1C1_0").getShape()).parallel_offset(1.6, "left")

    def body(v: ET.Element) -> Polygon:
        h = np.radians(90.0 - float(v.get("angle", 0.0)))
        u, n = np.array([np.cos(h), np.sin(h)]), np.array([-np.sin(h), np.cos(h)])
        f = np.array([float(v.get("x", 0.0)), float(v.get("y", 0.0))])
        return Polygon([f + 0.9 * n, f - 0.9 * n, f - 4.5 * u - 0.9 * n, f - 4.5 * u + 0.9 * n])

    across = 0
    for step in ET.parse(tmp_path / "out" / "fcd.xml").iter("timestep"):
        vs = {str(v.get("id")): v for v in step.iter("vehicle")}
        p = vs.get("p")
        if p is None or not str(p.get("lane")).startswith("B1C1") or not body(p).intersects(
                line):
            continue
        across += 1
        for k, v in vs.items():
            if k != "p" and v.get("lane") == "B1C1_0":
                assert body(p).distance(body(v)) >= 0.25, (step.get("time"), k)
    assert across > 5  # it did change lanes


def _p_crosses_q(tmp_path: Path, p: tuple[int, float, str], q: tuple[int, float, str],
                 duration: float) -> None:
    """On the city network, the planned car 'p' and SUMO's car 'q', each departing at full
    speed from ``(lane, position [m], route edges)``, cross paths: p arrives, no footprint
    with a planned car overlaps another, and p keeps the safety margin from every car."""
    cars = "".join(
        f'<vehicle id="{vid}" depart="0" departLane="{lane}" departPos="{pos:g}" '
        f'departSpeed="max" type="car"><route edges="{edges}"/></vehicle>\n'
        for vid, (lane, pos, edges) in (("p", p), ("q", q)))
    routes = ('<routes>\n<vType id="car" length="4.5" width="1.8" vClass="passenger"/>\n'
              f"{cars}</routes>")
    sc, r = _p_among_sumo(tmp_path, "city.net.xml", routes, duration)
    assert r.vehicles["p"].status == "arrived"
    pairs = r.metrics["pairs"]
    assert pairs["collision_pairs_planned"] == []
    assert pairs["min_gap_planned"]["value"] >= sc.roadmap.safety_margin


def test_planned_vehicle_keeps_a_junction_clear(tmp_path: Path) -> None:
    """A car crawls just beyond a junction: a planned vehicle coming up behind it stops
    before the junction, as SUMO's drivers do, rather than in it, where it would stand in
    the way of the crossing traffic; it never enters the junction while there is no room
    behind that car."""
    routes = """<routes>
<vType id="car" length="4.5" width="1.8" vClass="passenger"/>
<vType id="crawl" length="4.5" width="1.8" vClass="passenger" maxSpeed="0.05"/>
<vehicle id="q" depart="0" departLane="0" departPos="7" departSpeed="0" type="crawl">
  <route edges="B1C1 C1D1"/></vehicle>
<vehicle id="p" depart="0" departLane="0" departPos="60" type="car">
  <route edges="A1B1 B1C1 C1D1"/></vehicle>
</routes>"""
    _, r = _p_among_sumo(tmp_path, "grid.net.xml", routes, 25.0)
    d = r.vehicles["p"].driven
    lanes = [str(lane) for lane in d["lane"]]
    assert not any(lane.startswith(":B1") for lane in lanes)
    assert lanes[-1] == "A1B1_0" and float(d["speed"][-1]) < 0.1
    assert r.vehicles["p"].metrics["stuck"] == [] or all(
        "junction clear" in s["why"] for s in r.vehicles["p"].metrics["stuck"])


def test_planned_vehicle_stops_at_an_all_way_stop(tmp_path: Path) -> None:
    """At the city's all-way stop (D2), a planned car ('p') comes to a full stop with its
    front near the stop line and stands there for a moment before it crosses, as SUMO's
    own car beside it ('q') does; before, it drove through at speed."""
    from splineplan.closedloop.control import STOP_LINE, STOP_REACH, STOP_WAIT

    routes = """<routes>
<vType id="car" length="4.5" width="1.8" vClass="passenger"/>
<vehicle id="p" depart="0" departLane="1" departPos="20" departSpeed="max" type="car">
  <route edges="E2D2 D2C2"/></vehicle>
<vehicle id="q" depart="0" departLane="0" departPos="5" departSpeed="max" type="car">
  <route edges="E2D2 D2C2"/></vehicle>
</routes>"""
    _, r = _p_among_sumo(tmp_path, "city.net.xml", routes, 40.0)
    assert r.vehicles["p"].status == "arrived"
    end = sumolib.net.readNet(str(NETS / "city.net.xml")).getEdge("E2D2").getLength()
    stood: dict[str, float] = {"p": 0.0, "q": 0.0}
    crossed: dict[str, bool] = {}
    for step in ET.parse(tmp_path / "out" / "fcd.xml").iter("timestep"):
        for v in step.iter("vehicle"):
            vid, lane = str(v.get("id")), str(v.get("lane"))
            if lane.startswith(":D2"):
                crossed[vid] = True
            elif (lane.startswith("E2D2") and float(v.get("speed", 1.0)) < 0.1
                  and end - float(v.get("pos", 0.0)) <= STOP_LINE + STOP_REACH):
                assert not crossed.get(vid)
                stood[vid] += 0.1  # the step length
    assert crossed == {"p": True, "q": True}
    # both come to a full stop at the line; p stands its waiting time there (SUMO's car
    # a step or two)
    assert stood["p"] >= STOP_WAIT - 0.05 and stood["q"] > 0.0, stood
    why = {row["why_slow"] for row in _rows(tmp_path / "out" / "p" / "trajectory.csv")}
    assert "stopping at a stop sign" in why


@pytest.mark.parametrize("q_pos", [0.0, 60.0])
def test_planned_vehicle_takes_its_turn_at_an_all_way_stop(tmp_path: Path, q_pos: float
                                                            ) -> None:
    """A planned car ('p') and SUMO's car ('q', from the north) reach the all-way stop
    D2 at about the same time (q a little before or after p): SUMO's car does not see a
    car SUMO does not drive, so p, once stopped, waits for q to cross; they keep the
    margin (p driving through hit q at 60 m, and p going after its stop alone hit q at
    0 m)."""
    _p_crosses_q(tmp_path, (1, 20.0, "E2D2 D2C2"), (0, q_pos, "D3D2 D2D1"), 40.0)


@pytest.mark.parametrize("q_pos", [60.0, 100.0])
def test_a_car_giving_way_inside_a_junction_goes_once_the_foe_waits_for_it(
        tmp_path: Path, q_pos: float) -> None:
    """A planned car ('p') turning left at D3 stops inside the junction to give way to
    SUMO's car coming straight on ('q'); q, seeing p on the junction's lanes, stops too.
    The all-way stop's rule (a standing foe may go any moment) belongs to D2, the next
    junction on p's route, not to D3: p goes, and both cross with the margin. Before,
    p waited in D3 for the standing q, and q for p, until the run's end."""
    _p_crosses_q(tmp_path, (0, 60.0, "E3D3 D3D2 D2D1"), (0, q_pos, "C3D3 D3E3"), 60.0)
    arrived = {t.get("id") for t in ET.parse(tmp_path / "out" / "tripinfo.xml").iter("tripinfo")}
    assert arrived == {"p", "q"}


@pytest.mark.parametrize(("q_pos", "p_pos"), [(60.0, 60.0), (55.0, 60.0), (65.0, 60.0)])
def test_a_car_giving_way_to_a_left_turn_waits_before_the_junction(
        tmp_path: Path, q_pos: float, p_pos: float) -> None:
    """SUMO's car 'q' turns left from D1E1 into E1E2, where it waits for the oncoming
    traffic at its internal junction inside E1; the planned car 'p' goes straight on from
    E0E1 into the same lane and must give way to q. Where p stood inside the junction,
    before the area it shares with q, q waited at its internal junction with its front in
    p's way, for p to leave the junction's lanes, and p for q: both for good. p stands
    before the junction instead, on its own lane, and both arrive."""
    routes = _routes(("q", "car", "D1E1 E1E2", q_pos, "max", 'departLane="1"'),
                     ("p", "car", "E0E1 E1E2", p_pos, "max"))
    _, r = _p_among_sumo(tmp_path, "city.net.xml", routes, 40.0)
    assert r.metrics["pairs"]["collision_pairs_planned"] == []
    arrived = {t.get("id") for t in ET.parse(tmp_path / "out" / "tripinfo.xml").iter("tripinfo")}
    assert arrived == {"p", "q"}
    d = r.vehicles["p"].driven
    stands = {str(lane) for lane, v in zip(d["lane"], d["speed"], strict=True)
              if float(v) < 0.1}
    assert not any(lane.startswith(":") for lane in stands), stands


def _bridge_beside(tmp_path: Path, crawl: float) -> Any:
    """D1E1 onto the one-lane bridge: the planned car 'p' goes straight on, its footprint
    reaching over the line into the left lane as it comes to the junction, where SUMO's
    car 'q' creeps at ``crawl`` [m/s] towards its left turn. The run's result."""
    routes = f"""<routes>
<vType id="car" length="4.5" width="1.8" vClass="passenger"/>
<vType id="crawl" length="4.5" width="1.8" vClass="passenger" maxSpeed="{crawl:g}"/>
<vehicle id="q" depart="0" departLane="1" departPos="98" departSpeed="0" type="crawl">
  <route edges="D1E1 E1E2"/></vehicle>
<vehicle id="p" depart="0" departLane="0" departPos="30" departSpeed="max" type="car">
  <route edges="D1E1 bridge_east F1G1"/></vehicle>
</routes>"""
    return _p_among_sumo(tmp_path, "city.net.xml", routes, 30.0)[1]


def test_a_car_waiting_to_change_lanes_waits_before_the_junction(tmp_path: Path) -> None:
    """'q' crawls at 0.3 m/s: the planned car waits for the gap before the junction, on
    its own lane, not inside the junction (where it stood in the way of the crossing
    traffic, waiting for a gap that the junction's lanes do not need)."""
    r = _bridge_beside(tmp_path, 0.3)
    assert r.metrics["pairs"]["collision_pairs_planned"] == []
    d = r.vehicles["p"].driven
    lanes = [str(lane) for lane in d["lane"]]
    stands = [lane for lane, v in zip(lanes, d["speed"], strict=True) if float(v) < 0.1]
    assert stands and all(lane == "D1E1_0" for lane in stands), set(stands)


def test_a_car_standing_beside_a_footprint_over_the_line_is_passed(tmp_path: Path) -> None:
    """'q' stands (0.05 m/s): no gap along the lane is needed where the footprint passes
    it, over the line, with room to spare (``control.SIDE_CLEAR``). The planned car goes
    on without stopping and keeps clear of it (it stood there for good before, waiting
    for a gap that a standing queue never gives)."""
    r = _bridge_beside(tmp_path, 0.05)
    assert r.metrics["pairs"]["collision_pairs_planned"] == []
    assert r.metrics["pairs"]["min_gap_planned"]["value"] >= SIDE_CLEAR - 0.05
    p = r.vehicles["p"]
    assert p.status == "arrived"
    assert min(float(v) for v in p.driven["speed"]) >= 1.0


@given(st.floats(0.0, 30.0), st.floats(0.0, 30.0), st.sampled_from(["a", "b"]),
       st.booleans())
def test_of_two_planned_cars_giving_way_to_each_other_one_goes_first(
        d_a: float, d_b: float, first: str, same: bool) -> None:
    """Two standing planned cars, each of which must give way to the other by SUMO's
    right of way (both inside a junction, say), at ``d_a`` and ``d_b`` [m] from their
    conflict area: exactly one of them takes the other for one that goes first. Both
    waiting was a deadlock; both going, a collision."""
    if same:
        d_b = d_a
    one, two = ("a", "b") if first == "a" else ("b", "a")  # at d_a and d_b

    def waits(me: str, other: str, d_me: float, d_other: float) -> bool:
        """Whether ``me`` takes ``other`` for one that goes first (and waits for it)."""
        view = type("View", (), {"board": {other: None}, "ego": me})()
        foe = JunctionFoe(other, d_me, d_other, d_me + 3.0, d_other + 3.0, True, 0.0, 4.5)
        return Control._goes_first(view, foe)  # type: ignore[arg-type]

    one_waits = waits(one, two, d_a, d_b)
    two_waits = waits(two, one, d_b, d_a)
    assert one_waits != two_waits
    if d_a != d_b:
        assert two_waits == (d_a < d_b)  # the nearer one goes first


def _lane_view(pose: tuple[float, float, float] = (0.0, 0.0, 0.0), lane: str = "",
               board: tuple[str, ...] = ()) -> Any:
    """A stand-in for a planned car on the city's network (the real network, the car's
    4.5 x 1.8 m size), its centre and heading at ``pose``, on SUMO's lane ``lane``, with
    the published plans of ``board``: what the control's junction methods read."""
    ego = type("Ego", (), {"length": 4.5, "width": 1.8})()
    return type("View", (), {
        "net": _city_network(),
        "sc": type("Sc", (), {"ego": ego})(), "pose": np.array(pose), "last_lane": lane,
        "board": dict.fromkeys(board), "_lane_band": Control._lane_band, "_bands": {}})()


@functools.cache
def _city_network() -> Any:
    """The city's network, read once."""
    from splineplan.network import load_network

    return load_network(NETS / "city.net.xml")


def _box(x: float, y: float, h: float, length: float = 4.5, width: float = 1.8) -> Polygon:
    """The rectangle of a vehicle centred at ``x``, ``y`` [m], heading ``h`` [rad]."""
    c, s_ = math.cos(h), math.sin(h)
    a, b = length / 2.0, width / 2.0
    return Polygon([(x + p * c - q * s_, y + p * s_ + q * c)
                    for p, q in ((a, b), (-a, b), (-a, -b), (a, -b))])


@settings(deadline=None)  # the first example reads the network
@given(st.floats(6.0, 9.0), st.floats(-4.0, 4.0), st.floats(-math.pi, math.pi),
       st.floats(1.8, 2.6))
def test_a_footprint_over_a_foes_lane_is_in_its_way(station: float, offset: float,
                                                     heading: float, width: float) -> None:
    """A planned car that stands giving way at a junction but whose footprint already
    reaches over the foe's lane (where a foe ``width`` [m] wide drives) is in its way:
    it goes on to clear it rather than wait there to be hit (a bus ran into one that way).
    ``Control._in_lane_way`` against shapely, on the city's straight lane through C1,
    clear of the lane's ends."""
    lane = ":C1_1_0"
    view = _lane_view()
    line = LineString(view.net.lane(lane).shape)
    p = line.interpolate(station)
    q = line.interpolate(station + 0.1)
    h = math.atan2(q.y - p.y, q.x - p.x)
    x, y = p.x - offset * math.sin(h), p.y + offset * math.cos(h)
    view.pose = np.array([x, y, heading])
    band = line.buffer(width / 2.0, cap_style="flat")
    car = _box(x, y, heading)
    gap, depth = car.distance(band), car.intersection(band).area
    assume(gap > 1e-3 or depth > 1e-4)  # not on the edge's rounding
    assert Control._in_lane_way(view, lane, width) == (gap <= 1e-3)


def test_sumo_foes_outside_the_junction_wait_for_a_planned_car_in_it() -> None:
    """A planned car that must give way but is in the junction already (on its only
    internal lane) goes on where SUMO's foe is still outside it and can stop before the
    conflict area: SUMO's drivers wait for vehicles in a junction, and two that waited
    for each other stood for good. Not where the foe cannot stop, is on the junction's
    lane already, or is another planned car (its plan times the meeting), nor before an
    internal junction, where SUMO's drivers wait for foes that drive on."""
    from splineplan.closedloop.control import FOE_DECEL

    def waits(ego_lane: str, foe_in: float, speed: float, planned: bool = False) -> bool:
        """Whether SUMO's car 'q' (left turn from the bridge at E1) waits for the ego."""
        view = _lane_view(lane=ego_lane, board=("q",) if planned else ())
        foe = JunctionFoe("q", 3.0, foe_in, 8.0, foe_in + 6.0, True, speed, 4.5,
                          ":E1_3_0", 1.8)
        return Control._foe_waits(view, foe)  # type: ignore[arg-type]

    straight = ":E1_5_0"  # E0E1 -> E1E2, one internal lane
    stop = math.sqrt(2.0 * FOE_DECEL * 30.0)  # the fastest that stops within 30 m
    assert waits(straight, 30.0, 9.0)
    assert waits(straight, 30.0, 0.0)
    assert not waits(straight, 30.0, stop + 0.5)
    assert not waits(straight, 3.0, 1.0)  # on the junction's lane (5.1 m) already
    assert not waits(straight, 30.0, 9.0, planned=True)
    assert not waits(":C1_2_0", 30.0, 9.0)  # before C1's internal junction
    assert not waits("E0E1_0", 30.0, 9.0)  # not on a junction's lane at all


def _standing_beside(gap: float, bend: float) -> tuple[bool, float, float]:
    """A planned car standing at the origin, heading east, beside a car that stands to
    its left with ``gap`` [m] between the two bodies, its plan bending towards that car
    by ``bend`` [m] over 4 m: whether it passes it (``Control._clears_standing``), and
    shapely's distances between the bodies now and at the nearest along the plan."""
    from splineplan.closedloop.lanes import LaneChange
    from splineplan.traffic import Others

    u = np.linspace(0.0, 12.0, 121)
    lat = bend * np.clip(u / 4.0, 0.0, 1.0) ** 2
    head = np.arctan2(np.gradient(lat, u), 1.0)
    ego = type("Ego", (), {"length": 4.5, "width": 1.8})()
    y_other = 1.8 + gap  # its centre: half widths and the gap to the left
    others = Others(["q"], np.array([[2.25, y_other, 90.0, 4.5, 1.8, 0.0, 0.0]]), 0.1)
    view = type("View", (), {
        "u": 0.0, "path_s": u, "path_xy": np.column_stack((u, lat)), "path_heading": head,
        "others": others, "sc": type("Sc", (), {"ego": ego})(),
        "_keeps_off": Control._keeps_off})()
    change = LaneChange(at=0.0, lane=1, width=3.2, lane_id="x_1", end=12.0)
    passes = Control._clears_standing(view, 0, change)  # type: ignore[arg-type]

    def box(x: float, y: float, h: float) -> Polygon:
        c, s_ = math.cos(h), math.sin(h)
        return Polygon([(x + a * c - b * s_, y + a * s_ + b * c)
                        for a, b in ((2.25, 0.9), (-2.25, 0.9), (-2.25, -0.9), (2.25, -0.9))])
    body = box(0.0, y_other, 0.0)
    dist = [box(float(x), float(y), float(h)).distance(body)
            for x, y, h in zip(u, lat, head, strict=True)]
    return passes, dist[0], min(dist)


@given(st.floats(0.02, 0.5), st.floats(-0.3, 0.6))
def test_a_standing_car_beside_is_passed_where_the_plan_comes_no_nearer(
        gap: float, bend: float) -> None:
    """Two planned cars standing side by side nearer than ``SIDE_CLEAR``, each waiting for
    a gap in the other's lane, waited for ever. A plan passes a standing car beside it
    where its footprint keeps ``SIDE_CLEAR`` from it or, standing nearer already, comes
    no nearer than it stands (shapely's distances the judge), as straight on. Bending
    away is not enough: the rear swings towards the other car."""
    passes, now, nearest = _standing_beside(gap, bend)
    need = min(SIDE_CLEAR, now)
    assume(abs(nearest - need) > 0.01)  # not on the threshold's rounding
    assert passes == (nearest >= need)
    assert _standing_beside(gap, 0.0)[0]  # straight on: never nearer than it stands


def _beside_in_way(gap: float, turn: float, along: float, bend: float, speed: float = 0.0
                   ) -> tuple[int, int, list[float], list[float]]:
    """A planned car at the origin heading east, its plan bending by ``bend`` [m] to the
    left over 4 m, and another car to its left, ``along`` [m] ahead of it, turned
    ``turn`` [rad] towards it (its right front corner nearest), ``gap`` [m] or so
    between the two, driving at ``speed`` [m/s]: the first path sample in the other's way
    (``Control._first_in_way``), the sample at the car's front, and shapely's distances
    from the car's body along the plan to the other's and from each path point to it."""
    from splineplan.closedloop.control import PATH_MARGIN
    from splineplan.traffic import Others

    u = np.arange(0.0, 12.01, 0.25)
    lat = bend * np.clip(u / 4.0, 0.0, 1.0) ** 2
    head = np.arctan2(np.gradient(lat, u), 1.0)
    h_o = -turn
    # the other's centre: its right side 0.9 m + gap above the car's left side
    cx = along
    cy = 0.9 + gap + 0.9 * math.cos(h_o) + 2.25 * math.sin(turn)
    front = (cx + 2.25 * math.cos(h_o), cy + 2.25 * math.sin(h_o))
    angle = 90.0 - math.degrees(h_o)
    others = Others(["q"], np.array([[front[0], front[1], angle, 4.5, 1.8, speed, 0.0]]),
                    0.1)
    ego = type("Ego", (), {"length": 4.5, "width": 1.8})()
    xy = np.column_stack((u, lat))
    view = type("View", (), {
        "_full": (u.tolist(), u.tolist(), lat.tolist(), head.tolist()), "full_xy": xy,
        "full_heading": head, "others": others, "_sample_step": 0.25,
        "sc": type("Sc", (), {"ego": ego})(), "_keeps_off": Control._keeps_off})()
    reach = 0.9 + PATH_MARGIN
    i_front = int(np.searchsorted(u, 2.25))
    first = Control._first_in_way(view, 0, 0, (cx, cy, float(others.radius[0]) + reach),
                                  reach, 0, i_front)  # type: ignore[arg-type]
    body = _box(cx, cy, h_o)
    bodies = [_box(float(x), float(y), float(h)).distance(body)
              for x, y, h in zip(u[:i_front + 1], lat[:i_front + 1], head[:i_front + 1],
                                 strict=True)]
    points = [Point(float(x), float(y)).distance(body) for x, y in xy]
    return first, i_front, bodies, points


@given(st.floats(0.02, 0.4), st.floats(0.0, 0.2), st.floats(-3.0, 3.0),
       st.floats(-0.4, 0.4))
def test_a_car_beside_is_in_the_way_only_where_moving_on_comes_nearer(
        gap: float, turn: float, along: float, bend: float) -> None:
    """Two planned cars side by side, each in the reach of the other's path before its
    front (one turned a little towards the other, to change lanes), waited for each other
    for good on an empty road. A car beside the body holds the car back only where its
    footprint, moved on along the plan to its front, comes within ``PATH_MARGIN`` of it
    and more than ``BESIDE_GIVE`` nearer to it than it stands, or touches it; otherwise
    it is in the way from the first path point ahead of the front in reach of it
    (shapely's distances the judge)."""
    from splineplan.closedloop.control import BESIDE_GIVE, PATH_MARGIN

    first, i_front, bodies, points = _beside_in_way(gap, turn, along, bend)
    reach = 0.9 + PATH_MARGIN
    assume(all(abs(d - reach) > 1e-3 for d in points))
    need = min(PATH_MARGIN, bodies[0] - BESIDE_GIVE)
    nearest = min(bodies)
    assume(abs(nearest - need) > 0.005 and bodies[0] > 1e-3 and not 0.0 < nearest < 1e-3)
    beside = any(d <= reach for d in points[:i_front])
    passes = nearest >= need and nearest > 0.0  # never touching
    if beside and not passes:
        assert first == next(k for k, d in enumerate(points) if d <= reach) < i_front
    else:
        ahead = [k for k, d in enumerate(points) if d <= reach and k >= i_front]
        assert first == (ahead[0] if ahead else -1)


def test_of_two_cars_side_by_side_the_one_ahead_goes_on() -> None:
    """The two of a city run that stood side by side, 0.1 m apart, for good: the one
    behind turned 0.12 rad towards the other's side, with its plan bending on that way,
    the other one straight. The one ahead goes on; the one turned towards it waits. A car
    beside that moves is in the way as before."""
    # the one ahead, seen from it (mirrored: the other to its left, 0.6 m behind, turned
    # towards it), its plan straight on: never nearer
    first, i_front, _, _ = _beside_in_way(0.1, 0.12, -0.6, 0.0)
    assert first == -1 or first >= i_front
    # but not where the other moves: it may move in
    first, i_front, _, _ = _beside_in_way(0.1, 0.12, -0.6, 0.0, speed=2.0)
    assert 0 <= first < i_front
    # the one behind, seen from it: the other to its left, 0.6 m ahead, turned towards it
    # as seen from it, and its own plan bending on towards it
    first, i_front, bodies, _ = _beside_in_way(0.1, 0.12, 0.6, 0.3)
    assert bodies[0] > 0.05 and min(bodies) == 0.0  # it would run into the other's side
    assert 0 <= first < i_front


def test_a_crossing_planned_car_is_trusted_only_while_it_moves() -> None:
    """The time gap leaves out a planned car that crosses the path where its published
    plan has it (the plan was timed among it), but not one that stands or crawls: its
    control may hold it there (giving way, in a queue) while its plan moves on, and two
    planned cars met in a junction that way."""
    from splineplan.closedloop.control import QUEUE_SPEED
    from splineplan.spacetime import MovingObstacle
    from splineplan.traffic import Others

    t = np.arange(0.0, 10.01, 0.5)
    plan = MovingObstacle("q", t, np.column_stack((0.0 * t + 10.0, 2.0 * t - 10.0)),
                          np.full(len(t), np.pi / 2), 4.5, 1.8)  # north, at (10, 0) at 5 s

    def trusted(speed: float) -> bool:
        front_y = 2.25  # the centre at (10, 0), heading north
        others = Others(["q"], np.array([[10.0, front_y, 0.0, 4.5, 1.8, speed, 0.0]]), 0.1)
        view = type("View", (), {"others": others, "trusted": {"q": plan}, "time": 5.0})()
        return Control._keeps_to_plan(view, 0, 0.0)  # type: ignore[arg-type]

    assert trusted(2.0) and trusted(QUEUE_SPEED)
    assert not trusted(0.0) and not trusted(0.5 * QUEUE_SPEED)


@given(st.dictionaries(st.sampled_from("abcdefg"),
                       st.lists(st.sampled_from("abcdefgxy"), max_size=3).map(tuple),
                       min_size=1), st.sampled_from("abcdefg"))
def test_a_cycle_of_waits_is_found_where_there_is_one(
        holds: dict[str, tuple[str, ...]], start: str) -> None:
    """The deadlock watch's search: a cycle from a standing vehicle round to it, each
    held by the next, exactly where one exists (reachability by closure the judge); the
    vehicles not standing (``x``, ``y``) end a chain."""
    from splineplan.closedloop.cooperate import waits_in_cycle

    cycle = waits_in_cycle(holds, start)
    reach = {w for w in holds.get(start, ()) if w in holds}
    while True:
        more = {u for w in reach for u in holds[w] if u in holds} - reach
        if not more:
            break
        reach |= more
    assert (cycle is not None) == (start in holds and start in reach)
    if cycle is not None:
        assert cycle[0] == start and len(set(cycle)) == len(cycle)
        assert all(b in holds[a] for a, b in zip(cycle, [*cycle[1:], start], strict=True))


def test_plan_keeps_clear_of_others_plans() -> None:
    """The check that spares a replan when others publish new plans: a plan through a
    crossing keeps clear of one that crosses 5 s later, not of one that crosses at the
    same time, nor of one that comes after it has stopped where the other passes (a plan
    stays at its end)."""
    from splineplan.closedloop.cooperate import keeps_clear_of
    from splineplan.spacetime import MovingObstacle

    t = np.arange(0.0, 10.01, 0.5)
    east = MovingObstacle("a", t, np.column_stack((-20.0 + 4.0 * t, 0.0 * t)),
                          0.0 * t, 4.5, 1.8)  # through (0, 0) at t = 5 s

    def north(delay: float) -> MovingObstacle:
        return MovingObstacle("b", t, np.column_stack((0.0 * t, -20.0 + 4.0 * (t - delay))),
                              np.full(len(t), np.pi / 2), 4.5, 1.8)
    assert not keeps_clear_of(east, [north(0.0)], 0.0, margin=0.3)
    assert keeps_clear_of(east, [north(5.0)], 0.0, margin=0.3)
    assert keeps_clear_of(east, [north(-5.0)], 0.0, margin=0.3)
    stop = MovingObstacle("a", t[:9], np.column_stack((-20.0 + 2.5 * t[:9], 0.0 * t[:9])),
                          0.0 * t[:9], 4.5, 1.8)  # stops at x = -10 m at t = 4 s
    late = MovingObstacle("b", t, np.column_stack((-10.0 + 0.0 * t, -40.0 + 4.0 * t)),
                          np.full(len(t), np.pi / 2), 4.5, 1.8)  # at (-10, 0) at t = 10 s
    assert not keeps_clear_of(stop, [late], 0.0, margin=0.3)


def test_plans_that_cross_the_path_are_grown_by_the_pad() -> None:
    """Others' plans before the vehicle in priority: one that crosses the path (or comes
    the other way) is grown by the pad on every side, one alongside it is not (two
    vehicles may drive side by side), one far away or later in priority is left out."""
    from splineplan.closedloop.cooperate import Published, plans_before
    from splineplan.spacetime import MovingObstacle

    t = np.arange(0.0, 10.01, 0.5)
    xy = np.column_stack((np.linspace(-30.0, 30.0, 61), np.zeros(61)))  # the path, east
    h = np.zeros(61)

    def plan(vid: str, x0: float, y0: float, heading: float) -> MovingObstacle:
        return MovingObstacle(vid, t, np.column_stack((x0 + 3.0 * t * math.cos(heading),
                                                       y0 + 3.0 * t * math.sin(heading))),
                              np.full(len(t), heading), 4.5, 1.8)
    board = {"cross": Published(0, plan("cross", 5.0, -15.0, math.pi / 2)),
             "beside": Published(1, plan("beside", -20.0, 3.2, math.radians(10.0))),
             "oncoming": Published(2, plan("oncoming", 20.0, -3.2, math.pi)),
             "far": Published(3, plan("far", 0.0, 60.0, 0.0)),
             "after": Published(9, plan("after", 0.0, 0.0, math.pi / 2))}
    got = {p.id: p for p in plans_before(board, "me", 5, xy, h, 0.0, pad=1.0)}
    assert set(got) == {"cross", "beside", "oncoming"}
    assert (got["cross"].length, got["cross"].width) == (6.5, 3.8)
    assert (got["oncoming"].length, got["oncoming"].width) == (6.5, 3.8)
    assert (got["beside"].length, got["beside"].width) == (4.5, 1.8)


def test_waiting_vehicle_plans_again_when_its_plan_moves_on() -> None:
    """A vehicle that waits for another's plan plans again from shortly before its own
    plan has it move on (the time of the first sample half a metre on), not every second
    before then."""
    from types import SimpleNamespace

    from splineplan.closedloop.replan import _go_time

    waits = SimpleNamespace(t=np.array([0.0, 1.0, 6.0, 7.0, np.inf]),
                            s=np.array([0.0, 0.2, 0.4, 2.0, 3.0]))
    assert _go_time(waits, 100.0) == 107.0
    assert _go_time(SimpleNamespace(t=np.array([0.0, 0.5]), s=np.array([0.0, 0.3])),
                    100.0) == 100.0
