"""Feasible plans on seeded random routes: how often levels 1-3 give a trajectory a car can drive.

``python -m benchmarks feasible [--routes N] [--seed S] [--nets city grid monaco] [--place]``.
Random pairs of edges the passenger class may use, routed without turnarounds
(:func:`splineplan.route.shortest_route`); kept when the route is 0.3-3 km long on the
bundled networks and 0.5-3 km on Monaco (``../shared/data``, skipped when absent), and when
the planned route needs no turnaround (the draw of :mod:`benchmarks.routes`, which
``bench_drive`` shares). ``splineplan.pipeline.plan`` plans each with its defaults and no
obstacles. Printed per network: routes, feasible, those whose route takes a junction turn
or an edge's bend that level 1 finds too tight for the car (``Route.tight_turns``,
``Route.tight_bends``) and feasible among the others, and the first limit each infeasible
plan breaks.
"""

from __future__ import annotations

import argparse
import collections
import logging
import time
from pathlib import Path

from benchmarks.routes import LONGEST, NETS, random_routes


def bench_network(path: Path, shortest: float, n_routes: int, seed: int,
                  place: bool = False) -> dict[str, int]:
    """Plan ``n_routes`` random routes on one network (``place``: level 2 places the
    vertices, ``RoadmapParams(place=True)``); print and return the counts."""
    from splineplan.network import load_network
    from splineplan.roadmap import RoadmapParams

    net = load_network(path)
    counts = collections.Counter[str]()
    broken = collections.Counter[str]()
    t0 = time.perf_counter()
    for r in random_routes(net, n_routes, seed, shortest,
                           roadmap_params=RoadmapParams(place=place)):
        counts["routes"] += 1
        if r.plan is None:
            broken[f"error ({type(r.error).__name__})"] += 1
            continue
        tight = bool(r.plan.route.tight_turns or r.plan.route.tight_bends)
        counts["tight"] += tight
        if r.plan.trajectory.feasible:
            counts["feasible"] += 1
            counts["feasible_fit"] += not tight
        else:
            v = r.plan.trajectory.violations
            broken[v[0].kind if v else "unknown"] += 1
    n, ok = counts["routes"], counts["feasible"]
    fit = n - counts["tight"]
    print(f"{path.name}: {n} routes of {shortest / 1e3:.1f}-{LONGEST / 1e3:.0f} km with no "
          f"turnaround: feasible {ok} ({100.0 * ok / max(n, 1):.0f} %); {counts['tight']} take "
          f"a turn or bend too tight for the car, feasible among the other {fit}: "
          f"{counts['feasible_fit']} ({100.0 * counts['feasible_fit'] / max(fit, 1):.0f} %); "
          f"infeasible by the first limit broken: {dict(broken) or '-'} "
          f"({time.perf_counter() - t0:.0f} s)", flush=True)
    return dict(counts)


def main(argv: list[str]) -> int:
    ap = argparse.ArgumentParser(prog="python -m benchmarks feasible", description=__doc__)
    ap.add_argument("--routes", type=int, default=None,
                    help="routes per network (20 on city and grid, 100 on Monaco)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--nets", nargs="+", default=list(NETS), choices=list(NETS))
    ap.add_argument("--place", action="store_true",
                    help="level 2 places the vertices (RoadmapParams(place=True))")
    args = ap.parse_args(argv)
    logging.disable(logging.WARNING)  # the pipeline's warnings about tight turns
    for name in args.nets:
        path, shortest = NETS[name]
        if not path.exists():
            print(f"{name}: {path} not found, skipped")
            continue
        bench_network(path, shortest, args.routes or (100 if name == "monaco" else 20),
                      args.seed, args.place)
    return 0


if __name__ == "__main__":
    import sys

    sys.exit(main(sys.argv[1:]))
