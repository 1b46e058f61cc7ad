"""Levels 2 and 3 judged by the kinematic oracle on random obstacle fields.

``python -m benchmarks oracle [--fields N] [--seed S] [--place]``. Each field is a straight or
curved road of 2 to 4 lanes with parked cars, trucks and cones; the vehicle starts at
10 m/s with ``s_max`` 15 m/s. The planner (:func:`splineplan.planner.plan_corridor`) is
compared with the oracle (:mod:`benchmarks.kinematic_oracle`: hybrid A* with the car's
footprint and turning limit), which gives the best clearance any forward path of the car
keeps. Printed, as the planner's targets state them:

- passable fields (the oracle keeps the safety margin plus 0.05 m): the share the planner
  plans feasibly;
- impassable fields (the oracle cannot keep the margin): the share the planner reports
  blocked (or at least not feasible);
- where the best clearance is at most 1 m: the planner's minimum clearance over the
  oracle's best (median, and the share at 0.85 or more).
"""

from __future__ import annotations

import argparse
import math
import time

import numpy as np
from shapely.geometry import Polygon

from benchmarks.kinematic_oracle import Search, best_clearance, error
from splineplan.corridor import Corridor
from splineplan.errors import RoadBlockedError, TrajectoryError
from splineplan.obstacles import Obstacles
from splineplan.planner import plan_corridor
from splineplan.roadmap import RoadmapParams
from splineplan.trajectory import TrajectoryParams

#: Obstacle kinds: length and width [m].
KINDS = {"car": (4.5, 1.8), "truck": (10.0, 2.5), "cone": (0.4, 0.4)}
LANE = 3.2
LENGTH = 120.0


def random_field(rng: np.random.Generator) -> tuple[Corridor, Obstacles]:
    """A road of 2-4 lanes, straight or an arc of radius 80-300 m, ``LENGTH`` [m] long,
    with 1-6 obstacles (cars, trucks, cones) between 25 m in and 15 m before the end."""
    lanes = int(rng.integers(2, 5))
    half = lanes * LANE / 2.0
    n = 300
    if rng.random() < 0.5:
        ref = np.column_stack((np.linspace(0.0, LENGTH, n), np.zeros(n)))
    else:
        radius = float(rng.uniform(80.0, 300.0)) * (1 if rng.random() < 0.5 else -1)
        th = np.linspace(0.0, LENGTH / radius, n)
        ref = np.column_stack((radius * np.sin(th), radius * (1.0 - np.cos(th))))
    cor = Corridor.from_reference(ref, np.full(n, half), np.full(n, -half))
    k = int(rng.integers(1, 7))
    kinds = rng.choice(list(KINDS), k, p=[0.6, 0.2, 0.2])
    st = rng.uniform(25.0, LENGTH - 15.0, k)
    sizes = np.array([KINDS[x] for x in kinds])
    lat = rng.uniform(-half + sizes[:, 1] / 2, half - sizes[:, 1] / 2)
    heads = cor.heading_at(st) + rng.uniform(-0.1, 0.1, k)
    return cor, Obstacles.from_boxes(cor.to_xy(st, lat), heads, sizes[:, 0], sizes[:, 1],
                                     ids=[str(x) for x in kinds])


def extended_road(cor: Corridor, extra: float = 8.0) -> Polygon:
    """The corridor's area, extended straight past both ends by ``extra`` [m]."""
    left, right = cor.left_xy(), cor.right_xy()
    h0, h1 = float(cor.heading_at(0.0)), float(cor.heading_at(cor.length))
    back = extra * np.array([math.cos(h0), math.sin(h0)])
    ahead = extra * np.array([math.cos(h1), math.sin(h1)])
    left = np.vstack((left[0] - back, left, left[-1] + ahead))
    right = np.vstack((right[0] - back, right, right[-1] + ahead))
    return Polygon(np.vstack((right, left[::-1])))


def goal_region(cor: Corridor) -> Polygon:
    """The last 6 m of the corridor."""
    s = np.linspace(cor.length - 6.0, cor.length, 8)
    lo, hi = cor.bounds_at(s)
    return Polygon(np.vstack((cor.to_xy(s, lo), cor.to_xy(s[::-1], hi[::-1]))))


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(prog="python -m benchmarks oracle")
    ap.add_argument("--fields", type=int, default=30)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--place", action="store_true",
                    help="level 2 places the vertices (RoadmapParams(place=True))")
    args = ap.parse_args(argv)
    rng = np.random.default_rng(args.seed)
    rp = RoadmapParams(place=args.place)
    tp = TrajectoryParams(s_max=15.0)
    search = Search(step=0.05)
    rows = []
    t0 = time.perf_counter()
    for i in range(args.fields):
        cor, obs = random_field(rng)
        lo, hi = cor.bounds_at(np.array([1.0]))
        start = cor.to_xy(np.array([1.0]), np.array([rng.uniform(lo[0] + 1.2, hi[0] - 1.2)]))[0]
        heading = float(cor.heading_at(1.0))
        try:
            plan = plan_corridor(cor, obs, start, heading, roadmap_params=rp, params=tp,
                                 start_speed=10.0, end_speed=None)
            tr = plan.trajectory
            verdict = "feasible" if tr.feasible else "infeasible"
            clear = float(np.min(tr.clearance_obstacles))
        except (RoadBlockedError, TrajectoryError):
            verdict, clear = "blocked", float("nan")
        best = best_clearance(extended_road(cor), [Polygon(p) for p in obs.polygons()],
                              (float(start[0]), float(start[1]), heading), goal_region(cor),
                              upper=3.0, search=search)
        rows.append((verdict, clear, best))
        print(f"field {i:3d}: planner {verdict:>10} (clearance {clear:5.2f} m), oracle's "
              f"best {best:5.2f} m", flush=True)
    margin = rp.safety_margin
    passable = [r for r in rows if r[2] >= margin + 0.05]
    impassable = [r for r in rows if r[2] < margin - error(search)]
    tight = [r for r in passable if r[2] <= 1.0 and r[0] == "feasible"]
    ratio = np.array([min(r[1], 3.0) / r[2] for r in tight])
    print(f"\n{len(rows)} fields in {time.perf_counter() - t0:.0f} s (oracle error "
          f"{error(search):.2f} m)")
    if passable:
        ok = sum(r[0] == "feasible" for r in passable)
        print(f"passable ({len(passable)}): planner feasible on {ok} "
              f"({100 * ok / len(passable):.0f} %; target 99 %), blocked on "
              f"{sum(r[0] == 'blocked' for r in passable)}")
    if impassable:
        blocked = sum(r[0] == "blocked" for r in impassable)
        bad = sum(r[0] == "feasible" for r in impassable)
        print(f"impassable ({len(impassable)}): planner blocked on {blocked} "
              f"({100 * blocked / len(impassable):.0f} %; target 99 %), feasible on {bad}")
    if len(ratio):
        print(f"best clearance <= 1 m ({len(ratio)} planned feasibly): planner / oracle "
              f"median {np.median(ratio):.2f}, at least 0.85 on "
              f"{100 * np.mean(ratio >= 0.85):.0f} % (target: all)")
