"""Bad input, across the command line and the API: one clear line, never a traceback.

Each CLI case runs ``splineplan.cli.main`` in-process and checks that it exits with status 2,
prints exactly one line on stderr that names the problem (a key phrase), and leaves the
output folder empty or absent (checks come before any work, writing after all of it). A
couple run as a subprocess, to show that no traceback reaches the terminal. The API cases
check the error's class (a :class:`SplineplanError`) and its one-line message.
"""

from __future__ import annotations

import logging
import math
import os
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from conftest import NETS, ROOT

from splineplan.cli import main
from splineplan.corridor import Corridor
from splineplan.errors import (
    GeometryError,
    ParameterError,
    ScenarioError,
    SplineplanError,
    TrajectoryError,
)
from splineplan.obstacles import Obstacles
from splineplan.roadmap import RoadmapParams, plan_roadmap
from splineplan.trajectory import TrajectoryParams, plan_trajectory

CITY = str(NETS / "city.net.xml")
STRAIGHT = str(NETS / "straight.net.xml")
MAP = str(ROOT / "scenarios" / "maps" / "field_d.png")
#: The notice printed once per install while numba compiles: not an error line.
COMPILING = "compiling the planner's inner loops"

#: A scenario that loads (paths relative to the test's folder, where it is written).
GOOD_TOML = f"""
name = "t"
network = "{STRAIGHT}"
[ego]
start_edge = "e0"
goal_edge = "e2"
"""

CR_DATA = ROOT / "tests" / "data" / "commonroad"
CR_URBAN = str(CR_DATA / "ZAM_Urban-3_1.xml")
#: A bundled CommonRoad scenario with its planning problems taken out.
CR_NO_PROBLEM = re.sub(r"<planningProblem .*?</planningProblem>", "",
                       (CR_DATA / "ZAM_Urban-3_1.xml").read_text(), flags=re.S)

#: A bundled CommonRoad scenario whose goal lanelet lies behind the start (on no route).
CR_BEHIND = re.sub(r'<lanelet ref="3604"/>\s*<lanelet ref="3487"/>', '<lanelet ref="3450"/>',
                   (CR_DATA / "USA_Lanker-1_16_T-1.xml").read_text())

#: Files each case may name as ``{tmp}/<name>``.
FILES = {
    "behind.cr.xml": CR_BEHIND,
    "noproblem.cr.xml": CR_NO_PROBLEM,
    "afile": "just a file\n",
    "bad.xml": "this is not XML\n",
    "notimage.png": "not an image either\n",
    "empty.add.xml": "<additional/>\n",
    "badshape.add.xml": '<additional><poly id="p1" shape="0,0 1,x 2,2"/></additional>\n',
    "twopoints.add.xml": '<additional><poly id="p2" shape="0,0 1,1"/></additional>\n',
    "badlane.rou.xml": '<routes><vehicle id="v1" depart="0"><stop lane="nowhere_0" '
                       'endPos="10"/></vehicle></routes>\n',
    "badtype.rou.xml": '<routes><vType id="t" length="long"/><vehicle id="v2" type="t" '
                       'depart="0"><stop lane="e1_0" endPos="10"/></vehicle></routes>\n',
    "badjson/plan.json": "{not json",
    "badmetrics/metrics.json": "[1, 2",
    "emptyrun/readme.txt": "nothing to plot\n",
    "bad.toml": "name = \n",
}


def _toml(**sections: str) -> str:
    """GOOD_TOML with lines added to its sections (``top`` before the first table)."""
    text = GOOD_TOML
    if "top" in sections:
        text = text.replace("[ego]", sections["top"] + "\n[ego]")
    if "ego" in sections:
        text += sections["ego"] + "\n"
    for name in ("sim", "roadmap", "trajectory"):
        if name in sections:
            text += f"[{name}]\n{sections[name]}\n"
    return text


