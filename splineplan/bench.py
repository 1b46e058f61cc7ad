"""Scenario bench: the planner against SUMO's own drivers, over suites of cases x seeds.

A *case* is a scenario file and a seed: a bundled scenario (the seed is SUMO's) or an
obstacle field generated from the seed (:mod:`splineplan.fields`; its route file and scenario
file are written into the output folder). Each case is driven by each *driver*:
``planner`` (splineplan drives the ego), ``sumo`` (SUMO's default car-following and
lane-change model) and ``sublane`` (SUMO's sublane model, which may shift within a lane).

Every run, one case and one driver, runs in a fresh Python process (libsumo holds one
simulation per process), whichever executor hands the runs out: a local pool of
``workers`` threads that each start such processes, or a Ray cluster (``address``; its
nodes must have splineplan installed and see the output folder and the scenario files, as
on one machine or a shared file system). Rows come back sorted by case and driver, so that
the results do not depend on the executor; all randomness comes from the seeds.

Outputs: ``runs.csv`` and ``runs.json`` (one row per run), ``summary.md`` (a table by
difficulty tier and driver; a success is a safe arrival: no collision, no time off the
road) and figures (:func:`splineplan.plot.plot_bench`). Ctrl-C stops the suite at once:
the runs not started are cancelled, those in hand write their partial records, and the
three files are written for the runs that finished.
"""

from __future__ import annotations

import csv
import json
import logging
import math
import time
import xml.etree.ElementTree as ET
from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from splineplan import fields as fld
from splineplan._signals import sigint_ignored
from splineplan.errors import Interrupted, ParameterError
from splineplan.executor import run_tasks

log = logging.getLogger(__name__)

#: The drivers of every case, in the order of the rows.
DRIVERS = ("planner", "sumo", "sublane")


def _project_root() -> Path:
    """The folder holding the bundled ``sumo_nets/`` and ``scenarios/``: the project's
    checkout beside the package (an editable install), else the working directory (the
    project's folder, after ``pip install .``)."""
    here = Path(__file__).resolve().parent.parent
    for root in (here, Path.cwd()):
        if (root / "sumo_nets").is_dir() and (root / "scenarios").is_dir():
            return root
    return here


#: Folder of the bundled scenarios and networks.
ROOT = _project_root()
SCENARIOS = ROOT / "scenarios"
NETS = ROOT / "sumo_nets"

#: Bundled roads for generated fields: network file and edges in driving order.
ROADS: dict[str, tuple[str, tuple[str, ...]]] = {
    "straight": ("straight.net.xml", ("e0", "e1", "e2")),
    "curved": ("curved.net.xml", ("s0", "bend", "s1")),
}
#: Bundled scenarios of the default suite.
BUNDLED = ("empty_road", "one_obstacle", "obstacle_field_c", "obstacle_field_d")
#: Suites by name: bundled scenarios, roads and tiers of generated fields.
SUITES: dict[str, dict[str, tuple[str, ...]]] = {
    "default": {"bundled": BUNDLED, "roads": ("straight", "curved"),
                "tiers": ("sparse", "medium", "dense", "blocked")},
    "quick": {"bundled": ("one_obstacle",), "roads": ("straight",),
              "tiers": ("sparse", "blocked")},
    "fields": {"bundled": (), "roads": ("straight", "curved"),
               "tiers": ("empty", "sparse", "medium", "dense", "blocked")},
}
#: Row fields that hold wall-clock times: they differ between runs of the same case.
TIMING_FIELDS = ("wall_time", "wall_planner", "wall_sumo", "wall_loop", "plan_time_median",
                 "plan_time_max", "plan_time_total")
