"""Closed loop on seeded random routes: does the driven path keep the car's limits?

``python -m benchmarks drive [--routes N] [--seed S] [--nets monaco city grid] [--json FILE]
[--out DIR] [-v]``.

The routes are those of ``bench_feasible`` for the same seed (the draw of
:mod:`benchmarks.routes`: random pairs of edges the passenger class may use, 0.5-3 km on
Monaco and 0.3-3 km on the bundled networks, no turnaround in the planned route). Each
becomes a closed-loop scenario with no other traffic: on Monaco ``scenarios/monaco.toml``
with its ego's start and goal edges replaced, on city and grid ``scenarios/city.toml``'s
parameters on that network without its traffic. The ego starts on the rightmost lane its
class may use, 20 m along the start edge (the front bumper; at most the edge's length, at
least the car's: a route whose start edge is shorter than the car is not run), and drives
to the goal edge's end; the run lasts 60 s plus the route's length at 5 m/s.
:func:`splineplan.sim.simulate` runs each in turn (libsumo: one run at a time in the
process); a run that raises a ``SplineplanError`` counts as failed, with its message, and
what it recorded before (``metrics.json``) still counts. The closed loop plans its own
route (level 1), which may differ from the draw's: each record says whether it does and
where the driven route turns back.

The limits are issue 13's: driven curvature at most ``1 / min_turn_radius`` + 2 %, lateral
acceleration at most ``mu * g`` + 5 % (the scenario's ``[trajectory]`` parameters), no
collision, never off the road. Printed per network: routes run, arrived, within each limit,
all four together (also among the routes that take no turn or bend level 1 finds too tight
for the car, and among those whose plan from level 1 to 3 is feasible), the median wall
time per run and the worst value of each with its route;
``-v`` a line per route (with the speed where the curvature and the lateral acceleration
peak). ``--json`` writes every route's record; ``--out`` keeps each run's
folder (``metrics.json`` says why a run stopped).
"""

from __future__ import annotations

import argparse
import dataclasses
import itertools
import json
import logging
import statistics
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks.routes import LONGEST, NETS, ROOT, random_routes

#: Tolerances on the limits: curvature +2 %, lateral acceleration +5 % (issue 13).
CURVATURE_TOLERANCE = 0.02
LATERAL_TOLERANCE = 0.05
#: Run time [s]: this much plus the route's length at :data:`ROUTE_SPEED`.
BASE_DURATION = 60.0
ROUTE_SPEED = 5.0
#: Where the ego's front bumper starts along the start edge [m] (at most the edge's length).
START_POS = 20.0
#: Status of a route whose start edge is shorter than the car: no scenario can start there.
NOT_RUN = "not run"
#: The checks that make up the target, in print order.
CHECKS = ("curvature_ok", "lateral_ok", "no_collision", "on_road")


def base_scenario(name: str, path: Path) -> Any:
    """The scenario each random route of network ``name`` (file ``path``) starts from."""
    from splineplan.scenario import load_scenario

    if name == "monaco":
        return load_scenario(ROOT / "scenarios" / "monaco.toml")
    sc = load_scenario(ROOT / "scenarios" / "city.toml")
    return dataclasses.replace(sc, name=name, network=path, routes=(), additional=(),
                               description=f"a random route on {path.name}", path=None)


def route_scenario(base: Any, net: Any, index: int, from_edge: str, to_edge: str,
                   length: float) -> Any:
    """``base`` with its ego driving from ``from_edge`` to ``to_edge`` (a route of ``length``
    [m]), no other traffic, long enough to arrive."""
    ego = base.ego
    lane = next(i for i, ln in enumerate(net.lanes_of(from_edge)) if ln.allows(ego.vclass))
    start = max(min(START_POS, net.length_of(from_edge)), ego.length)
    ego = dataclasses.replace(ego, start_edge=from_edge, goal_edge=to_edge, start_pos=start,
                              start_lane=lane, goal_pos=None, depart=0.0)
    sim = dataclasses.replace(base.sim, duration=BASE_DURATION + length / ROUTE_SPEED)
    return dataclasses.replace(base, name=f"{base.name}_route{index:02d}", ego=ego, egos=(ego,),
                               routes=(), additional=(), sim=sim)