#: Scenario files, each with one mistake.
SCENARIOS = {
    "colour.toml": _toml(top='colour = "red"'),
    "egokey.toml": _toml(ego="speed = 3.0"),
    "spaceship.toml": _toml(ego='vclass = "spaceship"'),
    "twenty.toml": _toml(ego='start_pos = "twenty"'),
    "negpos.toml": _toml(ego="start_pos = -5.0"),
    "lane.toml": _toml(ego="start_lane = 1.5"),
    "d_small.toml": _toml(roadmap="d = 0.001"),
    "d_large.toml": _toml(roadmap="d = 1000.0"),
    "d_nan.toml": _toml(roadmap="d = nan"),
    "dims.toml": _toml(roadmap="vehicle_length = 5.0"),
    "seed_neg.toml": _toml(sim="seed = -1"),
    "seed_bool.toml": _toml(sim="seed = true"),
    "smax_text.toml": _toml(trajectory='s_max = "fast"'),
    "smax_high.toml": _toml(trajectory="s_max = 30.0"),
    "degree.toml": _toml(trajectory="degree = 9"),
    "nonet.toml": GOOD_TOML.replace(STRAIGHT, "missing.net.xml"),
    "noego.toml": GOOD_TOML.split("[ego]")[0],
    "egotable.toml": GOOD_TOML.split("[ego]")[0] + "ego = 3\n",
}

