"""Penetration sweep: one SUMO scenario with a rising share of its vehicles planned.

What SUMO's users ask of automated driving is what happens to the traffic as more of it
drives itself. A sweep runs one scenario (a ``.sumocfg``, or a TOML scenario with traffic)
at each share of planned vehicles (default 0, 10, 25, 50 and 100 % of the departing
passenger cars, a seeded draw) over several seeds, one SUMO per process
(:mod:`splineplan.executor`: local processes or a Ray cluster), and compares, per share,
the travel time, time loss and throughput of every vehicle from SUMO's tripinfo output, and
from the FCD output the time exposed to a low time-to-collision (per vehicle-hour) and the
smallest time-to-collision and gap between any two vehicles.

Outputs in the sweep's folder: ``sweep.csv`` and ``sweep.json`` (one row per run),
``sweep.md`` (means and spreads per share) and ``sweep.png`` (the figures against the
share); each run's own folder under ``runs/``.
"""

from __future__ import annotations

import contextlib
import csv
import json
import math
import statistics
import time
import xml.etree.ElementTree as ET
from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from splineplan._signals import sigint_ignored
from splineplan.closedloop.pairs import TET_THRESHOLD
from splineplan.errors import Interrupted, ParameterError
from splineplan.executor import run_tasks

#: Shares of planned vehicles a sweep runs by default.
SHARES = (0.0, 0.1, 0.25, 0.5, 1.0)
#: Columns of ``sweep.csv``, in order.
COLUMNS = ("index", "name", "share", "seed", "status", "reason", "error", "planned",
           "planned_arrived", "collisions", "overlaps_planned", "overlaps_unplanned",
           "time_off_road", "teleports", "vehicles",
           "arrived", "mean_travel_time", "mean_time_loss", "mean_travel_time_planned",
           "mean_travel_time_others", "throughput", "tet", "tet_planned", "min_ttc",
           "sumo_ssm_min_ttc", "min_gap", "min_gap_planned", "sim_time", "wall_time",
           "run_dir")
#: Columns that are wall-clock times (they differ between runs of the same point).
TIMING_FIELDS = ("wall_time", "process_wall_time")
#: What the summary and the figure compare between shares.
FIGURES = (("mean_travel_time", "mean travel time [s]"),
           ("mean_time_loss", "mean time loss [s]"),
           ("throughput", "throughput [veh/h]"),
           ("tet", f"time with TTC < {TET_THRESHOLD:g} s [s per vehicle-hour]"))


@dataclass(frozen=True)
class SweepPoint:
    """One run of a sweep: the scenario at one share and seed."""

    index: int
    name: str
    scenario: str
    share: float
    seed: int


@dataclass(frozen=True)
class SweepResult:
    """Outcome of :func:`run_sweep`.

    Attributes
    ----------
    rows
        One dict per finished run (keys :data:`COLUMNS`), sorted by share and seed.
    points
        The runs asked for.
    wall_time
        Wall time [s] of the sweep.
    executor
        ``local (N workers)`` or ``ray (ADDRESS)``.
    files
        Files written.
    interrupted
        Whether Ctrl-C stopped the sweep (``rows`` are the runs that finished).
    """

    rows: list[dict[str, Any]]
    points: tuple[SweepPoint, ...]
    wall_time: float
    executor: str
    files: tuple[str, ...] = field(default=())
    interrupted: bool = False


def build_sweep(scenario: str | Path, *, shares: Sequence[float] = SHARES,
                seeds: int = 5) -> list[SweepPoint]:
    """Every share with seeds ``0 .. seeds - 1``."""
    path = Path(scenario)
    if not path.is_file():
        raise ParameterError(f"scenario not found: {path}")
    if not path.name.endswith((".toml", ".sumocfg", ".cfg")):
        raise ParameterError(f"a sweep runs a scenario file (.toml or .sumocfg), not {path}")
    if not shares:
        raise ParameterError("a sweep needs at least one share")
    bad = [s for s in shares if not (isinstance(s, (int, float)) and 0.0 <= s <= 1.0)]
    if bad:
        raise ParameterError(f"shares must be between 0 and 1, got {bad}")
    if seeds < 1:
        raise ParameterError(f"seeds must be >= 1, got {seeds}")
    stem = path.name.split(".")[0]
    return [SweepPoint(i, f"{stem}_p{round(100 * share):03d}_s{seed}",
                       str(path.resolve()), float(share), seed)
            for i, (share, seed) in enumerate((sh, sd) for sh in sorted(set(shares))
                                              for sd in range(seeds))]