def drive(sc: Any, net: Any, out: Path) -> dict[str, Any]:
    """Run one scenario on ``net``; its record (``status`` ``failed`` with the message where
    it raised; ``turnarounds``: the steps where the driven route turns back)."""
    from splineplan.errors import SplineplanError
    from splineplan.route import is_turnaround
    from splineplan.sim import simulate

    t0 = time.perf_counter()
    try:
        m = dict(simulate(sc, out_dir=out, progress=False).metrics)
    except SplineplanError as err:
        message = str(err).splitlines()[0] if str(err) else type(err).__name__
        m = {}
        if (out / "metrics.json").exists():
            m = json.loads((out / "metrics.json").read_text())
        m.update(status="failed", arrived=False, error=f"{type(err).__name__}: {message}")
    wall = time.perf_counter() - t0
    tp = sc.trajectory
    kappa_max, a_max = 1.0 / tp.min_turn_radius, tp.mu * tp.g
    kappa, a_lat = m.get("max_curvature"), m.get("max_lateral_acceleration")
    collisions, off = m.get("collisions"), m.get("time_off_road")
    driven = list(m.get("route") or ())
    back = [f"{e} -> {f}" for e, f in itertools.pairwise(driven)
            if is_turnaround(net, e, f, sc.ego.vclass)]
    rec = {
        "status": m.get("status"), "arrived": bool(m.get("arrived")),
        "reason": m.get("reason"), "error": m.get("error"),
        "travel_time": m.get("travel_time"), "distance": m.get("distance"),
        "max_curvature": kappa, "max_lateral_acceleration": a_lat,
        "collisions": collisions, "sumo_collision_reports": m.get("sumo_collision_reports"),
        "time_off_road": off, "replans": m.get("replan_count"),
        "route_driven": driven, "turnarounds": back, "wall_time": wall,
        "curvature_limit": kappa_max, "lateral_limit": a_max,
        "curvature_ok": kappa is not None and kappa <= kappa_max * (1 + CURVATURE_TOLERANCE),
        "lateral_ok": a_lat is not None and a_lat <= a_max * (1 + LATERAL_TOLERANCE),
        "no_collision": collisions == 0 and not m.get("sumo_collision_reports"),
        "on_road": off is not None and off <= 0.0,
    }
    rec["all_ok"] = all(rec[c] for c in CHECKS)
    replans = [float(r["time"]) for r in m.get("replans") or ()]
    rec["curvature_peak"] = _peak(out / "trajectory.csv", "curvature", replans)
    rec["lateral_peak"] = _peak(out / "trajectory.csv", "a_lat", replans)
    return rec


def _peak(csv: Path, column: str, replans: list[float]) -> dict[str, float | None] | None:
    """Where the driven path's ``column`` peaks (absolute value): time [s], station [m],
    speed [m/s] and the time since the last replan before it [s]."""
    if not csv.exists():
        return None
    import csv as csvlib

    # the numeric columns only (Monaco's lane ids hold '#', numpy's comment character)
    with csv.open(newline="") as f:
        rows = list(csvlib.DictReader(f))
    if len(rows) < 3:
        return None
    d = {k: np.array([float(r[k]) for r in rows]) for k in ("t", "station", "speed", column)}
    i = int(np.argmax(np.abs(d[column])))
    t = float(d["t"][i])
    before = [r for r in replans if r <= t]
    return {"t": t, "station": float(d["station"][i]), "speed": float(d["speed"][i]),
            "since_replan": t - before[-1] if before else None}


def _fmt(x: Any, spec: str) -> str:
    return "-" if x is None else format(x, spec)


def _at(peak: dict[str, float | None] | None) -> str:
    return "" if peak is None else f" at {peak['speed']:.1f} m/s"