#: Row fields that depend on where the outputs went.
PLACE_FIELDS = ("run_dir",)
#: Columns of ``runs.csv``, in order. ``arrived``: the ego reached its goal; ``safe``: it
#: arrived without a collision (the closed loop's footprint check) and without time off
#: the road, what the summary counts as a success.
COLUMNS = ("index", "case", "driver", "tier", "road", "density", "obstacles", "seed",
           "status", "arrived", "safe", "reason", "error", "travel_time", "distance",
           "min_clearance", "min_clearance_sim", "collisions", "time_off_road", "teleports",
           "replans",
           *TIMING_FIELDS, "run_dir")


@dataclass(frozen=True)
class BenchCase:
    """One scenario file and seed of a suite.

    Attributes
    ----------
    index
        Position in the suite (rows are sorted by it).
    name
        Unique name, ``<scenario>_s<seed>`` or the generated field's name.
    scenario
        The scenario file (TOML).
    seed
        SUMO's random seed (and the field's, for generated cases).
    tier
        Difficulty tier (:data:`splineplan.fields.TIERS`), ``bundled`` for a bundled one.
    road
        Road name of a generated field, else the scenario's stem.
    density
        Stopped vehicles per 100 m of a generated field [1/(100 m)]; NaN for others.
    obstacles
        Number of stopped vehicles of a generated field (-1 if unknown).
    """

    index: int
    name: str
    scenario: str
    seed: int
    tier: str = "bundled"
    road: str = ""
    density: float = math.nan
    obstacles: int = -1


@dataclass(frozen=True)
class BenchResult:
    """Outcome of :func:`run_suite`.

    Attributes
    ----------
    rows
        One dict per run (keys :data:`COLUMNS`), sorted by case index and driver.
    cases
        The cases run.
    drivers
        The drivers of each case.
    wall_time
        Wall time [s] of the whole suite.
    executor
        ``local (N workers)`` or ``ray (ADDRESS)``.
    files
        Files written (``runs.csv``, ``runs.json``, ``summary.md``, figures).
    interrupted
        Whether Ctrl-C stopped the suite: ``rows`` are then the runs that had finished.
    """

    rows: list[dict[str, Any]]
    cases: tuple[BenchCase, ...]
    drivers: tuple[str, ...]
    wall_time: float
    executor: str
    files: tuple[str, ...] = field(default=())
    interrupted: bool = False

    @property
    def runs_planned(self) -> int:
        """Runs of the suite: every case with every driver."""
        return len(self.cases) * len(self.drivers)

    @property
    def cases_done(self) -> int:
        """Cases whose runs (every driver) all finished."""
        per: dict[int, int] = {}
        for r in self.rows:
            per[r["index"]] = per.get(r["index"], 0) + 1
        return sum(1 for n in per.values() if n >= len(self.drivers))

    @property
    def cases_not_run(self) -> int:
        """Cases of which no run finished (none, unless interrupted)."""
        return len(self.cases) - len({r["index"] for r in self.rows})

    @property
    def cases_per_minute(self) -> float:
        """Throughput: cases (each with all its drivers) per minute of wall time."""
        return 60.0 * self.cases_done / self.wall_time if self.wall_time > 0 else math.inf

    @property
    def runs_per_minute(self) -> float:
        """Throughput: runs (one case, one driver) per minute of wall time."""
        return 60.0 * len(self.rows) / self.wall_time if self.wall_time > 0 else math.inf


# ---- suites -------------------------------------------------------------------------------

def road_spec(name: str, **kwargs: Any) -> fld.RoadSpec:
    """The :class:`~splineplan.fields.RoadSpec` of a bundled road (:data:`ROADS`).

    Lane lengths are read from the network; ``kwargs`` go to ``RoadSpec`` (``start_pos``,
    ``field_start``, ``field_end``, or ``edges`` to use the first few edges only).
    """
    if name not in ROADS:
        raise ParameterError(f"unknown road {name!r}; known: {', '.join(ROADS)}")
    from splineplan.network import load_network

    net_file, edges = ROADS[name]
    edges = tuple(kwargs.pop("edges", edges))
    net = load_network(NETS / net_file)
    lengths, lanes = [], set()
    for e in edges:
        i = net.edge_ids.index(e)
        lengths.append(min(ln.length for ln in net.lanes[i]))
        lanes.add(len(net.lanes[i]))
    if len(lanes) != 1:
        raise ParameterError(f"road {name}: edges have different lane counts {sorted(lanes)}")
    return fld.RoadSpec(name, str(NETS / net_file), edges, tuple(lengths), lanes.pop(),
                        **kwargs)


