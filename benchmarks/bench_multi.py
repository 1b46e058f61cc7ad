"""Many planned vehicles in one SUMO run: SUMO's city scenario with a share of its cars planned.

Runs ``scenarios/city_traffic.sumocfg`` (the city network, the ten flows and the 391 random
trips) with ``--share`` of the departing passenger cars planned, for each seed, each run in
its own process (libsumo: one simulation per process), until every vehicle has left or the
duration ends. Prints per run: planned vehicles, arrived, collisions (pairs with a planned
vehicle whose footprints overlapped, from the FCD output), vehicles off the road, the
smallest gap between planned vehicles, the wall time against the simulated time (real-time
factor), the process's CPU time, and the wall time per planned vehicle and simulated second.

``python -m benchmarks multi [--share F] [--seeds N ...] [--duration S]``
"""

from __future__ import annotations

import argparse
import json
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
CONFIG = ROOT / "scenarios" / "city_traffic.sumocfg"


def _one(share: float, seed: int, duration: float, out: Path) -> dict[str, float]:
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    subprocess.run([sys.executable, "-m", "splineplan.cli", "simulate", str(CONFIG),
                    "--share", f"{share:g}", "--seed", str(seed), "--duration", f"{duration:g}",
                    "--out", str(out), "--no-progress"], cwd=ROOT, capture_output=True,
                   check=False)
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    s = json.loads((out / "summary.json").read_text())
    pairs = s.get("pairs") or {}
    gap = (pairs.get("min_gap_between_planned") or {}).get("value")
    return {"planned": s["planned"], "arrived": s["arrived"],
            "collision_pairs": len(pairs.get("collision_pairs_planned", [])),
            "off_road": s["vehicles_off_road"],
            "min_gap_planned": gap if gap is not None else float("nan"),
            "sim": s["sim_time_end"], "wall_run": s["wall_time"], "wall_process": wall,
            "cpu": (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime),
            "per_vehicle_second": s["wall_time_per_vehicle_second"] or float("nan"),
            "stuck": sum(1 for v in s["vehicles"].values() if v["stuck"])}


def main(argv: list[str]) -> None:
    ap = argparse.ArgumentParser(prog="bench_multi", description=__doc__.splitlines()[0])
    ap.add_argument("--share", type=float, default=0.25)
    ap.add_argument("--seeds", type=int, nargs="+", default=[1, 2, 3])
    ap.add_argument("--duration", type=float, default=900.0)
    ap.add_argument("--out", type=Path, default=None,
                    help="keep each run's folder here (default: a temporary folder)")
    args = ap.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp_dir:
        tmp = args.out or Path(tmp_dir)
        print("seed planned arrived collision_pairs off_road stuck min_gap_planned[m] sim[s] "
              "wall_run[s] sim/wall cpu[s] sim/cpu wall/(vehicle*s)")
        for seed in args.seeds:
            r = _one(args.share, seed, args.duration, tmp / f"seed{seed}")
            print(f"{seed} {r['planned']:.0f} {r['arrived']:.0f} {r['collision_pairs']:.0f} "
                  f"{r['off_road']:.0f} {r['stuck']:.0f} {r['min_gap_planned']:.2f} "
                  f"{r['sim']:.0f} {r['wall_run']:.0f} "
                  f"{r['sim'] / r['wall_run']:.2f} {r['cpu']:.0f} {r['sim'] / r['cpu']:.2f} "
                  f"{1e3 * r['per_vehicle_second']:.1f} ms", flush=True)
