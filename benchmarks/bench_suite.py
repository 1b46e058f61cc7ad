"""Scenario bench throughput: the same fixed suite with 1 and with 2 local workers.

Suite: ``splineplan bench quick --seeds 2`` (the bundled ``one_obstacle`` scenario and two
generated fields on the straight road, sparse and blocked, each with seeds 0 and 1: 6 cases),
drivers ``planner`` and ``sumo`` (12 runs, each in its own process). Prints the wall time,
the throughput (cases per minute), the speed-up of 2 workers over 1, whether both gave the
same rows (wall-clock fields left out), and per run the split between SUMO and the planner.

``python -m benchmarks suite`` or ``python -m benchmarks.bench_suite [--seeds N]``
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
from pathlib import Path


def main(argv: list[str]) -> None:
    ap = argparse.ArgumentParser(prog="bench_suite", description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=2, help="seeds per case (default 2)")
    ap.add_argument("--suite", default="quick", help="suite name (default quick)")
    args = ap.parse_args(argv)

    from splineplan.bench import build_suite, comparable, run_suite

    drivers = ("planner", "sumo")
    results = {}
    with tempfile.TemporaryDirectory() as tmp:
        cases = build_suite(args.suite, seeds=args.seeds, out_dir=Path(tmp) / "cases")
        for workers in (1, 2):
            results[workers] = run_suite(cases, out_dir=Path(tmp) / f"w{workers}",
                                         drivers=drivers, workers=workers, progress=False,
                                         plots=False)
    one, two = results[1], results[2]
    print(f"suite {args.suite!r}, {len(cases)} cases x {len(drivers)} drivers = "
          f"{len(one.rows)} runs")
    for w, r in results.items():
        print(f"  {w} worker(s): {r.wall_time:6.1f} s  {r.cases_per_minute:5.1f} cases/min "
              f"({r.runs_per_minute:.1f} runs/min)")
    print(f"  speed-up 2 workers / 1 worker: {one.wall_time / two.wall_time:.2f} x")
    print(f"  same rows: {comparable(one.rows) == comparable(two.rows)}")
    for d in drivers:
        rows = [r for r in one.rows if r["driver"] == d and r["wall_time"] is not None]
        proc = statistics.median(r["process_wall_time"] for r in rows)
        wall = statistics.median(r["wall_time"] for r in rows)
        sumo = statistics.median(r["wall_sumo"] or 0.0 for r in rows)
        plan = statistics.median(r["wall_planner"] or 0.0 for r in rows)
        loop = statistics.median(r.get("wall_loop") or 0.0 for r in rows)
        print(f"  {d:>8}: per run (median, 1 worker) process {proc:.2f} s, simulate() "
              f"{wall:.2f} s = SUMO {sumo:.2f} s + planner {plan:.2f} s + loop {loop:.2f} s")
    print("  per run:")
    for r in one.rows:
        print(f"    {r['case']:>22} {r['driver']:>8} {r['status']:>8}  wall "
              f"{(r['wall_time'] or 0):.2f} s  SUMO {(r['wall_sumo'] or 0):.2f} s  "
              f"planner {(r['wall_planner'] or 0):.2f} s  loop {(r.get('wall_loop') or 0):.2f} s")


if __name__ == "__main__":
    import sys

    main(sys.argv[1:])