def generated_case(
    road: fld.RoadSpec,
    tier: str,
    seed: int,
    out_dir: str | Path,
    *,
    index: int = 0,
    duration: float = 90.0,
) -> BenchCase:
    """Generate a field, write its route file and scenario file into ``out_dir``.

    Returns the case; the files are ``<name>.rou.xml`` and ``<name>.toml``.
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    f = fld.generate_field(road, tier, seed=seed)
    routes = []
    if f.vehicles:
        (out / f"{f.name}.rou.xml").write_text(fld.routes_xml(f))
        routes.append(f"{f.name}.rou.xml")
    net = str(Path(road.network).resolve())
    data = fld.scenario_dict(f, network=net, routes=routes, duration=duration)
    path = out / f"{f.name}.toml"
    path.write_text(f"# Generated by splineplan bench: {data['description']}\n"
                    + fld.toml_text(data))
    return BenchCase(index, f.name, str(path), int(seed), f.tier.name, road.name,
                     float(f.density), len(f.vehicles))


def build_suite(
    suite: str = "default",
    *,
    seeds: int = 1,
    tiers: Sequence[str] | None = None,
    out_dir: str | Path,
) -> list[BenchCase]:
    """The cases of a suite: a name of :data:`SUITES`, a scenario file or a folder of them.

    Generated fields are written into ``out_dir/scenarios``. ``seeds``: seeds 0 .. N-1 of
    every scenario and field. ``tiers`` keeps only these tiers (``bundled`` for the bundled
    scenarios).
    """
    if seeds < 1:
        raise ParameterError(f"seeds must be >= 1, got {seeds}")
    for t in tiers or ():
        if t != "bundled" and t not in fld.TIERS:
            raise ParameterError(f"unknown tier {t!r}; known: bundled, {', '.join(fld.TIERS)}")
    keep = set(tiers) if tiers else None
    bundled: list[Path] = []
    roads: tuple[str, ...] = ()
    suite_tiers: tuple[str, ...] = ()
    p = Path(suite)
    if suite in SUITES:
        if not (NETS.is_dir() and SCENARIOS.is_dir()):
            raise ParameterError(
                f"suite '{suite}' needs the project's bundled sumo_nets/ and scenarios/ "
                f"folders; run it from the project's folder (not found in {ROOT})")
        spec = SUITES[suite]
        bundled = [SCENARIOS / f"{n}.toml" for n in spec["bundled"]]
        roads, suite_tiers = spec["roads"], spec["tiers"]
    elif p.is_dir():
        bundled = sorted(p.glob("*.toml"))
        if not bundled:
            raise ParameterError(f"no scenario files (*.toml) in {p}")
    elif p.is_file():
        bundled = [p]
    else:
        raise ParameterError(f"unknown suite {suite!r}: not one of {', '.join(SUITES)} "
                             "and not a scenario file or folder")
    cases: list[BenchCase] = []
    if keep is None or "bundled" in keep:
        for path in bundled:
            for s in range(seeds):
                cases.append(BenchCase(len(cases), f"{path.stem}_s{s}", str(path), s,
                                       "bundled", path.stem))
    gen_dir = Path(out_dir) / "scenarios"
    for rname in roads:
        road = road_spec(rname)
        for tier in suite_tiers:
            if keep is not None and tier not in keep:
                continue
            for s in range(seeds):
                cases.append(generated_case(road, tier, s, gen_dir, index=len(cases)))
    if not cases:
        raise ParameterError(f"suite {suite!r} has no case for tiers {sorted(keep or [])}")
    return cases


# ---- one run ------------------------------------------------------------------------------

def run_task(task: Mapping[str, Any]) -> dict[str, Any]:
    """Run one case with one driver in this process; a row of :data:`COLUMNS`.

    ``task``: ``case`` (a :class:`BenchCase` as a dict), ``driver``, ``run_dir``. Errors are
    caught: the row says ``failed`` and gives the error message.
    """
    case = BenchCase(**task["case"])
    driver = str(task["driver"])
    run_dir = Path(task["run_dir"])
    row = _row_head(case, driver, run_dir)
    t0 = time.perf_counter()
    try:
        from splineplan.scenario import load_scenario
        from splineplan.sim import simulate

        sc = load_scenario(case.scenario)
        res = simulate(sc, out_dir=run_dir, seed=case.seed, progress=False,
                       driver=driver)  # type: ignore[arg-type]
        row.update(_row_metrics(res.metrics, res.status, res.reason))
        row["min_clearance"] = _fcd_clearance(run_dir / "fcd.xml", sc)
    except Exception as err:  # a crashing case is a failed row, the suite goes on
        row.update(_row_failed(run_dir, err, time.perf_counter() - t0))
        try:
            from splineplan.scenario import load_scenario

            row["min_clearance"] = _fcd_clearance(run_dir / "fcd.xml",
                                                  load_scenario(case.scenario))
        except Exception:
            pass
    return row


def failed_row(task: Mapping[str, Any], message: str) -> dict[str, Any]:
    """The row of a run that could not make its own (its process died, or never ran)."""
    row = _row_head(BenchCase(**task["case"]), str(task["driver"]), Path(task["run_dir"]))
    row["error"] = row["reason"] = message
    return row


def _row_head(case: BenchCase, driver: str, run_dir: Path) -> dict[str, Any]:
    row: dict[str, Any] = dict.fromkeys(COLUMNS)
    row.update({"index": case.index, "case": case.name, "driver": driver, "tier": case.tier,
                "road": case.road, "density": None if math.isnan(case.density)
                else round(case.density, 4), "obstacles": case.obstacles, "seed": case.seed,
                "status": "failed", "arrived": False, "safe": False, "reason": "",
                "error": "", "collisions": 0, "teleports": 0, "replans": 0,
                "run_dir": str(run_dir)})
    return row


def _row_metrics(m: Mapping[str, Any], status: str, reason: str) -> dict[str, Any]:
    plan = m.get("planning_time") or {}
    times = [float(r.get("planning_time", 0.0)) for r in m.get("replans") or []]
    wall = _num(m.get("wall_time"))
    planner = _num(m.get("wall_time_planner"))
    if planner is None:
        planner = float(sum(times))
    sumo = _num(m.get("wall_time_sumo"))
    loop = _num(m.get("wall_time_loop"))
    clear = [c for c in (_num(m.get("min_clearance_obstacles")),
                         _num(m.get("min_clearance_vehicles"))) if c is not None]
    collisions = int(m.get("collisions") or 0)
    off_road = _num(m.get("time_off_road"))
    arrived = status == "arrived"
    return {"status": status, "arrived": arrived,
            "safe": arrived and collisions == 0 and not off_road, "reason": reason,
            "travel_time": _round(_num(m.get("travel_time")), 3) if status == "arrived"
            else None,
            "distance": _round(_num(m.get("distance")), 3),
            "min_clearance_sim": _round(min(clear), 4) if clear else None,
            "collisions": collisions,
            "time_off_road": _round(off_road, 3),
            "teleports": int(m.get("teleports") or 0),
            "replans": int(m.get("replan_count") or 0),
            "wall_time": wall, "wall_planner": planner, "wall_sumo": sumo, "wall_loop": loop,
            "plan_time_median": _num(plan.get("median")), "plan_time_max": _num(plan.get("max")),
            "plan_time_total": float(sum(times))}


def _row_failed(run_dir: Path, err: BaseException, wall: float) -> dict[str, Any]:
    out: dict[str, Any] = {"status": "failed", "arrived": False, "safe": False,
                           "error": f"{type(err).__name__}: {err}".splitlines()[0][:500],
                           "wall_time": wall}
    mfile = run_dir / "metrics.json"
    if mfile.is_file():  # the run got far enough to write its metrics: keep what it has
        try:
            m = json.loads(mfile.read_text())
            got = _row_metrics(m, "failed", str(m.get("reason") or ""))
            got["travel_time"] = None
            out = {**got, **out, "wall_time": got["wall_time"] or wall}
        except (OSError, ValueError):
            pass
    out.setdefault("reason", out["error"])
    if not out.get("reason"):
        out["reason"] = out["error"]
    return out


def _num(value: Any) -> float | None:
    if value is None or isinstance(value, bool):
        return None
    try:
        x = float(value)
    except (TypeError, ValueError):
        return None
    return x if math.isfinite(x) else None


def _round(value: float | None, digits: int) -> float | None:
    return None if value is None else round(value, digits)


def _fcd_clearance(fcd: Path, scenario: Any) -> float | None:
    """Smallest distance [m] between the ego's rectangle and any other vehicle's, from
    SUMO's floating car data (the same measure for every driver); ``None`` if the ego never
    met another vehicle or the file is missing."""
    if not fcd.is_file():
        return None
    from splineplan.geometry import heading_from_sumo_angle
    from splineplan.metrics import box_distances, footprints

    dims = _vtype_dims(scenario)
    ego_id = scenario.ego.id
    ego_dims = (float(scenario.ego.length), float(scenario.ego.width))
    best = math.inf
    try:
        for _, el in ET.iterparse(fcd, events=("end",)):
            if el.tag != "timestep":
                continue
            vs = el.findall("vehicle")
            ego = [v for v in vs if v.get("id") == ego_id]
            others = [v for v in vs if v.get("id") != ego_id]
            if ego and others:
                e = ego[0]
                box = footprints([[float(e.get("x", 0)), float(e.get("y", 0))]],
                                 [heading_from_sumo_angle(float(e.get("angle", 0)))],
                                 [ego_dims[0]], [ego_dims[1]])[0]
                xy = np.array([[float(v.get("x", 0)), float(v.get("y", 0))] for v in others])
                near = np.hypot(*(xy - box.mean(axis=0)).T) < 30.0
                if near.any():
                    sel = [v for v, k in zip(others, near, strict=True) if k]
                    ln = [dims.get(v.get("type", ""), (5.0, 1.8))[0] for v in sel]
                    wd = [dims.get(v.get("type", ""), (5.0, 1.8))[1] for v in sel]
                    hd = [heading_from_sumo_angle(float(v.get("angle", 0))) for v in sel]
                    d = box_distances(box, footprints(xy[near], hd, ln, wd))
                    best = min(best, float(d.min()))
            el.clear()
    except ET.ParseError:  # a run that crashed may leave the file unfinished
        pass
    return round(best, 4) if math.isfinite(best) else None


def _vtype_dims(scenario: Any) -> dict[str, tuple[float, float]]:
    """Length and width [m] of the vehicle types of the scenario's route files."""
    dims = {"DEFAULT_VEHTYPE": (5.0, 1.8)}
    for path in (*scenario.routes, *scenario.additional):
        try:
            for _, el in ET.iterparse(path, events=("end",)):
                if el.tag == "vType" and el.get("id"):
                    dims[str(el.get("id"))] = (float(el.get("length", 5.0)),
                                               float(el.get("width", 1.8)))
        except (OSError, ET.ParseError):
            continue
    return dims