def load_any(path: str | Path) -> Any:
    """A scenario from a TOML file or a SUMO configuration."""
    from splineplan.scenario import load_scenario, sumo_scenario

    p = str(path)
    return sumo_scenario(p) if p.endswith((".sumocfg", ".cfg")) else load_scenario(p)


# ---- one run ------------------------------------------------------------------------------

def run_task(task: Mapping[str, Any]) -> dict[str, Any]:
    """Run one point in this process; a row of :data:`COLUMNS` (errors give a failed
    row)."""
    point = SweepPoint(**task["point"])
    run_dir = Path(task["run_dir"])
    row = _row_head(point, run_dir)
    t0 = time.perf_counter()
    try:
        from splineplan.sim import simulate

        res = simulate(load_any(point.scenario), out_dir=run_dir, seed=point.seed,
                       share=point.share, progress=False)
        row.update(_row_metrics(res.metrics, run_dir))
        row["status"], row["reason"] = res.status, res.reason
    except Exception as err:  # a crashing run is a failed row, the sweep goes on
        row["error"] = row["reason"] = f"{type(err).__name__}: {err}".splitlines()[0][:500]
        summary = run_dir / "summary.json"
        if summary.is_file():  # it got far enough to write its summary: keep what it has
            with contextlib.suppress(OSError, ValueError):
                row.update(_row_metrics(json.loads(summary.read_text()), run_dir))
    row["wall_time"] = time.perf_counter() - t0
    return row


def failed_row(task: Mapping[str, Any], message: str) -> dict[str, Any]:
    """The row of a run that could not make its own."""
    row = _row_head(SweepPoint(**task["point"]), Path(task["run_dir"]))
    row["error"] = row["reason"] = message
    return row


def _row_head(point: SweepPoint, run_dir: Path) -> dict[str, Any]:
    row: dict[str, Any] = dict.fromkeys(COLUMNS)
    row.update({"index": point.index, "name": point.name, "share": point.share,
                "seed": point.seed, "status": "failed", "reason": "", "error": "",
                "run_dir": str(run_dir)})
    return row


def _row_metrics(summary: Mapping[str, Any], run_dir: Path) -> dict[str, Any]:
    """The row's figures from the run's summary and SUMO's tripinfo output."""
    planned = set((summary.get("vehicles") or {}).keys())
    trips = read_tripinfo(run_dir / "tripinfo.xml")
    sim_time = float(summary.get("sim_time_end") or 0.0)
    pairs = summary.get("pairs") or {}

    def mean(values: list[float]) -> float | None:
        return statistics.fmean(values) if values else None

    def pair_value(key: str) -> float | None:
        rec = pairs.get(key)
        return None if rec is None else float(rec["value"])

    return {
        "planned": int(summary.get("planned") or 0),
        "planned_arrived": int(summary.get("arrived") or 0),
        "collisions": int(summary.get("collisions") or 0),
        # pairs whose footprints overlapped (FCD): with a planned vehicle, and of two of
        # SUMO's own (a baseline: SUMO's drivers overlap too)
        "overlaps_planned": len(pairs.get("collision_pairs_planned") or ()),
        "overlaps_unplanned": pairs.get("overlapping_pairs_unplanned"),
        "time_off_road": float(summary.get("time_off_road") or 0.0),
        "teleports": int(summary.get("teleports") or 0),
        "vehicles": len(trips),
        "arrived": sum(1 for t in trips if t["arrived"]),
        "mean_travel_time": mean([t["duration"] for t in trips if t["arrived"]]),
        "mean_time_loss": mean([t["time_loss"] for t in trips if t["arrived"]]),
        "mean_travel_time_planned": mean([t["duration"] for t in trips
                                          if t["arrived"] and t["id"] in planned]),
        "mean_travel_time_others": mean([t["duration"] for t in trips
                                         if t["arrived"] and t["id"] not in planned]),
        "throughput": (3600.0 * sum(1 for t in trips if t["arrived"]) / sim_time
                       if sim_time > 0 else None),
        "tet": pairs.get("tet_per_vehicle_hour"),
        "tet_planned": pairs.get("tet_planned_per_vehicle_hour"),
        "min_ttc": pair_value("min_ttc"),
        "sumo_ssm_min_ttc": pair_value("sumo_ssm_min_ttc"),  # SUMO's SSM device's, beside
        "min_gap": pair_value("min_gap"),
        "min_gap_planned": pair_value("min_gap_planned"),
        "sim_time": sim_time,
    }