# (arguments, key phrase): {tmp} is the test's folder, {out} an output folder in it that
# must stay empty or absent.
CLI_CASES: list[tuple[list[str], str]] = [
    # top level
    ([], "required: COMMAND"),
    (["fly"], "invalid choice: 'fly'"),
    # route: inputs
    (["route", "{tmp}/missing.net.xml", "a", "b"], "network file not found"),
    (["route", "{tmp}/bad.xml", "a", "b"], "it is not XML"),
    (["route", str(NETS / "city.edg.xml"), "a", "b"], "root element is <edges>"),
    (["route", CITY, "nowhere", "G1G2"], "edge 'nowhere' is not in network"),
    (["route", CITY, "SWA0", "G1G2", "--vclass", "spaceship"],
     "unknown vehicle class 'spaceship'"),
    (["route", CITY, "SWA0", "G1G2", "--avoid", "SWA0"], "origin edge 'SWA0' is to be avoided"),
    (["route", CITY, "SWA0", "G1G2", "--start-pos", "nan"], "--start-pos: must be a finite"),
    (["route", CITY, "SWA0", "G1G2", "--start-pos", "-inf"], "--start-pos: must be a finite"),
    (["route", CITY, "SWA0", "G1G2", "--weight", "fuel"], "invalid choice: 'fuel'"),
    # route: the picture
    (["route", CITY, "SWA0", "G1G2", "--plot", "{out}/route"], "no picture extension"),
    (["route", CITY, "SWA0", "G1G2", "--plot", "{out}/route.xyz"], "unknown picture format"),
    (["route", CITY, "SWA0", "G1G2", "--plot", "{tmp}"], "is a folder; give a picture file"),
    (["route", CITY, "SWA0", "G1G2", "--plot", "{tmp}/afile/route.png"],
     "afile is a file, not a folder"),
    # plan: outputs, checked before planning
    (["plan", STRAIGHT, "e0", "e2", "--out", "{tmp}/afile"], "--out {tmp}/afile is a file"),
    (["plan", STRAIGHT, "e0", "e2", "--out", "{tmp}/afile/sub"], "afile is a file, not a"),
    (["plan", STRAIGHT, "e0", "e2", "--out", "{out}", "--plot", "{out}/p.gif2"],
     "unknown picture format '.gif2'"),
    # plan: numbers
    (["plan", STRAIGHT, "e0", "e2", "--out", "{out}", "--d", "0.001"],
     "--d: the sweep-line spacing must be between 0.1 and 10 m"),
    (["plan", STRAIGHT, "e0", "e2", "--out", "{out}", "--d", "1000"],
     "--d: the sweep-line spacing must be between 0.1 and 10 m"),
    (["plan", STRAIGHT, "e0", "e2", "--out", "{out}", "--d", "-1"], "--d: the sweep-line"),
    (["plan", STRAIGHT, "e0", "e2", "--out", "{out}", "--d", "nan"], "--d: must be a finite"),
    (["plan", STRAIGHT, "e0", "e2", "--out", "{out}", "--s-max", "0"], "--s-max: must be pos"),
    (["plan", STRAIGHT, "e0", "e2", "--out", "{out}", "--s-max", "-5"], "--s-max: must be pos"),
    (["plan", STRAIGHT, "e0", "e2", "--out", "{out}", "--s-max", "inf"], "--s-max: must be a f"),
    (["plan", STRAIGHT, "e0", "e2", "--out", "{out}", "--s-max", "fast"],
     "--s-max: must be a number, got 'fast'"),
    (["plan", STRAIGHT, "e0", "e2", "--out", "{out}", "--start-pos", "-1"],
     "--start-pos: must be >= 0"),
    # plan: inputs
    (["plan", "{tmp}/missing.net.xml", "e0", "e2", "--out", "{out}"], "network file not found"),
    (["plan", STRAIGHT, "e0", "nowhere", "--out", "{out}"], "edge 'nowhere' is not in network"),
    (["plan", STRAIGHT, "e0", "e2", "--out", "{out}", "--obstacles", "{tmp}/none.xml"],
     "obstacle file not found"),
    (["plan", STRAIGHT, "e0", "e2", "--out", "{out}", "--obstacles", STRAIGHT],
     "is a SUMO network, not an additional or route file"),
    (["plan", STRAIGHT, "e0", "e2", "--out", "{out}", "--obstacles", "{tmp}/bad.xml"],
     "cannot read obstacle file"),
    (["plan", STRAIGHT, "e0", "e2", "--out", "{out}", "--obstacles", "{tmp}/badshape.add.xml"],
     "badshape.add.xml: polygon 'p1' has a bad shape"),
    (["plan", STRAIGHT, "e0", "e2", "--out", "{out}", "--obstacles",
      "{tmp}/twopoints.add.xml"], "twopoints.add.xml: obstacle 'p2' needs at least 3 vertices"),
    (["plan", STRAIGHT, "e0", "e2", "--out", "{out}", "--obstacles", "{tmp}/badlane.rou.xml"],
     "vehicle 'v1' stops on unknown lane 'nowhere_0'"),
    (["plan", STRAIGHT, "e0", "e2", "--out", "{out}", "--obstacles", "{tmp}/badtype.rou.xml"],
     "vehicle 'v2''s vType: length must be a number, got 'long'"),
    # plan-image
    (["plan-image", MAP, "--out", "{out}"], "required: --scale"),
    (["plan-image", MAP, "--out", "{out}", "--scale", "0"], "--scale: must be positive"),
    (["plan-image", MAP, "--out", "{out}", "--scale", "-0.25"], "--scale: must be positive"),
    (["plan-image", MAP, "--out", "{out}", "--scale", "nan"], "--scale: must be a finite"),
    (["plan-image", MAP, "--out", "{out}", "--scale", "1e6"],
     "--scale 1e+06 m per pixel makes the 400-pixel-wide map 4e+05 km long"),
    (["plan-image", MAP, "--out", "{out}", "--scale", ".25", "--threshold", "1.5"],
     "--threshold: must lie between 0 and 1"),
    (["plan-image", MAP, "--out", "{out}", "--scale", ".25", "--threshold", "0"],
     "--threshold: must lie between 0 and 1"),
    (["plan-image", MAP, "--out", "{out}", "--scale", ".25", "--merge-tolerance", "-1"],
     "--merge-tolerance: must be an integer >= 0"),
    (["plan-image", MAP, "--out", "{out}", "--scale", ".25", "--start", "abc"],
     "--start: expected X,Y in metres"),
    (["plan-image", MAP, "--out", "{out}", "--scale", ".25", "--start", "1,2,3"],
     "--start: expected X,Y in metres"),
    (["plan-image", MAP, "--out", "{out}", "--scale", ".25", "--goal", "nan,3"],
     "--goal: expected X,Y in metres (two finite numbers)"),
    (["plan-image", MAP, "--out", "{out}", "--scale", ".25", "--start", "1000,3"],
     "lies outside the map"),
    (["plan-image", MAP, "--out", "{out}", "--scale", ".25", "--goal", "1,10"],
     "it must lie at least 1 m ahead"),
    (["plan-image", "{tmp}/nomap.png", "--out", "{out}", "--scale", ".25"], "not found"),
    (["plan-image", "{tmp}/notimage.png", "--out", "{out}", "--scale", ".25"],
     "is not a readable image"),
    (["plan-image", MAP, "--out", "{tmp}/afile", "--scale", ".25"], "--out {tmp}/afile is a"),
    # simulate: arguments and scenario files (all refused before SUMO starts)
    (["simulate", "{tmp}/colour.toml", "--seed", "-1", "--out", "{out}"],
     "--seed: must be an integer in 0..2147483647"),
    (["simulate", "{tmp}/colour.toml", "--seed", "x", "--out", "{out}"],
     "--seed: must be an integer, got 'x'"),
    (["simulate", "{tmp}/colour.toml", "--out", "{tmp}/afile"], "--out {tmp}/afile is a file"),
    (["simulate", "{tmp}/none.toml", "--out", "{out}"], "scenario file not found"),
    (["simulate", "{tmp}/bad.toml", "--out", "{out}"], "not valid TOML"),
    (["simulate", "{tmp}/colour.toml", "--out", "{out}"], "unknown key 'colour'"),
    (["simulate", "{tmp}/egokey.toml", "--out", "{out}"], "unknown key [ego] 'speed'"),
    (["simulate", "{tmp}/spaceship.toml", "--out", "{out}"],
     "ego.vclass: unknown vehicle class 'spaceship'; SUMO's classes are e.g. passenger"),
    (["simulate", "{tmp}/twenty.toml", "--out", "{out}"],
     "ego.start_pos must be a number, got 'twenty'"),
    (["simulate", "{tmp}/negpos.toml", "--out", "{out}"], "ego.start_pos must be >= 0"),
    (["simulate", "{tmp}/lane.toml", "--out", "{out}"], "ego.start_lane must be an integer"),
    (["simulate", "{tmp}/d_small.toml", "--out", "{out}"],
     "[roadmap] d, the sweep-line spacing, must be between 0.1 and 10 m"),
    (["simulate", "{tmp}/d_large.toml", "--out", "{out}"],
     "RoadmapParams.d (1000 m) must be at most half of RoadmapParams.segment_length"),
    (["simulate", "{tmp}/d_nan.toml", "--out", "{out}"], "d must be a finite number, got nan"),
    (["simulate", "{tmp}/dims.toml", "--out", "{out}"], "roadmap.vehicle_length comes from"),
    (["simulate", "{tmp}/seed_neg.toml", "--out", "{out}"], "sim.seed must be an integer in"),
    (["simulate", "{tmp}/seed_bool.toml", "--out", "{out}"], "sim.seed must be an integer in"),
    (["simulate", "{tmp}/smax_text.toml", "--out", "{out}"],
     "s_max must be a number, got 'fast'"),
    (["simulate", "{tmp}/smax_high.toml", "--out", "{out}"], "exceeds ego.max_speed"),
    (["simulate", "{tmp}/degree.toml", "--out", "{out}"], "degree must be an integer in 2..5"),
    (["simulate", "{tmp}/nonet.toml", "--out", "{out}"], "network file not found"),
    (["simulate", "{tmp}/noego.toml", "--out", "{out}"], "missing key 'ego'"),
    (["simulate", "{tmp}/egotable.toml", "--out", "{out}"], "[ego] must be a table"),
    # plot
    (["plot", "{tmp}/norun"], "RUN_DIR {tmp}/norun not found"),
    (["plot", "{tmp}/afile"], "RUN_DIR {tmp}/afile is a file"),
    (["plot", "{tmp}/emptyrun", "--out", "{out}"], "holds neither plan.json nor metrics.json"),
    (["plot", "{tmp}/badjson", "--out", "{out}"], "plan.json is not readable JSON"),
    (["plot", "{tmp}/badmetrics", "--out", "{out}"], "metrics.json is not readable JSON"),
    (["plot", "{tmp}/emptyrun", "--out", "{tmp}/afile"], "--out {tmp}/afile is a file"),
    (["plot", "{tmp}/emptyrun", "--format", "gif"], "invalid choice: 'gif'"),
    # bench: arguments only (no case runs)
    (["bench", "--seeds", "0", "--out", "{out}"], "--seeds: must be an integer >= 1"),
    (["bench", "--workers", "-2", "--out", "{out}"], "--workers: must be an integer >= 1"),
    (["bench", "--drivers", "robot", "--out", "{out}"], "--drivers: invalid choice: 'robot'"),
    (["bench", "--out", "{tmp}/afile"], "--out {tmp}/afile is a file"),
    (["bench", "nosuite", "--out", "{out}"], "unknown suite 'nosuite'"),
    # commonroad (checked before any planning)
    (["commonroad", "{tmp}/none.xml", "--out", "{out}"], "scenario file not found"),
    (["commonroad", STRAIGHT, "--out", "{out}"],
     "straight.net.xml is not a CommonRoad scenario (no <commonRoad> root element)"),
    (["commonroad", "{tmp}/noproblem.cr.xml", "--out", "{out}"],
     "noproblem.cr.xml holds no planning problem: nothing to solve"),
    (["commonroad", "{tmp}/behind.cr.xml", "--out", "{out}"],
     "behind.cr.xml: no lanelet route from lanelet 3604 to goal lanelet 3450"),
    (["commonroad", CR_URBAN, "--out", "{out}", "--vehicle-type", "7"],
     "unknown vehicle type 7; CommonRoad's are 1 (FORD_ESCORT), 2 (BMW_320i), 3 (VW_VANAGON)"),
    (["commonroad", CR_URBAN, "--out", "{out}", "--planning-problem", "5"],
     "ZAM_Urban-3_1.xml has no planning problem 5 (it has 11)"),
    (["commonroad", CR_URBAN, "--out", "{tmp}/afile"], "--out {tmp}/afile is a file"),
]


