"""Junction turns: the planner against the kinematic oracle inside SUMO's paving.

``python -m benchmarks turns [--monaco N] [--seed S] [--nets city grid monaco] [-v]``.
Every turn of ``sumo_nets/city.net.xml`` and ``grid.net.xml`` and ``N`` seeded random
turns of the Monaco network (``../shared/data``, skipped when absent). Each turn
(:mod:`benchmarks.turns`) is a route of two edges; its drivable area is the allowed lanes
of both edges, SUMO's junction outline and the connection's internal lanes. The oracle
(:mod:`benchmarks.kinematic_oracle`: hybrid A*, the 4.5 x 1.8 m car, 4.2 m turning
radius) says whether the car can drive from the start to the goal inside that area;
``splineplan.pipeline.plan`` plans the same route from the same pose. Printed per
network: turns, oracle-drivable, planner-feasible among those, planner-feasible turns
whose footprint leaves the area (shapely, by more than :data:`TOL`), and timings.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from benchmarks.kinematic_oracle import Search, drive
from benchmarks.turns import Turn, TurnBuilder, outside, random_turns, turns_of
from splineplan.corridor import Corridor
from splineplan.network import CarShape, searched_path, turn_fits

ROOT = Path(__file__).resolve().parent.parent
MONACO = ROOT.parent / "shared" / "data" / "monaco.net.xml.gz"
NETS = {"city": ROOT / "sumo_nets" / "city.net.xml", "grid": ROOT / "sumo_nets" / "grid.net.xml",
        "monaco": MONACO}
#: How far [m] a footprint may reach outside the area before it counts (shapely's
#: buffers of curved lanes, and the footprint's sampling along the curve).
TOL = 0.05
#: The oracle's raster [m] (its verdicts hold to about twice that).
SEARCH = Search(step=0.05)


#: Oracle verdicts already known (``--oracle-cache``): the planner's changes do not
#: change them.
_KNOWN: dict[str, list[float]] = {}


def run_turn(net: object, builder: TurnBuilder, a: str, b: str) -> dict[str, object]:
    """Oracle and planner on one turn; their verdicts and times."""
    from splineplan.errors import SplineplanError
    from splineplan.pipeline import plan

    turn = builder.turn(a, b)
    t0 = time.perf_counter()
    fits = turn_fits(net, a, b, "passenger", CarShape())  # type: ignore[arg-type]
    t_fits = time.perf_counter() - t0
    t0 = time.perf_counter()
    key = f"{builder.path.name}:{a}:{b}"
    if key in _KNOWN:
        found, t_oracle = bool(_KNOWN[key][0]), _KNOWN[key][1]
    else:
        found = drive(turn.window, [], turn.start, turn.goal, margin=0.0, search=SEARCH).found
        t_oracle = time.perf_counter() - t0
        _KNOWN[key] = [float(found), t_oracle]
    t0 = time.perf_counter()
    try:
        p = plan(net, a, b, start_pos=turn.start_pos, start_xy=turn.start[:2],  # type: ignore[arg-type]
                 start_heading=turn.start[2], end_pos=turn.end_pos)
        tr = p.trajectory
        verdict = "feasible" if tr.feasible else "infeasible"
        out = outside(turn, np.asarray(tr.x), np.asarray(tr.y), np.asarray(tr.heading))
        why = "; ".join(str(v) for v in tr.violations[:2]) if not tr.feasible else ""
        routed = tuple(p.route.edges)
    except SplineplanError as err:
        verdict, out, why, routed = "error", 0.0, str(err), ()
    t_plan = time.perf_counter() - t0
    if routed and routed != (a, b):
        verdict = "avoided"  # level 1 went round the turn
    in_corridor = None
    if found and verdict == "infeasible":
        in_corridor = _drives_in_corridor(p.corridor, turn)
    limit = searched_path(net, a, b, "passenger", CarShape()) is not None  # type: ignore[arg-type]
    return {"turn": (a, b), "junction": turn.junction, "drivable": found, "fits": fits,
            "limit": limit, "verdict": verdict, "outside": out, "why": why, "route": routed,
            "in_corridor": in_corridor, "t_oracle": t_oracle, "t_plan": t_plan,
            "t_fits": t_fits}


def _drives_in_corridor(corridor: Corridor, turn: Turn) -> bool:
    """Whether the oracle drives the turn inside the planner's own corridor (widened to
    the junctions' paving where the corridor knows it) cut to the turn's area: where it
    cannot, the planner's drivable area, not its curve, is what fails the turn."""
    from shapely.geometry import Polygon

    wide = corridor.paved() or corridor
    area = Polygon(wide.polygon()).buffer(0).intersection(turn.window)
    return bool(drive(area, [], turn.start, turn.goal, margin=0.0, search=SEARCH).found)


