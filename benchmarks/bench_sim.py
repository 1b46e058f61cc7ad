"""Closed-loop benchmark: the planner driving the ego against SUMO's own driver model.

On the city-scale scenario (``scenarios/city.toml``: the same level-1 route, the same
background traffic, the same SUMO options and FCD output), runs the scenario with the planner
driving the ego (``driver="planner"``) and with SUMO's own model driving it
(``driver="sumo"``), alternately, in one process (libsumo: one run at a time, closed in
between). Prints the wall times, the wall time per simulated second (each run stops when
its ego arrives, and the two egos arrive at different times), their ratio, and the
planning time per replan (median and max).

``python -m benchmarks sim`` or ``python -m benchmarks.bench_sim [--repeat N]
[--scenario PATH]``
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parent.parent


def _one(scenario: Any, driver: str, out: Path) -> dict[str, float]:
    from splineplan.sim import simulate

    r = simulate(scenario, out_dir=out, driver=driver, progress=False)  # type: ignore[arg-type]
    m = r.metrics
    if not r.arrived:
        raise SystemExit(f"{driver} run did not arrive: {r.reason}")
    return {"wall": float(m["wall_time"]), "sim": float(m["sim_time_end"]),
            "travel": float(m["travel_time"]),
            "plan_median": float(m["planning_time"]["median"] or 0.0),
            "plan_max": float(m["planning_time"]["max"] or 0.0),
            "replans": float(m["replan_count"])}


def main(argv: list[str]) -> None:
    ap = argparse.ArgumentParser(prog="bench_sim", description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=3, help="runs of each driver (default 3)")
    ap.add_argument("--scenario", default=str(ROOT / "scenarios" / "city.toml"))
    args = ap.parse_args(argv)

    from splineplan.scenario import load_scenario

    sc = load_scenario(args.scenario)
    runs: dict[str, list[dict[str, float]]] = {"planner": [], "sumo": []}
    with tempfile.TemporaryDirectory() as tmp:
        for i in range(args.repeat):
            for driver in ("planner", "sumo"):
                runs[driver].append(_one(sc, driver, Path(tmp) / f"{driver}{i}"))

    def med(driver: str, key: str) -> float:
        return statistics.median(r[key] for r in runs[driver])

    wp, ws = med("planner", "wall"), med("sumo", "wall")
    per_p = statistics.median(r["wall"] / r["sim"] for r in runs["planner"])
    per_s = statistics.median(r["wall"] / r["sim"] for r in runs["sumo"])
    plan_med = statistics.median(r["plan_median"] for r in runs["planner"])
    plan_max = max(r["plan_max"] for r in runs["planner"])
    print(f"scenario {sc.name} ({args.repeat} runs each, medians)")
    print(f"  planner drives: wall {wp:.2f} s for {med('planner', 'sim'):.1f} s simulated "
          f"(ego travel {med('planner', 'travel'):.1f} s, "
          f"{med('planner', 'replans'):.0f} replans)")
    print(f"  SUMO drives:    wall {ws:.2f} s for {med('sumo', 'sim'):.1f} s simulated "
          f"(ego travel {med('sumo', 'travel'):.1f} s)")
    print(f"  wall per simulated second: planner {1e3 * per_p:.2f} ms, SUMO {1e3 * per_s:.2f} ms"
          f", ratio {per_p / per_s:.2f} (target <= 1.5); raw wall ratio {wp / ws:.2f}")
    print(f"  planning per replan: median {1e3 * plan_med:.1f} ms (target <= 20), "
          f"max {1e3 * plan_max:.1f} ms")


if __name__ == "__main__":
    import sys

    main(sys.argv[1:])
