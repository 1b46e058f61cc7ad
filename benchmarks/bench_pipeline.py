"""The three levels together: ``splineplan.pipeline.plan`` on ~2 km routes with obstacles.

Picks seeded random origin-destination pairs whose shortest route is 1.8-2.2 km long, parks
cars along the route (one every ``spacing`` metres, in a random lane of the edges that have
two lanes or more, so no road is closed), and times level 1, 2 and 3 and their sum. Runs on
the Monaco network of ../shared/data when present, else on a generated grid (netgenerate),
and prints medians and how the time grows with route length and obstacle count.

``python -m benchmarks pipeline`` or ``python -m benchmarks.bench_pipeline [--routes N] [--place]``
"""

from __future__ import annotations

import argparse
import random
import statistics
import subprocess
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
MONACO = ROOT.parent / "shared" / "data" / "monaco.net.xml.gz"


def parked_cars(net: Any, route: Any, spacing: float, rng: random.Random) -> Any:
    """Cars (4.5 x 1.8 m) parked along a route, one per ``spacing`` [m], never closing it."""
    from splineplan.network import _lane_point
    from splineplan.obstacles import Obstacles

    pos, head = [], []
    for edge in route.edges:
        lanes = [ln for ln in net.lanes_of(edge) if ln.allows("passenger")]
        if len(lanes) < 2:
            continue
        for s in np.arange(spacing / 2.0, net.length_of(edge) - 10.0, spacing):
            lane = rng.choice(lanes)
            xy, h = _lane_point(lane, float(s))
            pos.append(xy)
            head.append(h)
    if not pos:
        return Obstacles.empty()
    return Obstacles.from_boxes(np.array(pos), np.array(head), 4.5, 1.8)


def bench_network(path: Path, n_routes: int, seed: int, spacing: float,
                  place: bool = False) -> dict[str, float]:
    """Time the pipeline on ``n_routes`` routes of about 2 km (``place``: level 2 places
    the vertices); print and return medians."""
    from splineplan.errors import SplineplanError
    from splineplan.network import load_network
    from splineplan.pipeline import plan, turnarounds
    from splineplan.roadmap import RoadmapParams
    from splineplan.route import shortest_route

    net = load_network(path)
    rng = random.Random(seed)
    usable = [e for e in net.edge_ids if net.allows(e, "passenger")]
    rows: list[tuple[float, int, float, float, float, float]] = []
    feasible: list[bool] = []
    turning: list[bool] = []  # the route turns back (a dead end): no forward-only path
    failures: list[str] = []
    tries = 0
    while len(rows) < n_routes and tries < 200 * n_routes:
        tries += 1
        a, b = rng.choice(usable), rng.choice(usable)
        try:
            route = shortest_route(net, a, b)
        except SplineplanError:
            continue
        if not 1800.0 <= route.length <= 2200.0:
            continue
        obstacles = parked_cars(net, route, spacing, rng)
        times = []
        try:
            for _ in range(3):
                p = plan(net, a, b, obstacles, roadmap_params=RoadmapParams(place=place))
                times.append((p.total_seconds, p.route_seconds, p.roadmap_seconds,
                              p.trajectory_seconds))
        except SplineplanError as err:
            failures.append(f"{a} -> {b}: {err}")
            continue
        best = min(times)
        rows.append((route.length, len(obstacles), *best))
        feasible.append(bool(p.trajectory.feasible))
        turning.append(bool(turnarounds(net, p.route)))
    if not rows:
        print(f"{path.name}: no route planned ({len(failures)} failures)")
        return {}
    arr = np.array(rows)
    med = {name: 1e3 * float(np.median(arr[:, i]))
           for i, name in enumerate(("total", "level1", "level2", "level3"), start=2)}
    med["feasible"] = sum(feasible) / len(feasible)
    print(f"{path.name}: {len(rows)} routes of {arr[:, 0].min():.0f}-{arr[:, 0].max():.0f} m, "
          f"{int(arr[:, 1].min())}-{int(arr[:, 1].max())} parked cars; medians: "
          f"total {med['total']:.1f} ms (level 1 {med['level1']:.2f}, level 2 "
          f"{med['level2']:.1f}, level 3 {med['level3']:.1f}); planning failed on "
          f"{len(failures)} of {len(rows) + len(failures)} routes; trajectory feasible on "
          f"{sum(feasible)} of {len(feasible)}")
    forward = [f for f, t in zip(feasible, turning, strict=True) if not t]
    if len(forward) < len(feasible):
        fwd_total = [r[2] for r, t in zip(rows, turning, strict=True) if not t]
        med["forward_total"] = 1e3 * float(np.median(fwd_total)) if fwd_total else np.nan
        print(f"  {len(feasible) - len(forward)} of the routes must turn back (every route "
              f"between their edges has a U-turn, which forward planning cannot drive); "
              f"the other {len(forward)}: median total {med['forward_total']:.1f} ms, "
              f"feasible on {sum(forward)}")
    for f in failures[:5]:
        print(f"  failed: {f}")
    per_km = 1e3 * arr[:, 2] / (arr[:, 0] / 1e3)
    print(f"  per km of route: median {statistics.median(per_km):.1f} ms")
    return med


def _grid(tmp: Path) -> Path:
    out = tmp / "grid.net.xml"
    subprocess.run(["netgenerate", "--grid", "--grid.number", "8", "--grid.length", "300",
                    "--default.lanenumber", "2", "--no-turnarounds", "-o", str(out)],
                   check=True, capture_output=True)
    return out


def main(argv: list[str]) -> int:
    ap = argparse.ArgumentParser(prog="bench_pipeline", description=__doc__)
    ap.add_argument("--routes", type=int, default=15)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--spacing", type=float, default=50.0,
                    help="metres of route per parked car (50)")
    ap.add_argument("--place", action="store_true",
                    help="level 2 places the vertices (RoadmapParams(place=True))")
    args = ap.parse_args(argv)
    if MONACO.exists():
        bench_network(MONACO, args.routes, args.seed, args.spacing, args.place)
    else:
        print(f"Monaco network not found at {MONACO}: using a generated grid")
    with tempfile.TemporaryDirectory() as tmp:
        grid = _grid(Path(tmp))
        for spacing in (100.0, args.spacing, args.spacing / 2.0):
            print(f"-- grid, one parked car per {spacing:.0f} m")
            bench_network(grid, args.routes, args.seed, spacing, args.place)
    return 0


if __name__ == "__main__":
    import sys

    sys.exit(main(sys.argv[1:]))