def route_line(r: dict[str, Any]) -> str:
    """One line of ``-v``: a route's outcome and its maxima."""
    if r["status"] == NOT_RUN:
        return (f"  #{r['index']:02d} {r['from_edge']} -> {r['to_edge']} ({r['length']:.0f} m): "
                f"{NOT_RUN}: {r['error']}")
    flags = " ".join(c for c in CHECKS if not r[c])
    why = r["error"] or ("" if r["arrived"] else r["reason"] or "")
    return (f"  #{r['index']:02d} {r['from_edge']} -> {r['to_edge']} ({r['length']:.0f} m): "
            f"{r['status']}, travel {_fmt(r['travel_time'], '.1f')} s, kappa "
            f"{_fmt(r['max_curvature'], '.3f')} 1/m{_at(r['curvature_peak'])}, a_lat "
            f"{_fmt(r['max_lateral_acceleration'], '.2f')} m/s^2{_at(r['lateral_peak'])}, "
            f"collisions {_fmt(r['collisions'], 'd')}, off road "
            f"{_fmt(r['time_off_road'], '.1f')} s, "
            f"wall {r['wall_time']:.1f} s" + (f"; breaks: {flags}" if flags else "")
            + (f"; turns back {', '.join(r['turnarounds'])}" if r["turnarounds"] else "")
            + (f"; {why}" if why else ""))


def summary(recs: list[dict[str, Any]]) -> dict[str, Any]:
    """Counts, median wall time and the worst values (with their route) of one network,
    over the routes run."""
    drawn = len(recs)
    recs = [r for r in recs if r["status"] != NOT_RUN]
    out: dict[str, Any] = {"drawn": drawn, "not_run": drawn - len(recs), "routes": len(recs),
                           "arrived": sum(r["arrived"] for r in recs),
                           "failed": sum(r["status"] == "failed" for r in recs)}
    for c in (*CHECKS, "all_ok"):
        out[c] = sum(bool(r[c]) for r in recs)
    out["arrived_all_ok"] = sum(r["arrived"] and r["all_ok"] for r in recs)
    forward = [r for r in recs if not r["turnarounds"]]
    out["turning_back"] = len(recs) - len(forward)
    out["forward_all_ok"] = sum(r["all_ok"] for r in forward)
    out["not_as_planned"] = sum(not r["route_as_planned"] for r in recs)
    fit = [r for r in recs if r.get("too_tight") is False]
    out["fit"], out["fit_all_ok"] = len(fit), sum(r["all_ok"] for r in fit)
    feasible = [r for r in recs if r.get("planned_feasible")]
    out["feasible"], out["feasible_all_ok"] = len(feasible), sum(r["all_ok"] for r in feasible)
    out["median_wall_time"] = statistics.median(r["wall_time"] for r in recs) if recs else None
    for key in ("max_curvature", "max_lateral_acceleration", "collisions", "time_off_road"):
        have = sorted((r[key], r["index"]) for r in recs if r[key] is not None)
        if not have:
            out[f"worst_{key}"] = None
            continue
        value, i = have[-1]
        w = next(r for r in recs if r["index"] == i)
        out[f"worst_{key}"] = {"value": value, "index": i,
                               "route": f"{w['from_edge']} -> {w['to_edge']}"}
    return out


def summary_lines(name: str, s: dict[str, Any], limits: tuple[float, float]) -> list[str]:
    """The printed summary of one network."""
    n = s["routes"]

    def share(k: str) -> str:
        return f"{s[k]} ({100.0 * s[k] / max(n, 1):.0f} %)"

    def worst(k: str, spec: str, unit: str) -> str:
        w = s[f"worst_{k}"]
        if w is None:
            return "-"
        where = f" (#{w['index']:02d} {w['route']})" if w["value"] else ""
        return f"{format(w['value'], spec)}{unit}{where}"

    wall = s["median_wall_time"]
    return [
        f"{name}: {s['drawn']} routes drawn"
        + (f", {s['not_run']} not run (start edge shorter than the car)" if s["not_run"] else "")
        + f"; {n} run, arrived {share('arrived')}, failed {s['failed']}; within "
        f"curvature 1/R + 2 % {share('curvature_ok')}, lateral acceleration mu g + 5 % "
        f"{share('lateral_ok')}, no collision {share('no_collision')}, never off the road "
        f"{share('on_road')}; all four {share('all_ok')}, arrived and all four "
        f"{share('arrived_all_ok')}; median wall {_fmt(wall, '.1f')} s per run",
        f"  driven route not the planned one (a re-route): {s['not_as_planned']}; it turns "
        f"back: {s['turning_back']}, all four among the other "
        f"{n - s['turning_back']}: {s['forward_all_ok']}",
        f"  all four among the {s['fit']} that take no turn or bend too tight for the car: "
        f"{s['fit_all_ok']}; among the {s['feasible']} whose plan from level 1 to 3 is "
        f"feasible: {s['feasible_all_ok']}",
        f"  worst: curvature {worst('max_curvature', '.3f', ' 1/m')} (limit {limits[0]:.3f}), "
        f"lateral acceleration {worst('max_lateral_acceleration', '.2f', ' m/s^2')} (limit "
        f"{limits[1]:.2f}), collisions {worst('collisions', 'd', '')}, off road "
        f"{worst('time_off_road', '.1f', ' s')}",
    ]


