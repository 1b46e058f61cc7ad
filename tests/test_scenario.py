"""Tests of scenario files: the bundled ones load; unknown keys and missing files are errors."""

from __future__ import annotations

import tomllib
from pathlib import Path

import pytest
from conftest import ROOT

from splineplan.errors import ScenarioError
from splineplan.scenario import EgoSpec, Scenario, load_scenario, scenario_from_dict

SCENARIOS = ROOT / "scenarios"
BUNDLED = sorted(p for p in SCENARIOS.glob("*.toml") if p.stem != "monaco")
PAPER = {"city", "empty_road", "one_obstacle", "obstacle_field_c", "obstacle_field_d"}
BEYOND = {"moving_traffic", "blocked_road", "appearing_obstacle", "monaco"}


def _minimal(tmp_path: Path, extra: str = "") -> Path:
    p = tmp_path / "s.toml"
    p.write_text(f'network = "{ROOT / "sumo_nets" / "straight.net.xml"}"\n'
                 '[ego]\nstart_edge = "e0"\ngoal_edge = "e2"\n' + extra)
    return p


def test_every_experiment_is_bundled() -> None:
    names = {p.stem for p in SCENARIOS.glob("*.toml")}
    assert names >= PAPER | BEYOND


@pytest.mark.parametrize("path", BUNDLED, ids=lambda p: p.stem)
def test_bundled_scenarios_load(path: Path) -> None:
    sc = load_scenario(path)
    assert isinstance(sc, Scenario) and sc.name == path.stem
    assert sc.network.is_file() and all(p.is_file() for p in (*sc.routes, *sc.additional))
    # the ego's size is the planner's, and the speed limit caps level 3
    assert sc.roadmap.vehicle_length == sc.ego.length
    assert sc.roadmap.vehicle_width == sc.ego.width
    assert sc.trajectory.s_max <= sc.ego.max_speed
    raw = tomllib.loads(path.read_text())
    assert sc.sim.seed == raw["sim"]["seed"]


def test_monaco_scenario(monaco_net: Path) -> None:
    sc = load_scenario(SCENARIOS / "monaco.toml")
    assert sc.network.resolve() == monaco_net.resolve()


def test_defaults_and_values(tmp_path: Path) -> None:
    sc = load_scenario(_minimal(tmp_path, "length = 5\nwidth = 2\nmax_speed = 10\n"
                                          "[sim]\nseed = 9\nduration = 30\n"
                                          "[roadmap]\nd = 0.5\n"))
    assert sc.ego == EgoSpec("e0", "e2", length=5.0, width=2.0, max_speed=10.0)
    assert sc.sim.seed == 9 and sc.sim.duration == 30.0 and isinstance(sc.sim.duration, float)
    assert sc.roadmap.d == 0.5 and sc.roadmap.vehicle_width == 2.0
    assert sc.trajectory.s_max == 10.0  # from the ego's max speed
    assert sc.with_seed(4).sim.seed == 4 and sc.sim.seed == 9


@pytest.mark.parametrize(("extra", "needle"), [
    ("colour = 1\n", "'colour'"),
    ("[ego.extra]\n", "[ego] 'extra'"),
    ("[sim]\nstep = 0.1\n", "[sim] 'step'"),
    ("[roadmap]\nsegment = 3\n", "[roadmap] 'segment'"),
    ("[trajectory]\nvmax = 3\n", "[trajectory] 'vmax'"),
])
def test_unknown_key_is_named(tmp_path: Path, extra: str, needle: str) -> None:
    # top-level keys must come before the [ego] table in TOML: put them first
    p = tmp_path / "s.toml"
    base = _minimal(tmp_path).read_text()
    p.write_text(extra + base if not extra.startswith("[") else base + extra)
    with pytest.raises(ScenarioError, match="unknown key") as info:
        load_scenario(p)
    assert needle in str(info.value)


def test_missing_files_are_named(tmp_path: Path) -> None:
    with pytest.raises(ScenarioError, match="not found"):
        load_scenario(tmp_path / "nope.toml")
    p = tmp_path / "s.toml"
    p.write_text('network = "missing.net.xml"\n[ego]\nstart_edge = "a"\ngoal_edge = "b"\n')
    with pytest.raises(ScenarioError, match=r"missing\.net\.xml"):
        load_scenario(p)
    p.write_text(f'network = "{ROOT / "sumo_nets" / "straight.net.xml"}"\n'
                 'routes = ["traffic.rou.xml"]\n[ego]\nstart_edge = "a"\ngoal_edge = "b"\n')
    with pytest.raises(ScenarioError, match=r"routes file not found: .*traffic\.rou\.xml"):
        load_scenario(p)


@pytest.mark.parametrize(("extra", "needle"), [
    ("length = -1\n", "ego.length"),
    ("start_lane = -2\n", "start_lane"),
    ("[roadmap]\nvehicle_width = 2.0\n", "comes from [ego]"),
    ("[roadmap]\nd = 0\n", "RoadmapParams.d"),
    ("[trajectory]\ns_max = 40\n", "exceeds"),
    ("[sim]\nreplan_distance = 500\n", "replan_distance"),
    ("[sim]\nseed = 1.5\n", "seed"),
])
def test_bad_values(tmp_path: Path, extra: str, needle: str) -> None:
    with pytest.raises(ScenarioError, match=r"s\.toml") as info:
        load_scenario(_minimal(tmp_path, extra))
    assert needle in str(info.value)


def test_malformed_toml_and_missing_keys(tmp_path: Path) -> None:
    p = tmp_path / "s.toml"
    p.write_text("network = \n")
    with pytest.raises(ScenarioError, match="not valid TOML"):
        load_scenario(p)
    with pytest.raises(ScenarioError, match="missing key 'ego'"):
        scenario_from_dict({"network": str(ROOT / "sumo_nets" / "straight.net.xml")})
