"""Ctrl-C (SIGINT) on the real commands, as separate processes: the run folder keeps a
record that reads (metrics.json says "interrupted", trajectory.csv and SUMO's fcd.xml and
ssm.xml are complete files, ``splineplan plot`` draws it), and ``bench`` stops at once and
writes the runs that finished."""

from __future__ import annotations

import csv
import json
import os
import signal
import subprocess
import sys
import time
import xml.etree.ElementTree as ET
from collections.abc import Callable
from pathlib import Path

import pytest
from conftest import ROOT

pytestmark = pytest.mark.skipif(os.name != "posix", reason="sends SIGINT to a process")

#: Longest wait [s] for a command to get under way (it loads the compiled loops first).
START_TIMEOUT = 60.0


def _cli(*args: str) -> subprocess.Popen[str]:
    # Ctrl-C as in a terminal: where the tests themselves run with SIGINT ignored (started
    # in a shell's background, as CI may), the command would inherit that
    return subprocess.Popen([sys.executable, "-m", "splineplan.cli", *args], cwd=ROOT,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            preexec_fn=_default_sigint)


def _default_sigint() -> None:
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def _wait_for(proc: subprocess.Popen[str], ready: Callable[[], bool]) -> None:
    t0 = time.monotonic()
    while not ready():
        assert proc.poll() is None, f"the command ended before it was interrupted: " \
                                    f"{proc.communicate()}"
        assert time.monotonic() - t0 < START_TIMEOUT, "the command did not get under way"
        time.sleep(0.02)


def _interrupt(proc: subprocess.Popen[str]) -> tuple[float, str]:
    """SIGINT; the seconds until the process ended and its error output (the exit status
    is checked to be 130, with both outputs shown where it is not)."""
    t0 = time.monotonic()
    proc.send_signal(signal.SIGINT)
    out, err = proc.communicate(timeout=30)
    assert proc.returncode == 130, (proc.returncode, out, err)
    return time.monotonic() - t0, err


def _check_run_folder(run: Path) -> dict[str, object]:
    """An interrupted run's folder: what it holds reads, and plot draws it."""
    m = json.loads((run / "metrics.json").read_text())
    assert m["status"] == "interrupted" and not m["arrived"]
    assert "interrupted" in m["reason"]
    with (run / "trajectory.csv").open(newline="") as fh:
        rows = list(csv.DictReader(fh))
    if rows:  # the last step observed: the one reached, or the one before (Ctrl-C came
        # between SUMO's step and the loop's look at it)
        assert 0.0 <= m["sim_time_end"] - float(rows[-1]["t"]) <= m["step_length"] + 1e-6
    if m["sim_time_end"] or (run / "fcd.xml").is_file():  # SUMO had started
        steps = ET.parse(run / "fcd.xml").getroot().findall("timestep")  # complete XML
        # every step SUMO made is in the file, and none beyond the time reached; a Ctrl-C
        # that came as SUMO started leaves it without steps, at time 0
        assert steps or m["sim_time_end"] == 0.0, m
        if steps:
            assert float(steps[-1].get("time", "nan")) <= m["sim_time_end"] + 1e-6
    if (run / "ssm.xml").is_file():  # SUMO's SSM device: closed by SUMO, complete XML too
        root = ET.parse(run / "ssm.xml").getroot()
        assert root.tag == "SSMLog"
        # what it logged ends by the time reached, and metrics.json has read it
        ends = [float(c.get("end", "nan")) for c in root.iter("conflict")]
        assert all(e <= m["sim_time_end"] + 1e-6 for e in ends), (ends, m)
        assert m["sumo_ssm_conflicts"] <= len(ends)
    plot = subprocess.run([sys.executable, "-m", "splineplan.cli", "plot", str(run)],
                          cwd=ROOT, capture_output=True, text=True, timeout=120, check=False)
    assert plot.returncode == 0, plot.stderr
    return m


def test_simulate_interrupted_writes_the_record(tmp_path: Path) -> None:
    out = tmp_path / "city"
    proc = _cli("simulate", "scenarios/city.toml", "--out", str(out), "--no-progress")
    fcd = out / "fcd.xml"
    # under way: SUMO has written steps with the ego (it departs at t = 20 s)
    _wait_for(proc, lambda: fcd.is_file() and b'id="ego"' in fcd.read_bytes())
    took, err = _interrupt(proc)
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("splineplan simulate: city: interrupted")
    assert took < 10.0
    m = _check_run_folder(out)
    assert 20.0 < m["sim_time_end"] < 140.0  # type: ignore[operator]
    assert m["depart_time"] is not None


def test_bench_interrupted_stops_at_once_and_writes_the_finished_runs(tmp_path: Path
                                                                      ) -> None:
    out = tmp_path / "bench"
    proc = _cli("bench", "scenarios/empty_road.toml", "--seeds", "4", "--drivers", "planner",
                "sumo", "--workers", "2", "--out", str(out), "--no-progress")
    _wait_for(proc, lambda: any((out / "runs").glob("*/*/row.json")))  # a run finished
    took, err = _interrupt(proc)
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("splineplan bench: interrupted after")
    assert took < 10.0  # before: 40 s, as the pool ran on
    with (out / "runs.csv").open(newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert 1 <= len(rows) < 8
    assert all(r["status"] in ("arrived", "timeout", "failed") for r in rows)
    runs = json.loads((out / "runs.json").read_text())
    assert runs["interrupted"] is True and len(runs["runs"]) == len(rows)
    summary = (out / "summary.md").read_text()
    assert "Interrupted" in summary and "did not run" in summary
    # the runs in hand when the suite stopped wrote their partial record
    for run in (out / "runs").glob("*/*"):
        if (run / "metrics.json").is_file() and not (run / "row.json").is_file():
            _check_run_folder(run)
