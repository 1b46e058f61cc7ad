"""SUMO's SSM device (surrogate safety measures) in a run: every run folder has SUMO's
``ssm.xml``, and the run's summary (metrics) its minimum TTC beside ours."""

from __future__ import annotations

import csv
import json
import math
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest
import sumolib
from conftest import NETS, ROOT

from splineplan.scenario import load_scenario
from splineplan.sim import simulate
from splineplan.sumo.ssm import COLLISION_TYPE, THRESHOLDS, read_ssm

SCENARIOS = ROOT / "scenarios"


def _conflicts(path: Path) -> list[ET.Element]:
    root = ET.parse(path).getroot()  # complete XML, in SUMO's format
    assert root.tag == "SSMLog"
    return root.findall("conflict")


def _speeds(path: Path) -> dict[float, float]:
    with path.open() as fh:
        return {round(float(r["t"]), 1): float(r["speed"]) for r in csv.DictReader(fh)}


def test_crossing_sumo_ttc_agrees_with_ours(tmp_path: Path) -> None:
    """Two planned vehicles cross at a junction of the grid, the second yielding to the
    first: SUMO's SSM device (every vehicle equipped) logs the encounter from both sides,
    counted once, and its smallest TTC, for the same pair, is ours within what the two
    definitions' geometry allows."""
    p = tmp_path / "cross.toml"
    p.write_text(f'network = "{NETS / "grid.net.xml"}"\n'
                 '[[ego]]\nid = "a"\nstart_edge = "A1B1"\nstart_pos = 35.0\n'
                 'goal_edge = "B1C1"\n'
                 '[[ego]]\nid = "b"\nstart_edge = "B0B1"\nstart_pos = 30.0\n'
                 'goal_edge = "B1B2"\n[sim]\nduration = 60\nseed = 1\n')
    sc = load_scenario(p)
    out = tmp_path / "out"
    r = simulate(sc, out_dir=out, progress=False)
    assert r.arrived, r.reason
    logged = _conflicts(out / "ssm.xml")
    assert {(c.get("ego"), c.get("foe")) for c in logged} == {("a", "b"), ("b", "a")}
    pairs = json.loads((out / "summary.json").read_text())["pairs"]
    assert pairs["sumo_ssm_conflicts"] == 1
    sumo, ours = pairs["sumo_ssm_min_ttc"], pairs["min_ttc"]
    assert sumo is not None and ours is not None
    assert sumo["pair"] == ours["pair"] == ["a", "b"]
    assert pairs["sumo_ssm_min_ttc_planned"] == sumo
    assert math.isfinite(sumo["value"]) and sumo["value"] >= 0.0
    assert pairs["sumo_ssm_threshold_conflicts"]["TTC"] == int(
        sumo["value"] < THRESHOLDS["TTC"])
    # SUMO's TTC is the time until both vehicles are in the conflict area around the
    # crossing of their lanes' centre lines, ours until the footprints touch: a car lies
    # up to (lane width - car width) / 2 beside its lane's centre, which moves where the
    # two touch by that much along each one's way; each figure is found to 0.1 s (ours in
    # steps of 0.1 s, and the two minima may fall one step apart)
    lane = sumolib.net.readNet(str(NETS / "grid.net.xml")).getEdge("A1B1").getLane(0)
    off = (lane.getWidth() - sc.ego.width) / 2.0
    t = round(sumo["time"], 1)
    v = [_speeds(out / vid / "trajectory.csv")[t] for vid in ("a", "b")]
    assert min(v) > 1.0, v  # both drive towards the crossing then
    margin = off / v[0] + off / v[1] + 2 * sc.sim.step_length
    assert abs(sumo["value"] - ours["value"]) <= margin, (sumo, ours, margin)


def test_no_encounter_reports_none(tmp_path: Path) -> None:
    """Two planned vehicles side by side in the two lanes of a road, driving the same way:
    no conflict for SUMO (an empty log) nor a time-to-collision for us."""
    r = simulate(load_scenario(SCENARIOS / "two_side_by_side.toml"), out_dir=tmp_path,
                 progress=False)
    assert r.arrived, r.reason
    assert _conflicts(tmp_path / "ssm.xml") == []
    pairs = json.loads((tmp_path / "summary.json").read_text())["pairs"]
    assert pairs["sumo_ssm_conflicts"] == 0 and pairs["sumo_ssm_collisions"] == 0
    assert pairs["sumo_ssm_min_ttc"] is None and pairs["sumo_ssm_max_drac"] is None
    assert pairs["min_ttc"] is None
    assert pairs["min_gap_between_planned"] is not None  # they were near each other


