"""Closed-loop benchmark: the planner driving the ego against SUMO's own driver models.

On the city-scale scenarios (``scenarios/city.toml``: light background traffic, ten flows;
``scenarios/city_traffic.toml``: the same plus 391 seeded random trips), with the same
level-1 route, the same background traffic and the same outputs, runs the scenario with
each driver of :func:`splineplan.sim.simulate`, alternately, in one process (libsumo: one
run at a time, closed in between):

- ``planner``: splineplan drives (SUMO's sublane model on, 0.4 m, see
  :data:`splineplan.sim.LATERAL_RESOLUTION`);
- ``sumo``: SUMO's default lane-based model drives (no sublanes: SUMO's cheapest setup);
- ``sublane``: SUMO's sublane model drives (the same SUMO options as the planner's run).

Prints, per scenario and driver, the median wall time and its split (inside SUMO, in the
planner, in the closed loop's own code), the wall time per simulated second (each run stops
when its ego arrives, at different times), the ratios planner / sumo and planner / sublane,
and the planning time per replan (median and max).

``python -m benchmarks sim [--repeat N] [--scenario PATH ...]``
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parent.parent
DRIVERS = ("planner", "sumo", "sublane")


def _one(scenario: Any, driver: str, out: Path) -> dict[str, float]:
    from splineplan.sim import simulate

    r = simulate(scenario, out_dir=out, driver=driver, progress=False)  # type: ignore[arg-type]
    m = r.metrics
    return {"wall": float(m["wall_time"]), "sim": float(m["sim_time_end"]),
            "travel": float(m["travel_time"] or 0.0), "arrived": float(r.arrived),
            "checks": float(m["safety_check_time"]),
            "t_sumo": float(m["wall_time_sumo"]), "t_plan": float(m["wall_time_planner"]),
            "t_loop": float(m["wall_time_loop"]),
            "plan_median": float(m["planning_time"]["median"] or 0.0),
            "plan_max": float(m["planning_time"]["max"] or 0.0),
            "replans": float(m["replan_count"]), "collisions": float(m["collisions"])}


def main(argv: list[str]) -> None:
    ap = argparse.ArgumentParser(prog="bench_sim", description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=3, help="runs of each driver (default 3)")
    ap.add_argument("--scenario", nargs="+", default=[
        str(ROOT / "scenarios" / "city.toml"), str(ROOT / "scenarios" / "city_traffic.toml")])
    args = ap.parse_args(argv)

    from splineplan.scenario import load_scenario

    for path in args.scenario:
        sc = load_scenario(path)
        runs: dict[str, list[dict[str, float]]] = {d: [] for d in DRIVERS}
        with tempfile.TemporaryDirectory() as tmp:
            for i in range(args.repeat):
                for driver in DRIVERS:
                    runs[driver].append(_one(sc, driver, Path(tmp) / f"{driver}{i}"))

        def med(driver: str, key: str, runs: dict[str, list[dict[str, float]]] = runs
                ) -> float:
            return statistics.median(r[key] for r in runs[driver])

        def per_s(driver: str, runs: dict[str, list[dict[str, float]]] = runs) -> float:
            return statistics.median(r["wall"] / r["sim"] for r in runs[driver])

        print(f"scenario {sc.name} ({args.repeat} runs each, medians)")
        for d in DRIVERS:
            print(f"  {d:8s} wall {med(d, 'wall'):5.2f} s for {med(d, 'sim'):5.1f} s simulated "
                  f"({1e3 * per_s(d):5.2f} ms per simulated s; ego travel "
                  f"{med(d, 'travel'):.1f} s, arrived {med(d, 'arrived'):.0f}, collisions "
                  f"{med(d, 'collisions'):.0f}, own safety checks {med(d, 'checks'):.2f} s)")
            print(f"           split: SUMO {med(d, 't_sumo'):.2f} s, "
                  f"planner {med(d, 't_plan'):.2f} s, "
                  f"loop {med(d, 't_loop'):.2f} s")
        print(f"  ratio planner/sumo {per_s('planner') / per_s('sumo'):.2f}, planner/sublane "
              f"{per_s('planner') / per_s('sublane'):.2f} (per simulated second; target "
              f"<= 1.5); raw wall ratios {med('planner', 'wall') / med('sumo', 'wall'):.2f}, "
              f"{med('planner', 'wall') / med('sublane', 'wall'):.2f}")
        plan_max = max(r["plan_max"] for r in runs["planner"])
        print(f"  planning per replan: median {1e3 * med('planner', 'plan_median'):.1f} ms "
              f"(target <= 20), max {1e3 * plan_max:.1f} ms, "
              f"{med('planner', 'replans'):.0f} replans")


if __name__ == "__main__":
    import sys

    main(sys.argv[1:])