# ---- runs ---------------------------------------------------------------------------------

def _tasks(cases: Sequence[BenchCase], drivers: Sequence[str],
           out_dir: Path) -> list[dict[str, Any]]:
    return [{"runner": __name__, "case": asdict(c), "driver": d,
             "run_dir": str(out_dir / "runs" / c.name / d)} for c in cases for d in drivers]


def run_suite(
    cases: Sequence[BenchCase],
    *,
    out_dir: str | Path,
    drivers: Sequence[str] = DRIVERS,
    workers: int | None = None,
    address: str | None = None,
    progress: bool = True,
    plots: bool = True,
) -> BenchResult:
    """Run every case with every driver; write ``runs.csv``, ``runs.json``, ``summary.md``
    and (``plots``) the figures into ``out_dir``.

    ``workers``: processes at a time on this machine (default: the number of cores);
    ``address``: a Ray cluster's address (``HOST:PORT`` or ``ray://HOST:PORT``) instead
    (:mod:`splineplan.executor`). ``progress``: a progress bar on stderr naming the case in
    hand.

    Raises
    ------
    Interrupted
        Ctrl-C (``KeyboardInterrupt``): the runs not started are cancelled, those running
        stopped (each writes its partial record in its run folder), and ``runs.csv``,
        ``runs.json`` and ``summary.md`` of the runs that had finished are written (no
        figures); the exception's ``result`` is the :class:`BenchResult`.
    """
    bad = [d for d in drivers if d not in DRIVERS]
    if bad or not drivers:
        raise ParameterError(f"unknown driver(s) {bad}; known: {', '.join(DRIVERS)}")
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    tasks = _tasks(cases, drivers, out.resolve())
    ran = run_tasks(tasks, workers=workers, address=address, progress=progress,
                    label=lambda i: f"{tasks[i]['case']['name']} ({tasks[i]['driver']})")
    if ran.interrupted:
        with sigint_ignored():  # write what has finished
            result = _result(ran.rows, cases, drivers, ran.wall_time, ran.executor, out,
                             plots=False, interrupted=True)
        raise Interrupted(f"interrupted after {len(result.rows)} of {result.runs_planned} "
                          f"runs; runs.csv, runs.json and summary.md of those are in {out}",
                          result)
    return _result(ran.rows, cases, drivers, ran.wall_time, ran.executor, out, plots=plots)


