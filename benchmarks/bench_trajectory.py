"""Level 3 timing: trajectory generation (optimisation + speed profile) on the shared fields.

The roadmap comes from the real level 2 among obstacles elongated as the planner does
(:func:`splineplan.planner.elongate_for_roadmap`); level 3 checks the original obstacles.
Cases: 300 m with 0/20/40 obstacles (80 do not fit on 300 m with a passage: 80 run on
400 m), empty roads of 100/300/1000 m, and levels 2+3 along a 2 km field cut into
segments (:func:`splineplan.planner.plan_corridor`).
"""

from __future__ import annotations

import statistics
import time

import numpy as np

from benchmarks.fields import obstacle_field
from splineplan.errors import SplineplanError
from splineplan.planner import elongate_for_roadmap, plan_corridor
from splineplan.roadmap import RoadmapParams, plan_roadmap
from splineplan.trajectory import plan_trajectory

CASES = ((100, 0), (300, 0), (1000, 0), (300, 20), (300, 40), (400, 80))
SEEDS = (0, 1, 2, 3, 4, 5, 6, 7)
REPEAT = 11


def _median_ms(fn, repeat: int = REPEAT) -> float:  # type: ignore[no-untyped-def]
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return 1e3 * statistics.median(times)


def main(argv: list[str]) -> None:
    rp = RoadmapParams(segment_length=1000.0)
    for length, n_obs in CASES:
        ms_all, feasible, vmin, ctrl, moves = [], [], [], [], []
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
            moves.append(it.tried)
            print(f"{length:5d} m {n_obs:4d} obstacles seed {seed}: {ms:7.1f} ms median  "
                  f"ctrl {it.control_points} repair {it.refinements}/{it.doubled} "
                  f"moves {it.tried}/{it.accepted} rounds {it.rounds}  "
                  f"v_min {tr.min_speed_before:.1f}->{tr.min_speed_after:.1f} m/s  "
                  f"feasible {tr.feasible} clearance {tr.min_clearance:.2f} m", flush=True)
        if ms_all:
            print(f"== {length} m {n_obs} obstacles: median {np.median(ms_all):.1f} ms "
                  f"(range {min(ms_all):.1f}-{max(ms_all):.1f}), control points "
                  f"{np.median(ctrl):.0f}, moves {np.median(moves):.0f}, feasible "
                  f"{sum(feasible)}/{len(feasible)}, min allowed speed {min(vmin):.1f} m/s",
                  flush=True)
    # levels 2 + 3 along 2 km (segments of 300 m), 40 obstacles per 300 m
    tot, l2, l3, feas = [], [], [], []
    for seed in SEEDS[:5]:
        corridor, obstacles, start = obstacle_field(2000.0, 260, seed=seed)
        try:
            plan_corridor(corridor, obstacles, start, 0.0)
        except SplineplanError as err:
            print(f" 2000 m  260 obstacles seed {seed}: {err}")
            continue
        runs = []
        for _ in range(5):
            t0 = time.perf_counter()
            res = plan_corridor(corridor, obstacles, start, 0.0)
            runs.append((time.perf_counter() - t0, res.roadmap_seconds,
                         res.trajectory_seconds))
        t, a, b = (1e3 * statistics.median(x) for x in zip(*runs, strict=True))
        tot.append(t)
        l2.append(a)
        l3.append(b)
        feas.append(res.trajectory.feasible)
        print(f" 2000 m  260 obstacles seed {seed}: plan_corridor {t:6.1f} ms median "
              f"(level 2 {a:.1f}, level 3 {b:.1f}) feasible {res.trajectory.feasible}",
              flush=True)
    if tot:
        print(f"== 2000 m 260 obstacles, plan_corridor: median {np.median(tot):.1f} ms "
              f"(level 2 {np.median(l2):.1f}, level 3 {np.median(l3):.1f}), feasible "
              f"{sum(feas)}/{len(feas)}", flush=True)


if __name__ == "__main__":
    main([])
