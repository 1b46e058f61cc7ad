"""Level 3 timing: optimisation + speed profile on the shared obstacle fields."""

from __future__ import annotations

import statistics
import time

from benchmarks.fields import obstacle_field
from splineplan.errors import SplineplanError
from splineplan.roadmap import plan_roadmap
from splineplan.trajectory import plan_trajectory

CASES = ((100, 0), (300, 0), (1000, 0), (300, 20), (300, 40), (100, 13), (1000, 133))
SEEDS = (0, 1, 2)


def _median_ms(fn, repeat: int = 5) -> float:  # type: ignore[no-untyped-def]
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return 1e3 * statistics.median(times)


def main(argv: list[str]) -> None:
    for length, n_obs in CASES:
        for seed in SEEDS if n_obs else SEEDS[:1]:
            try:
                corridor, obstacles, start = obstacle_field(length, n_obs, seed=seed)
                rm = plan_roadmap(corridor, obstacles, start)
            except (SplineplanError, ValueError) as err:
                print(f"{length:5d} m {n_obs:4d} obstacles seed {seed}: no roadmap: {err}")
                continue
            tr = plan_trajectory(rm, corridor, obstacles, None, 0.0)
            ms = _median_ms(lambda c=corridor, o=obstacles, r=rm:
                            plan_trajectory(r, c, o, None, 0.0))
            it = tr.iterations
            print(f"{length:5d} m {n_obs:4d} obstacles seed {seed}: {ms:8.1f} ms median  "
                  f"ctrl {it.control_points} refine {it.refinements} "
                  f"moves {it.tried}/{it.accepted} rounds {it.rounds}  "
                  f"v_min {tr.min_speed_before:.1f}->{tr.min_speed_after:.1f} m/s  "
                  f"feasible {tr.feasible} clearance {tr.min_clearance:.2f} m", flush=True)


if __name__ == "__main__":
    main([])