def _write_inputs(tmp: Path) -> None:
    for name, text in {**FILES, **SCENARIOS}.items():
        p = tmp / name
        p.parent.mkdir(parents=True, exist_ok=True)
        p.write_text(text)


def _run(argv: list[str]) -> int:
    """``main(argv)``'s exit status, whether it returns it or argparse raises it."""
    try:
        return main(argv)
    except SystemExit as exit_:
        return int(exit_.code or 0)


def _error_lines(err: str) -> list[str]:
    return [ln for ln in err.strip().splitlines() if COMPILING not in ln]


@pytest.mark.parametrize(("args", "phrase"), CLI_CASES,
                         ids=[f"{i:02d}-{' '.join(a[:1])}-{p[:30]}"
                              for i, (a, p) in enumerate(CLI_CASES)])
def test_cli_bad_input(args: list[str], phrase: str, tmp_path: Path,
                       capsys: pytest.CaptureFixture[str]) -> None:
    _write_inputs(tmp_path)
    out = tmp_path / "out"
    argv = [a.format(tmp=tmp_path, out=out) for a in args]
    code = _run(argv)
    captured = capsys.readouterr()
    lines = _error_lines(captured.err)
    assert code == 2, captured
    assert "Traceback" not in captured.err
    assert len(lines) == 1, captured.err
    assert ": error: " in lines[0] and lines[0].startswith("splineplan")
    assert phrase.format(tmp=tmp_path) in lines[0]
    assert not out.exists() or not any(out.iterdir()), sorted(out.rglob("*"))


