"""Penetration sweep: one SUMO scenario at several shares of planned vehicles, one process
per run, figures per share; and its bad input."""

from __future__ import annotations

import csv
import json
import subprocess
import sys
from pathlib import Path

import pytest
from conftest import NETS

from splineplan import sweep
from splineplan.errors import ParameterError

#: Departures of the small scenario: cars every 8 s on the grid's straight line.
CARS = 5


def _scenario(tmp: Path) -> Path:
    """SUMO's own scenario: a flow of cars across the grid, 60 s."""
    (tmp / "cars.rou.xml").write_text(
        '<routes>\n  <vType id="car" vClass="passenger" length="4.5" width="1.8"/>\n'
        '  <route id="r" edges="A1B1 B1C1"/>\n'
        f'  <flow id="f" type="car" route="r" begin="0" period="8" number="{CARS}" '
        'departSpeed="max" departPos="10"/>\n</routes>\n')
    cfg = tmp / "cars.sumocfg"
    cfg.write_text(f'<configuration>\n  <input>\n    <net-file value="{NETS / "grid.net.xml"}"/>'
                   '\n    <route-files value="cars.rou.xml"/>\n  </input>\n  <time>\n'
                   '    <begin value="0"/>\n    <end value="90"/>\n  </time>\n'
                   '</configuration>\n')
    return cfg


@pytest.fixture(scope="module")
def swept(tmp_path_factory: pytest.TempPathFactory) -> tuple[sweep.SweepResult, Path]:
    tmp = tmp_path_factory.mktemp("sweep")
    points = sweep.build_sweep(_scenario(tmp), shares=(0.0, 1.0), seeds=1)
    return sweep.run_sweep(points, out_dir=tmp / "out", workers=2, progress=False), tmp / "out"


def test_a_sweep_runs_each_share_and_compares_the_traffic(
        swept: tuple[sweep.SweepResult, Path]) -> None:
    res, out = swept
    assert [r["share"] for r in res.rows] == [0.0, 1.0]
    none, every = res.rows
    assert not none["error"] and not every["error"], (none["error"], every["error"])
    # the same demand either way: every car makes its trip, planned or not
    assert none["vehicles"] == every["vehicles"] == CARS
    assert none["planned"] == 0 and every["planned"] == CARS
    assert every["planned_arrived"] == CARS and every["collisions"] == 0
    assert none["mean_travel_time"] > 0 and every["mean_travel_time"] > 0
    assert every["mean_travel_time_planned"] == pytest.approx(every["mean_travel_time"])
    assert none["throughput"] == pytest.approx(3600.0 * CARS / none["sim_time"])
    # time exposed to a low TTC: none with a planned vehicle where none is planned
    assert none["tet_planned"] == 0.0 and none["tet"] >= 0.0
    assert every["tet_planned"] == pytest.approx(every["tet"])
    for name in ("sweep.csv", "sweep.json", "sweep.md", "sweep.png"):
        assert (out / name).is_file()
    with (out / "sweep.csv").open() as fh:
        assert len(list(csv.DictReader(fh))) == 2
    summary = json.loads((out / "sweep.json").read_text())["summary"]
    assert [s["share"] for s in summary] == [0.0, 1.0]
    assert "| 100 % | 1 | 0 |" in (out / "sweep.md").read_text()


def test_sweep_bad_input_is_one_line(tmp_path: Path) -> None:
    cfg = _scenario(tmp_path)
    with pytest.raises(ParameterError, match="between 0 and 1"):
        sweep.build_sweep(cfg, shares=(0.0, 1.5))
    with pytest.raises(ParameterError, match="scenario not found"):
        sweep.build_sweep(tmp_path / "nope.sumocfg")
    with pytest.raises(ParameterError, match="seeds must be >= 1"):
        sweep.build_sweep(cfg, seeds=0)
    proc = subprocess.run([sys.executable, "-m", "splineplan.cli", "bench", str(cfg),
                           "--shares", "0", "2", "--out", str(tmp_path / "o")],
                          capture_output=True, text=True, timeout=60)
    assert proc.returncode == 2
    assert proc.stderr.strip().splitlines() == [
        "splineplan bench: error: shares must be between 0 and 1, got [2.0]"]
