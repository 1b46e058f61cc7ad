"""Level 3 timing: trajectory generation (optimisation + speed profile) on the shared fields.

The roadmap comes from the real level 2 among obstacles elongated as the planner does
(:func:`splineplan.planner.elongate_for_roadmap`); level 3 checks the original obstacles.
"""

from __future__ import annotations

import statistics
import time

import numpy as np

from benchmarks.fields import obstacle_field
from splineplan.errors import SplineplanError
from splineplan.planner import elongate_for_roadmap
from splineplan.roadmap import RoadmapParams, plan_roadmap
from splineplan.trajectory import plan_trajectory

CASES = ((100, 0), (300, 0), (1000, 0), (300, 20), (300, 40))
SEEDS = (0, 1, 2, 3, 4)


def _median_ms(fn, repeat: int = 7) -> float:  # type: ignore[no-untyped-def]
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return 1e3 * statistics.median(times)


def main(argv: list[str]) -> None:
    rp = RoadmapParams(segment_length=1000.0)
    for length, n_obs in CASES:
        ms_all, feasible, vmin, ctrl = [], [], [], []
        for seed in SEEDS if n_obs else SEEDS[:1]:
            corridor, obstacles, start = obstacle_field(length, n_obs, seed=seed)
            try:
                rm = plan_roadmap(corridor, elongate_for_roadmap(corridor, obstacles, rp),
                                  start, rp)
            except SplineplanError as err:
                print(f"{length:5d} m {n_obs:4d} obstacles seed {seed}: level 2: {err}")
                continue
            tr = plan_trajectory(rm, corridor, obstacles, None, 0.0)
            ms = _median_ms(lambda c=corridor, o=obstacles, r=rm:
                            plan_trajectory(r, c, o, None, 0.0))
            it = tr.iterations
            ms_all.append(ms)
            feasible.append(tr.feasible)
            vmin.append(tr.min_speed_after)
            ctrl.append(it.control_points)
            print(f"{length:5d} m {n_obs:4d} obstacles seed {seed}: {ms:7.1f} ms median  "
                  f"ctrl {it.control_points} repair {it.refinements}/{it.doubled} "
                  f"moves {it.tried}/{it.accepted} rounds {it.rounds}  "
                  f"v_min {tr.min_speed_before:.1f}->{tr.min_speed_after:.1f} m/s  "
                  f"feasible {tr.feasible} clearance {tr.min_clearance:.2f} m", flush=True)
        if ms_all:
            print(f"== {length} m {n_obs} obstacles: median {np.median(ms_all):.1f} ms, "
                  f"control points {np.median(ctrl):.0f}, feasible {sum(feasible)}/"
                  f"{len(feasible)}, min allowed speed {min(vmin):.1f} m/s", flush=True)


if __name__ == "__main__":
    main([])