def test_cli_cases_are_many_and_distinct() -> None:
    """The table covers at least 40 kinds of bad input, none twice."""
    keys = [(tuple(a), p) for a, p in CLI_CASES]
    assert len(set(keys)) == len(keys) >= 40


@pytest.mark.parametrize(("args", "phrase"), [
    (["plan", STRAIGHT, "e0", "e2", "--out", "{tmp}/afile"], "is a file, not a folder"),
    (["simulate", "{tmp}/spaceship.toml", "--out", "{tmp}/out"], "unknown vehicle class"),
])
def test_no_traceback_reaches_the_terminal(args: list[str], phrase: str,
                                           tmp_path: Path) -> None:
    """As a user runs it: a separate process, its stderr as the terminal shows it."""
    _write_inputs(tmp_path)
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    proc = subprocess.run([sys.executable, "-m", "splineplan.cli",
                           *(a.format(tmp=tmp_path) for a in args)],
                          capture_output=True, text=True, cwd=tmp_path, env=env, timeout=120)
    lines = _error_lines(proc.stderr)
    assert proc.returncode == 2
    assert "Traceback" not in proc.stderr
    assert len(lines) == 1 and phrase in lines[0], proc.stderr
    assert proc.stdout == ""


def test_route_takes_verbose_after_the_command(capsys: pytest.CaptureFixture[str]) -> None:
    """``route -v NET A B`` is ``-v route NET A B``: -v stays an option, while an edge id
    with a leading minus stays an edge id."""
    assert _run(["route", "-v", CITY, "SWA0", "G1G2"]) == 0
    assert "length:" in capsys.readouterr().out
    assert _run(["route", "-vv", CITY, "-SWA0", "G1G2"]) == 2
    assert "edge '-SWA0' is not in network" in capsys.readouterr().err