def _result(rows: Sequence[dict[str, Any] | None], cases: Sequence[BenchCase],
            drivers: Sequence[str], wall: float, executor: str, out: Path, *, plots: bool,
            interrupted: bool = False) -> BenchResult:
    """The finished rows, sorted by case and driver, written out."""
    done = [r for r in rows if r is not None]
    done.sort(key=lambda r: (r["index"], drivers.index(r["driver"])))
    result = BenchResult(done, tuple(cases), tuple(drivers), wall, executor,
                         interrupted=interrupted)
    files = write_outputs(result, out, plots=plots)
    return BenchResult(done, tuple(cases), tuple(drivers), wall, executor, tuple(files),
                       interrupted=interrupted)


# ---- outputs ------------------------------------------------------------------------------

def comparable(rows: Sequence[Mapping[str, Any]]) -> list[dict[str, Any]]:
    """The rows without wall-clock times and output paths: what equal seeds reproduce."""
    drop = {*TIMING_FIELDS, *PLACE_FIELDS, "process_wall_time"}
    return [{k: v for k, v in r.items() if k not in drop} for r in rows]


def summarise(rows: Sequence[Mapping[str, Any]]) -> list[dict[str, Any]]:
    """Per tier and driver: runs, arrivals, safe arrivals, success rate, clearance and
    travel time.

    A success is a safe arrival (``safe``: arrived, no collision, no time off the road):
    an ego that reaches its goal through other cars has not done its job. Clearance [m]
    (``min_clearance``, from SUMO's floating car data) is over every run that met another
    vehicle; travel time [s] over the runs that arrived.
    """
    tiers: list[str] = []
    drivers: list[str] = []
    for r in rows:
        if r["tier"] not in tiers:
            tiers.append(r["tier"])
        if r["driver"] not in drivers:
            drivers.append(r["driver"])
    order = ["bundled", *fld.TIERS]
    tiers.sort(key=lambda t: order.index(t) if t in order else len(order))
    out = []
    for t in tiers:
        for d in drivers:
            sel = [r for r in rows if r["tier"] == t and r["driver"] == d]
            if not sel:
                continue
            arrived = [r for r in sel if r["arrived"]]
            safe = [r for r in arrived if r.get("safe")]
            clear = [float(r["min_clearance"]) for r in sel if r["min_clearance"] is not None]
            travel = [float(r["travel_time"]) for r in arrived if r["travel_time"] is not None]
            dens = [float(r["density"]) for r in sel if r["density"] is not None]
            out.append({
                "tier": t, "driver": d, "runs": len(sel), "arrived": len(arrived),
                "safe": len(safe), "success_rate": len(safe) / len(sel),
                "density": float(np.mean(dens)) if dens else None,
                "clearance_mean": float(np.mean(clear)) if clear else None,
                "clearance_median": float(np.median(clear)) if clear else None,
                "travel_time_mean": float(np.mean(travel)) if travel else None,
                "travel_time_median": float(np.median(travel)) if travel else None,
                "collisions": int(sum(int(r["collisions"] or 0) for r in sel)),
                "failed": sum(1 for r in sel if r["status"] == "failed"),
            })
    return out