def bench_network(name: str, path: Path, shortest: float, n_routes: int, seed: int,
                  out: Path, verbose: bool, save: Callable[[dict[str, Any]], None]
                  ) -> dict[str, Any]:
    """Drive ``n_routes`` random routes on one network; print and return the records,
    handing them to ``save`` after each route (nothing lost from a run stopped midway)."""
    from splineplan.network import load_network

    net = load_network(path)
    base = base_scenario(name, path)
    tp = base.trajectory
    limits = (1.0 / tp.min_turn_radius, tp.mu * tp.g)
    recs: list[dict[str, Any]] = []
    result: dict[str, Any] = {"limits": {"curvature": limits[0],
                                         "lateral_acceleration": limits[1]}, "routes": recs}
    t0 = time.perf_counter()
    for i, r in enumerate(random_routes(net, n_routes, seed, shortest)):
        planned = None if r.plan is None else list(r.plan.route.edges)
        rec: dict[str, Any] = {
            "index": i, "from_edge": r.from_edge, "to_edge": r.to_edge, "length": r.length,
            "planned_feasible": None if r.plan is None else bool(r.plan.trajectory.feasible),
            "too_tight": None if r.plan is None else bool(r.plan.route.tight_turns
                                                          or r.plan.route.tight_bends),
            "route_planned": planned}
        start_len = net.length_of(r.from_edge)
        if start_len < base.ego.length:  # the closed loop needs the car on its start edge
            rec.update(status=NOT_RUN, error=f"start edge '{r.from_edge}' ({start_len:.2f} m) "
                       f"is shorter than the car ({base.ego.length} m)")
        else:
            sc = route_scenario(base, net, i, r.from_edge, r.to_edge, r.length)
            rec.update(drive(sc, net, out / sc.name))
            rec["route_as_planned"] = rec["route_driven"] == planned
        recs.append(rec)
        result["summary"] = summary(recs)
        save(result)
        if verbose:
            print(route_line(rec), flush=True)
    result["summary"] = summary(recs)
    for line in summary_lines(path.name, result["summary"], limits):
        print(line, flush=True)
    print(f"  ({shortest / 1e3:.1f}-{LONGEST / 1e3:.0f} km, seed {seed}, "
          f"{time.perf_counter() - t0:.0f} s)", flush=True)
    return result


def main(argv: list[str]) -> int:
    ap = argparse.ArgumentParser(prog="python -m benchmarks drive",
                                 description=__doc__.splitlines()[0])
    ap.add_argument("--routes", type=int, default=50, help="routes per network (default 50)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--nets", nargs="+", default=["monaco", "city", "grid"],
                    choices=list(NETS))
    ap.add_argument("--json", type=Path, default=None, help="write every route's record here")
    ap.add_argument("--out", type=Path, default=None,
                    help="keep each run's folder here (default: a temporary folder)")
    ap.add_argument("-v", "--verbose", action="store_true", help="a line per route")
    args = ap.parse_args(argv)
    logging.disable(logging.WARNING)  # the pipeline's warnings about tight turns
    results: dict[str, Any] = {"seed": args.seed, "networks": {}}
    with tempfile.TemporaryDirectory() as tmp:
        out = args.out if args.out is not None else Path(tmp)
        for name in args.nets:
            path, shortest = NETS[name]
            if not path.exists():
                print(f"{name}: {path} not found, skipped")
                continue

            def save(result: dict[str, Any], name: str = name) -> None:
                results["networks"][name] = result
                if args.json is not None:
                    args.json.write_text(json.dumps(results, indent=1))

            bench_network(name, path, shortest, args.routes, args.seed, out / name,
                          args.verbose, save)
    return 0


if __name__ == "__main__":
    import sys

    sys.exit(main(sys.argv[1:]))