def read_tripinfo(path: Path) -> list[dict[str, Any]]:
    """Each vehicle's trip from SUMO's tripinfo output: id, duration [s], time loss [s],
    whether it arrived (``arrival`` >= 0); none where the file is missing or cut short."""
    if not path.is_file():
        return []
    out = []
    try:
        for _, el in ET.iterparse(path, events=("end",)):
            if el.tag == "tripinfo":
                arrival = float(el.get("arrival", -1))
                out.append({"id": el.get("id", ""), "duration": float(el.get("duration", 0)),
                            "time_loss": float(el.get("timeLoss", 0)),
                            "arrived": arrival >= 0})
                el.clear()
    except ET.ParseError:
        pass  # a run cut short: the trips read so far
    return out


# ---- the sweep ----------------------------------------------------------------------------

def run_sweep(points: Sequence[SweepPoint], *, out_dir: str | Path,
              workers: int | None = None, address: str | None = None,
              progress: bool = True, plots: bool = True) -> SweepResult:
    """Run every point; write ``sweep.csv``, ``sweep.json``, ``sweep.md`` and
    (``plots``) ``sweep.png`` into ``out_dir``.

    Raises
    ------
    Interrupted
        Ctrl-C: the runs not started are cancelled, those running stopped, and the files
        are written for the runs that finished (``result`` is the :class:`SweepResult`).
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    tasks = [{"runner": __name__, "point": asdict(p),
              "run_dir": str(out.resolve() / "runs" / p.name)} for p in points]
    ran = run_tasks(tasks, workers=workers, address=address, progress=progress,
                    label=lambda i: points[i].name)
    rows = sorted((r for r in ran.rows if r is not None), key=lambda r: r["index"])
    result = SweepResult(rows, tuple(points), ran.wall_time, ran.executor,
                         interrupted=ran.interrupted)
    if ran.interrupted:
        with sigint_ignored():
            files = write_outputs(result, out, plots=False)
        raise Interrupted(f"interrupted after {len(rows)} of {len(points)} runs; sweep.csv, "
                          f"sweep.json and sweep.md of those are in {out}",
                          SweepResult(rows, tuple(points), ran.wall_time, ran.executor,
                                      tuple(files), True))
    files = write_outputs(result, out, plots=plots)
    return SweepResult(rows, tuple(points), ran.wall_time, ran.executor, tuple(files))


def summarise(rows: Sequence[Mapping[str, Any]]) -> list[dict[str, Any]]:
    """Per share: runs, failed runs, planned vehicles, collisions, and the mean and the
    standard deviation over seeds of each of :data:`FIGURES` (``None`` without data)."""
    out = []
    for share in sorted({float(r["share"]) for r in rows}):
        rs = [r for r in rows if float(r["share"]) == share]
        entry: dict[str, Any] = {
            "share": share, "runs": len(rs),
            "failed": sum(1 for r in rs if r["status"] == "failed"),
            "planned": sum(int(r["planned"] or 0) for r in rs),
            "planned_arrived": sum(int(r["planned_arrived"] or 0) for r in rs),
            "collisions": sum(int(r["collisions"] or 0) for r in rs),
            "overlaps_planned": sum(int(r.get("overlaps_planned") or 0) for r in rs),
            "overlaps_unplanned": sum(int(r.get("overlaps_unplanned") or 0) for r in rs)}
        for key, _ in FIGURES:
            vals = [float(r[key]) for r in rs if r.get(key) is not None]
            entry[key] = statistics.fmean(vals) if vals else None
            entry[key + "_sd"] = statistics.stdev(vals) if len(vals) > 1 else None
        out.append(entry)
    return out


def _fmt(value: Any, digits: int = 1) -> str:
    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        return "-"
    return f"{value:.{digits}f}" if isinstance(value, float) else str(value)


def summary_markdown(result: SweepResult) -> str:
    """``sweep.md``: a table by share."""
    scenario = Path(result.points[0].scenario).name if result.points else ""
    lines = [f"# Penetration sweep: {scenario}", "",
             f"{len(result.rows)} of {len(result.points)} runs, {result.executor}, "
             f"{result.wall_time:.0f} s" + (" (interrupted)" if result.interrupted else ""),
             "", "| share | runs | failed | planned (arrived) | collisions | overlapping "
             "pairs: planned / SUMO's | " + " | ".join(label for _, label in FIGURES) + " |",
             "|---:|---:|---:|---:|---:|---:|" + "---:|" * len(FIGURES)]
    for s in summarise(result.rows):
        cells = [f"{_fmt(s[k])} ± {_fmt(s[k + '_sd'])}"
                 for k, _ in FIGURES]
        lines.append(f"| {100 * s['share']:.0f} % | {s['runs']} | {s['failed']} | "
                     f"{s['planned']} ({s['planned_arrived']}) | {s['collisions']} | "
                     f"{s['overlaps_planned']} / {s['overlaps_unplanned']} | "
                     + " | ".join(cells) + " |")
    lines += ["", "Collisions: the steps in which a planned vehicle's own footprint check "
              "found it overlapping another; overlapping "
              "pairs: pairs of vehicles whose footprints overlapped (FCD output), with a "
              "planned vehicle and of two of SUMO's own. "
              "Means over seeds ± their standard deviation; travel time and time loss "
              "of every vehicle that arrived (SUMO's tripinfo); throughput: arrivals per "
              f"hour of simulated time; time with TTC < {TET_THRESHOLD:g} s: the seconds that "
              f"pairs of vehicles spend less than {TET_THRESHOLD:g} s from touching at their "
              "speeds and headings, "
              "per hour that vehicles spend in the run (time exposed TTC, FCD output)."]
    return "\n".join(lines) + "\n"


def write_outputs(result: SweepResult, out_dir: Path, *, plots: bool = True) -> list[str]:
    """Write ``sweep.csv``, ``sweep.json``, ``sweep.md`` and (``plots``) ``sweep.png``."""
    files = []
    csv_path = out_dir / "sweep.csv"
    with csv_path.open("w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=COLUMNS, extrasaction="ignore")
        w.writeheader()
        for r in result.rows:
            w.writerow({k: "" if r.get(k) is None else r[k] for k in COLUMNS})
    files.append(str(csv_path))
    json_path = out_dir / "sweep.json"
    json_path.write_text(json.dumps({"executor": result.executor,
                                     "wall_time": result.wall_time,
                                     "interrupted": result.interrupted,
                                     "summary": summarise(result.rows),
                                     "rows": result.rows}, indent=1, allow_nan=False))
    files.append(str(json_path))
    md_path = out_dir / "sweep.md"
    md_path.write_text(summary_markdown(result))
    files.append(str(md_path))
    if plots and result.rows:
        from splineplan.plot import plot_sweep

        files.append(str(plot_sweep(result.rows, out_dir / "sweep.png")))
    return files