def exit_status(rows: Sequence[Mapping[str, Any]]) -> int:
    """The ``bench`` command's exit status: 1 when a planner run failed with an error
    (the planner or the closed loop broke, not the scenario's difficulty) or when no run
    at all arrived safely (nothing worked), else 0."""
    if any(r["driver"] == "planner" and r["status"] == "failed" for r in rows):
        return 1
    if not any(r.get("safe") for r in rows):
        return 1
    return 0


def fmt(value: Any, digits: int) -> str:
    """A number as the summary table writes it (``-`` for none)."""
    return "-" if value is None else f"{float(value):.{digits}f}"


def summary_markdown(result: BenchResult) -> str:
    """The Markdown summary: a table by tier and driver, throughput and failures."""
    lines = ["# Scenario bench", ""]
    if result.interrupted:
        partly = len({r["index"] for r in result.rows}) - result.cases_done
        lines += [f"**Interrupted** (Ctrl-C) after {len(result.rows)} of "
                  f"{result.runs_planned} runs: {result.cases_not_run} of "
                  f"{len(result.cases)} cases did not run"
                  + (f" and {partly} ran with only some of the drivers" if partly else "")
                  + ". The tables hold the runs that finished.", ""]
    lines += [f"{len(result.cases)} cases x {len(result.drivers)} drivers "
             f"({', '.join(result.drivers)}) = {result.runs_planned} runs; executor "
             f"{result.executor}; wall time {result.wall_time:.1f} s; "
             f"{result.cases_per_minute:.1f} cases/min ({result.runs_per_minute:.1f} runs/min).",
             "",
             "Clearance: smallest distance between the ego's rectangle and any other "
             "vehicle's, from SUMO's floating car data, over runs that met one: the same "
             "record and the same computation for every driver (the closed loop's own "
             "`min_clearance_sim` uses the planned pose for the planner and SUMO's pose for "
             "SUMO's drivers; the two agree within centimetres). Travel time: "
             "runs that arrived. Density: stopped vehicles per 100 m of road. Safe: "
             "arrived without a collision and without time off the road; success is the "
             "share of safe arrivals.", "",
             "| tier | density [1/100 m] | driver | runs | arrived | safe | success | "
             "clearance mean [m] | clearance median [m] | travel time mean [s] | "
             "travel time median [s] | collisions | failed |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for s in summarise(result.rows):
        lines.append(
            f"| {s['tier']} | {fmt(s['density'], 2)} | {s['driver']} | {s['runs']} | "
            f"{s['arrived']} | {s['safe']} | {100.0 * s['success_rate']:.0f}% | "
            f"{fmt(s['clearance_mean'], 2)} | {fmt(s['clearance_median'], 2)} | "
            f"{fmt(s['travel_time_mean'], 1)} | {fmt(s['travel_time_median'], 1)} | "
            f"{s['collisions']} | {s['failed']} |")
    lines += ["", "## Time per run (wall clock)", "",
              "| case | driver | status | wall [s] | SUMO [s] | planner [s] | loop [s] | "
              "planning median / max [ms] |", "|---|---|---|---|---|---|---|---|"]
    for r in result.rows:
        med, mx = r.get("plan_time_median"), r.get("plan_time_max")
        lines.append(
            f"| {r['case']} | {r['driver']} | {r['status']} | {fmt(r['wall_time'], 2)} | "
            f"{fmt(r['wall_sumo'], 2)} | {fmt(r['wall_planner'], 2)} | "
            f"{fmt(r.get('wall_loop'), 2)} | {fmt(None if med is None else 1e3 * med, 1)} / "
            f"{fmt(None if mx is None else 1e3 * mx, 1)} |")
    failed = [r for r in result.rows if r["error"]]
    if failed:
        lines += ["", "## Errors", ""]
        lines += [f"- {r['case']} ({r['driver']}): {r['error']}" for r in failed]
    return "\n".join(lines) + "\n"


def write_outputs(result: BenchResult, out_dir: Path, *, plots: bool = True) -> list[str]:
    """Write ``runs.csv``, ``runs.json``, ``summary.md`` and the figures; the files."""
    files = []
    p = out_dir / "runs.csv"
    with p.open("w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(COLUMNS), extrasaction="ignore")
        w.writeheader()
        for r in result.rows:
            w.writerow({k: ("" if r.get(k) is None else r.get(k)) for k in COLUMNS})
    files.append(str(p))
    p = out_dir / "runs.json"
    p.write_text(json.dumps({
        "executor": result.executor, "drivers": list(result.drivers),
        "wall_time": result.wall_time, "cases_per_minute": result.cases_per_minute,
        "interrupted": result.interrupted, "runs_planned": result.runs_planned,
        "cases": [asdict(c) | {"density": None if math.isnan(c.density) else c.density}
                  for c in result.cases],
        "runs": result.rows}, indent=1, allow_nan=False))
    files.append(str(p))
    p = out_dir / "summary.md"
    p.write_text(summary_markdown(result))
    files.append(str(p))
    if plots:
        try:
            from splineplan.plot import plot_bench

            files += plot_bench(result.rows, out_dir)
        except (ImportError, ValueError, OSError) as err:
            log.warning("bench figures failed: %s", err)
    return files


def read_runs_csv(path: str | Path) -> list[dict[str, Any]]:
    """Rows of a ``runs.csv``, with numbers as numbers and empty cells as ``None``."""
    ints = {"index", "obstacles", "seed", "collisions", "teleports", "replans"}
    rows = []
    with Path(path).open(newline="") as fh:
        for raw in csv.DictReader(fh):
            row: dict[str, Any] = {}
            for k, v in raw.items():
                if v == "":
                    row[k] = None
                elif k in ("arrived", "safe"):
                    row[k] = v == "True"
                elif k in ints:
                    row[k] = int(v)
                else:
                    try:
                        row[k] = float(v)
                    except ValueError:
                        row[k] = v
            for k in ("case", "driver", "tier", "road", "status", "reason", "error"):
                if row.get(k) is None:
                    row[k] = ""
                else:
                    row[k] = str(raw[k])
            rows.append(row)
    return rows