def bench(name: str, path: Path, pairs: list[tuple[str, str]], verbose: bool
          ) -> list[dict[str, object]]:
    from splineplan.network import load_network

    net = load_network(path)
    builder = TurnBuilder(path)
    rows = []
    for a, b in pairs:
        r = run_turn(net, builder, a, b)
        rows.append(r)
        if verbose or (r["drivable"] and r["verdict"] != "feasible") or \
                (r["verdict"] == "feasible" and float(r["outside"]) > TOL):  # type: ignore[arg-type]
            inside = ("" if r["in_corridor"] is None else
                      "; the oracle drives it in the planner's corridor" if r["in_corridor"]
                      else "; the oracle cannot drive it in the planner's corridor")
            print(f"  {a} -> {b} (junction {r['junction']}): oracle "
                  f"{'drives' if r['drivable'] else 'cannot'}; level 1 "
                  f"{'fits' if r['fits'] else 'too tight'}; planner {r['verdict']}, "
                  f"outside {float(r['outside']):.2f} m{inside}  {r['why']}"[:300],  # type: ignore[arg-type]
                  flush=True)
    drivable = [r for r in rows if r["drivable"]]
    ok = [r for r in drivable if r["verdict"] == "feasible"]
    bad = [r for r in rows if r["verdict"] == "feasible" and float(r["outside"]) > TOL]  # type: ignore[arg-type]
    undrivable_ok = [r for r in rows if not r["drivable"] and r["verdict"] == "feasible"]
    avoided = [r for r in drivable if r["verdict"] == "avoided"]
    tight = [r for r in rows if not r["fits"]]
    tight_right = [r for r in tight if not r["drivable"]]
    t_f = np.median([float(r["t_fits"]) for r in rows])  # type: ignore[arg-type]
    t_o = np.median([float(r["t_oracle"]) for r in rows])  # type: ignore[arg-type]
    t_p = np.median([float(r["t_plan"]) for r in rows])  # type: ignore[arg-type]
    share = 100.0 * len(ok) / max(len(drivable), 1)
    worst = max((float(r["outside"]) for r in rows if r["verdict"] == "feasible"),  # type: ignore[arg-type]
                default=0.0)
    print(f"{name}: {len(rows)} turns, oracle-drivable {len(drivable)}, planner-feasible "
          f"among those {len(ok)} ({share:.1f} %; target 99 %), feasible with the footprint "
          f"outside the area (> {TOL} m) {len(bad)} (worst {worst:.2f} m; target 0); "
          f"feasible where the oracle cannot drive {len(undrivable_ok)}; median time: "
          f"oracle {t_o:.2f} s, planner {1e3 * t_p:.0f} ms", flush=True)
    missed = [r for r in drivable if r["verdict"] == "infeasible"]
    if missed:
        print(f"  of the {len(missed)} drivable turns planned infeasibly, the oracle drives "
              f"{sum(bool(r['in_corridor']) for r in missed)} inside the planner's own "
              f"corridor (with its junction paving); the others need room it does not give",
              flush=True)
    print(f"  level 1: {len(tight)} turns too tight for the car, {len(tight_right)} of them "
          f"undrivable by the oracle too; of the {len(rows) - len(drivable)} undrivable turns "
          f"{sum(not r['fits'] for r in rows if not r['drivable'])} known to level 1; "
          f"drivable turns avoided by level 1: {len(avoided)}; median test time "
          f"{1e3 * t_f:.2f} ms (first use, then cached)", flush=True)
    limit = [r for r in rows if r.get("limit")]
    if limit:
        print(f"  level 1 found {len(limit)} turns only by its search (at the turning limit): "
              f"the oracle drives {sum(bool(r['drivable']) for r in limit)}, the planner plans "
              f"{sum(r['verdict'] == 'feasible' for r in limit)} feasibly", flush=True)
    return rows


def main(argv: list[str]) -> int:
    ap = argparse.ArgumentParser(prog="python -m benchmarks turns", description=__doc__)
    ap.add_argument("--monaco", type=int, default=200, help="random Monaco turns (200)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--nets", nargs="+", default=["city", "grid", "monaco"],
                    choices=sorted(NETS))
    ap.add_argument("-v", "--verbose", action="store_true", help="a line per turn")
    ap.add_argument("--json", type=Path, help="write the rows to this file")
    ap.add_argument("--oracle-cache", type=Path,
                    help="JSON file of the oracle's verdicts, read if present and updated "
                         "(for runs that change only the planner)")
    args = ap.parse_args(argv)
    if args.oracle_cache is not None and args.oracle_cache.exists():
        import json

        _KNOWN.update(json.loads(args.oracle_cache.read_text()))
    t0 = time.perf_counter()
    for name in args.nets:
        path = NETS[name]
        if not path.exists():
            print(f"{name}: network not found at {path}: skipped")
            continue
        pairs = (random_turns(path, args.monaco, args.seed) if name == "monaco"
                 else turns_of(path))
        rows = bench(name, path, pairs, args.verbose)
        if args.json is not None:
            import json

            out = args.json.with_name(f"{args.json.stem}_{name}{args.json.suffix}")
            out.write_text(json.dumps(rows, indent=1, default=str))
        if args.oracle_cache is not None:
            import json

            args.oracle_cache.write_text(json.dumps(_KNOWN))
    print(f"in {time.perf_counter() - t0:.0f} s")
    return 0


if __name__ == "__main__":
    import sys

    sys.exit(main(sys.argv[1:]))
