"""Level 1 benchmark: splineplan's route query against sumolib and SUMO's C++ router.

In one process and on the same seeded random origin-destination pairs, times
``splineplan.route.shortest_route``, ``sumolib``'s ``getShortestPath`` and
``libsumo.simulation.findRoute`` (every edge's travel time, junction edges' too, set to its
length, so all three minimise length), checks they agree on length, and prints medians and
ratios. Runs on the Monaco network of ../shared/data (skipped with a message if absent)
and on a generated grid of >= 50,000 edges; also times loading a network against
``sumolib.net.readNet``.

``python -m benchmarks route`` or ``python -m benchmarks.bench_route [--pairs N]
[--skip-large]``
"""

from __future__ import annotations

import argparse
import contextlib
import itertools
import random
import statistics
import subprocess
import tempfile
import time
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parent.parent
MONACO = ROOT.parent / "shared" / "data" / "monaco.net.xml.gz"


def _median_ms(times: list[float]) -> float:
    return 1e3 * statistics.median(times)


def bench_network(path: Path, pairs: int, seed: int, *, sumolib_pairs: int | None = None) -> None:
    """Time the three routers on one network and print the figures."""
    import libsumo
    import sumolib

    from splineplan.errors import NoRouteError
    from splineplan.network import load_network
    from splineplan.route import shortest_route

    t0 = time.perf_counter()
    net = load_network(path)
    t_load = time.perf_counter() - t0
    t0 = time.perf_counter()
    sn = sumolib.net.readNet(str(path), withInternal=True)
    t_sumolib_load = time.perf_counter() - t0
    print(f"{path.name}: {net.n_edges} edges; load_network {t_load:.2f} s, "
          f"sumolib.net.readNet(withInternal=True) {t_sumolib_load:.2f} s "
          f"(ratio {t_load / t_sumolib_load:.2f})")

    rng = random.Random(seed)
    usable = [e for e in net.edge_ids if net.allows(e, "passenger")]
    od = [(rng.choice(usable), rng.choice(usable)) for _ in range(pairs)]
    t0 = time.perf_counter()
    net.graph("passenger")
    with contextlib.suppress(NoRouteError):
        shortest_route(net, usable[0], usable[-1])
    print(f"  first query (builds the class graph and landmarks): "
          f"{time.perf_counter() - t0:.2f} s")

    ours: dict[tuple[str, str], float | None] = {}
    t_ours = []
    for a, b in od:
        t0 = time.perf_counter()
        try:
            ours[a, b] = shortest_route(net, a, b).length
        except NoRouteError:
            ours[a, b] = None
        t_ours.append(time.perf_counter() - t0)

    n_sl = len(od) if sumolib_pairs is None else min(sumolib_pairs, len(od))
    theirs: dict[tuple[str, str], float | None] = {}
    t_sl = []
    for a, b in od[:n_sl]:
        ea, eb = sn.getEdge(a), sn.getEdge(b)
        t0 = time.perf_counter()
        p, c = sn.getShortestPath(ea, eb, vClass="passenger")
        t_sl.append(time.perf_counter() - t0)
        theirs[a, b] = None if p is None else c
        if sn._routingCache is not None:  # time fresh searches, not cache hits
            sn._routingCache.cache_clear()

    found: dict[tuple[str, str], Any] = {}
    t_fr = []
    libsumo.start(["sumo", "-n", str(path), "--no-step-log", "--no-warnings"])
    try:
        for e, length in zip(net.edge_ids, net.lengths.tolist(), strict=True):
            libsumo.edge.adaptTraveltime(e, length)
        for e in libsumo.edge.getIDList():  # junction lanes count too, as in sumolib
            if e.startswith(":"):
                libsumo.edge.adaptTraveltime(e, libsumo.lane.getLength(f"{e}_0"))
        for a, b in od:
            t0 = time.perf_counter()
            r = libsumo.simulation.findRoute(a, b, vType="DEFAULT_VEHTYPE")
            t_fr.append(time.perf_counter() - t0)
            found[a, b] = r
    finally:
        libsumo.close()

    agree_sl = sum(1 for k in theirs if (theirs[k] is None) == (ours[k] is None)
                   and (theirs[k] is None or abs(theirs[k] - ours[k]) <= 1e-6 * max(1, theirs[k])))
    agree_fr = same_fr = 0
    for k, r in found.items():
        if not r.edges or ours[k] is None:
            agree_fr += (not r.edges) == (ours[k] is None)
            continue
        # findRoute's own length leaves out the first edge; compare in one convention
        theirs_len = shortest_route_length(net, k, tuple(r.edges))
        agree_fr += abs(theirs_len - ours[k]) <= 1e-6 * max(1.0, ours[k])
        same_fr += tuple(r.edges) == shortest_route(net, *k).edges
    m_ours, m_sl, m_fr = _median_ms(t_ours), _median_ms(t_sl), _median_ms(t_fr)
    print(f"  {len(od)} pairs ({sum(v is not None for v in ours.values())} with a route), "
          f"medians: splineplan {m_ours:.3f} ms, sumolib {m_sl:.3f} ms ({n_sl} pairs), "
          f"libsumo findRoute {m_fr:.3f} ms")
    print(f"  ratios: splineplan / findRoute {m_ours / m_fr:.3f}, "
          f"splineplan / sumolib {m_ours / m_sl:.4f}")
    print(f"  agreement on length: sumolib {agree_sl}/{n_sl}, findRoute "
          f"{agree_fr}/{len(found)} (same edges {same_fr})")


def shortest_route_length(net: Any, key: tuple[str, str], edges: tuple[str, ...]) -> float:
    """Length [m] of an edge list in splineplan's convention (internal lanes included)."""
    length = net.length_of(edges[0])
    for a, b in itertools.pairwise(edges):
        vias = [c for c in net.connections_between(a, b, vclass="passenger") if c.via]
        if vias:
            length += min(sum(net.internal_lane(v).length for v in c.via) for c in vias)
        length += net.length_of(b)
    return float(length)


def make_large(tmp: Path, *, side: int = 113) -> Path:
    """A grid of side x side junctions (>= 50,000 edges) built with netgenerate."""
    out = tmp / f"grid{side}.net.xml"
    subprocess.run(["netgenerate", "--grid", "--grid.number", str(side), "--grid.length",
                    "100", "--no-turnarounds", "true", "--default.lanewidth", "3.2",
                    "--no-warnings", "true", "--output-file", str(out)],
                   check=True, capture_output=True)
    return out


def main(argv: list[str]) -> int:
    ap = argparse.ArgumentParser(prog="python -m benchmarks route")
    ap.add_argument("--pairs", type=int, default=500)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--skip-large", action="store_true")
    args = ap.parse_args(argv)
    if MONACO.exists():
        bench_network(MONACO, args.pairs, args.seed)
    else:
        print(f"Monaco network not found at {MONACO}: skipped")
    if not args.skip_large:
        with tempfile.TemporaryDirectory() as tmp:
            big = make_large(Path(tmp))
            bench_network(big, min(args.pairs, 100), args.seed, sumolib_pairs=20)
    return 0


if __name__ == "__main__":
    import sys

    sys.exit(main(sys.argv[1:]))