def test_single_ego_equips_the_ego_only(tmp_path: Path) -> None:
    """A single ego passing a stopped car: ``ssm.xml`` holds the ego's conflicts only (its
    device alone), and ``metrics.json`` SUMO's figures of them."""
    simulate(load_scenario(SCENARIOS / "one_obstacle.toml"), out_dir=tmp_path,
             progress=False)
    logged = _conflicts(tmp_path / "ssm.xml")
    assert logged and all(c.get("ego") == "ego" for c in logged)
    m = json.loads((tmp_path / "metrics.json").read_text())
    assert m["sumo_ssm_conflicts"] == len(logged)
    ttc = m["sumo_ssm_min_ttc"]
    assert ttc["pair"] == ["ego", "obstacle0"] and 0.0 <= ttc["value"] < THRESHOLDS["TTC"]


_LOG = """<?xml version="1.0" encoding="UTF-8"?>
<SSMLog>
    <conflict begin="1.00" end="9.00" ego="b" foe="a">
        <minTTC time="4.00" position="1.00,2.00" type="11" value="1.50" speed="9.00"/>
        <maxDRAC time="3.00" position="1.00,2.00" type="11" value="2.00" speed="9.00"/>
        <PET time="NA" position="NA" type="NA" value="NA" speed="NA"/>
    </conflict>
    <conflict begin="1.00" end="12.00" ego="a" foe="b">
        <minTTC time="4.10" position="1.00,2.00" type="10" value="1.60" speed="13.00"/>
        <maxDRAC time="3.00" position="1.00,2.00" type="10" value="3.50" speed="13.00"/>
        <PET time="7.00" position="1.00,2.00" type="17" value="1.20" speed="13.00"/>
    </conflict>
    <conflict begin="20.00" end="30.00" ego="a" foe="b">
        <minTTC time="22.00" position="5.00,2.00" type="2" value="2.50" speed="10.00"/>
        <maxDRAC time="NA" position="NA" type="NA" value="NA" speed="NA"/>
        <PET time="NA" position="NA" type="NA" value="NA" speed="NA"/>
    </conflict>
    <conflict begin="5.00" end="8.00" ego="c" foe="d">
        <minTTC time="6.00" position="9.00,9.00" type="111" value="0.00" speed="3.00"/>
        <maxDRAC time="6.00" position="9.00,9.00" type="3" value="4.00" speed="3.00"/>
        <PET time="NA" position="NA" type="NA" value="NA" speed="NA"/>
    </conflict>
</SSMLog>
"""


def test_read_ssm_counts_each_encounter_once(tmp_path: Path) -> None:
    """An encounter both devices logged is one conflict with the worse of each measure; a
    later encounter of the same pair is another; NA is no value."""
    path = tmp_path / "ssm.xml"
    path.write_text(_LOG)
    s = read_ssm(path, planned=["a"])
    assert s["sumo_ssm_conflicts"] == 3
    assert s["sumo_ssm_min_ttc"] == {"value": 0.0, "time": 6.0, "pair": ["c", "d"],
                                     "type": COLLISION_TYPE, "position": [9.0, 9.0]}
    assert s["sumo_ssm_min_ttc_planned"]["value"] == pytest.approx(1.5)
    assert s["sumo_ssm_min_ttc_planned"]["pair"] == ["a", "b"]
    assert s["sumo_ssm_max_drac"]["value"] == pytest.approx(4.0)
    assert s["sumo_ssm_min_pet"]["value"] == pytest.approx(1.2)
    # TTC below 3 s: all three; DRAC above 3 m/s^2: the merged one (3.5) and c-d (4.0)
    assert s["sumo_ssm_threshold_conflicts"] == {"TTC": 3, "DRAC": 2, "PET": 1}
    assert s["sumo_ssm_collisions"] == 1