def test_route_plot_makes_missing_folders(tmp_path: Path,
                                          capsys: pytest.CaptureFixture[str]) -> None:
    png = tmp_path / "new" / "deeper" / "route.png"
    assert _run(["route", CITY, "SWA0", "G1G2", "--plot", str(png)]) == 0
    assert png.read_bytes()[:4] == b"\x89PNG"
    assert f"picture: {png}" in capsys.readouterr().out


def test_plan_counts_obstacles_and_replaces_its_old_outputs(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """An obstacle file that holds none is a warning (the plan still runs), the count is
    printed; a reused folder loses the earlier plan's pictures but keeps other files."""
    _write_inputs(tmp_path)
    out = tmp_path / "out"
    out.mkdir()
    (out / "roadmap.png").write_bytes(b"stale")
    (out / "notes.txt").write_text("mine")
    assert _run(["plan", STRAIGHT, "e0", "e2", "--out", str(out), "--obstacles",
                 str(tmp_path / "empty.add.xml")]) == 0
    captured = capsys.readouterr()
    assert "obstacles: 0 read from" in captured.out
    warn = [ln for ln in _error_lines(captured.err) if "warning" in ln]
    assert len(warn) == 1 and "holds no obstacles" in warn[0]
    assert sorted(p.name for p in out.iterdir()) == ["notes.txt", "plan.json",
                                                     "trajectory.csv"]


# ---- the API ----------------------------------------------------------------------------
def _road() -> Corridor:
    return Corridor.from_boundaries(left=[[0, 4.8], [60, 4.8]], right=[[0, -4.8], [60, -4.8]])


@pytest.fixture(scope="module")
def roadmap() -> tuple[Corridor, object]:
    road = _road()
    return road, plan_roadmap(road, None, start_xy=[1.0, -2.0])


def _one_line(err: pytest.ExceptionInfo[SplineplanError], phrase: str) -> None:
    text = str(err.value)
    assert isinstance(err.value, SplineplanError)
    assert "\n" not in text and phrase in text, text


@pytest.mark.parametrize(("speed", "phrase"), [
    (100.0, "start_speed 100.00 m/s exceeds TrajectoryParams.s_max (13.89 m/s)"),
    (-1.0, "start_speed must be >= 0 m/s"),
    (math.nan, "start_speed must be >= 0 m/s"),
    ("fast", "start_speed must be a number"),
])
def test_start_speed_out_of_range_is_refused(roadmap: tuple[Corridor, object], speed: object,
                                             phrase: str) -> None:
    road, rm = roadmap
    with pytest.raises(TrajectoryError) as err:
        plan_trajectory(rm, road, None, start_speed=speed)  # type: ignore[arg-type]
    _one_line(err, phrase)


def test_start_speed_at_s_max_and_no_obstacles_plan(roadmap: tuple[Corridor, object]) -> None:
    """None is no obstacles (as in plan_roadmap and pipeline.plan); a start at s_max itself
    is allowed and the profile starts there."""
    road, rm = roadmap
    tr = plan_trajectory(rm, road, None, start_heading=0.0, start_speed=13.89)
    assert tr.feasible and tr.speed[0] == pytest.approx(13.89)


def test_start_inside_an_obstacle_is_logged(caplog: pytest.LogCaptureFixture) -> None:
    road = _road()
    car = Obstacles.from_boxes([[20.0, 0.0]], headings=[0.0], lengths=4.5, widths=1.8,
                               ids=["parked"])
    with caplog.at_level(logging.WARNING, logger="splineplan.roadmap"):
        rm = plan_roadmap(road, car, start_xy=[20.0, 0.0])
    msgs = [r.getMessage() for r in caplog.records if r.levelno == logging.WARNING]
    assert len(msgs) == 1 and "inside obstacle 'parked'" in msgs[0]
    # the roadmap starts off the obstacle, as far from the start as the message says
    moved = float(np.hypot(*(rm.xy[0] - [20.0, 0.0])))
    assert moved > 0.9 and f"{moved:.2f} m away" in msgs[0]


@pytest.mark.parametrize(("left", "right", "phrase"), [
    ([[0, -3], [50, -3]], [[0, 3], [50, 3]], "left and right sides are swapped"),
    ([[0, 3], [50, -3]], [[0, -3], [50, 3]], "left and right sides cross at station 2"),
])
def test_corridor_sides_swapped_or_crossing(left: list[list[float]], right: list[list[float]],
                                            phrase: str) -> None:
    with pytest.raises(GeometryError) as err:
        Corridor.from_boundaries(left=left, right=right)
    _one_line(err, phrase)


@pytest.mark.parametrize(("make", "error", "phrase"), [
    (lambda: RoadmapParams(d=200.0), ParameterError,
     "RoadmapParams.d (200 m) must be at most half of RoadmapParams.segment_length (300 m)"),
    (lambda: RoadmapParams(d="1"), ParameterError, "RoadmapParams.d must be a number, got '1'"),
    (lambda: TrajectoryParams(s_max=math.inf), ParameterError,
     "TrajectoryParams.s_max must be a finite number, got inf"),
    (lambda: Obstacles.from_polygons([[[0, 0], [1, 1]]], ids=["kerb"]), GeometryError,
     "obstacle 'kerb' needs at least 3 vertices"),
    (lambda: Obstacles.from_polygons([[[0, 0], [1, "x"], [2, 0]]], ids=["k2"]), GeometryError,
     "obstacle 'k2' is not an array of numbers"),
])
def test_api_values_are_named(make: object, error: type[SplineplanError], phrase: str) -> None:
    with pytest.raises(error) as err:
        make()  # type: ignore[operator]
    _one_line(err, phrase)


def test_scenario_errors_name_the_file(tmp_path: Path) -> None:
    from splineplan.scenario import load_scenario

    _write_inputs(tmp_path)
    with pytest.raises(ScenarioError) as err:
        load_scenario(tmp_path / "twenty.toml")
    _one_line(err, f"{tmp_path / 'twenty.toml'}: [ego] ego.start_pos must be a number")


def test_simulate_replaces_its_old_outputs(tmp_path: Path,
                                           capsys: pytest.CaptureFixture[str]) -> None:
    """A reused run folder loses the pictures of an earlier run (they would sit beside the
    new run's as if they were its own), keeps other files, and gets the new run's status."""
    scenario = tmp_path / "nowhere.toml"
    scenario.write_text(GOOD_TOML.replace('goal_edge = "e2"', 'goal_edge = "nowhere"'))
    out = tmp_path / "run"
    (out / "plans").mkdir(parents=True)
    stale = out / "plans" / "plan_000_t00000.0.png"
    stale.write_bytes(b"stale")
    (out / "route.png").write_bytes(b"stale")
    (out / "notes.txt").write_text("mine")
    assert _run(["simulate", str(scenario), "--out", str(out), "--no-progress"]) == 2
    assert "edge 'nowhere'" in capsys.readouterr().err
    assert not stale.exists() and not (out / "route.png").exists()
    assert (out / "notes.txt").read_text() == "mine"
    assert '"failed"' in (out / "metrics.json").read_text()
