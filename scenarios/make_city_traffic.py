"""Write ``city_traffic.rou.xml``: reproducible background traffic for ``city_traffic.toml``.

Random trips between the edges of ``sumo_nets/city.net.xml`` that a passenger car may use,
drawn with a seeded generator: departures at exponential intervals (a Poisson stream) of
mean ``--period`` seconds, origin and destination uniform over the edges, kept only where
level 1 (:func:`splineplan.route.shortest_route`) finds a route, so that SUMO can route
every trip at insertion. A tenth of the vehicles are buses (on edges buses may use).

    python scenarios/make_city_traffic.py [--seed 11] [--period 0.8] [--end 300]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))  # the package from this checkout, installed or not

from splineplan.errors import NoRouteError  # noqa: E402
from splineplan.network import load_network  # noqa: E402
from splineplan.route import shortest_route  # noqa: E402


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seed", type=int, default=11)
    ap.add_argument("--period", type=float, default=0.8, help="mean seconds between trips")
    ap.add_argument("--end", type=float, default=300.0, help="last departure [s]")
    ap.add_argument("--out", default=str(HERE / "city_traffic.rou.xml"))
    args = ap.parse_args(argv)
    rng = np.random.default_rng(args.seed)
    net = load_network(HERE.parent / "sumo_nets" / "city.net.xml")
    edges = {vc: [e for e in net.edge_ids if any(ln.allows(vc) for ln in net.lanes_of(e))]
             for vc in ("passenger", "bus")}
    lines = []
    t = 0.0
    k = 0
    while True:
        t += float(rng.exponential(args.period))
        if t > args.end:
            break
        vc = "bus" if rng.random() < 0.1 else "passenger"
        pool = edges[vc]
        while True:
            a, b = (pool[i] for i in rng.choice(len(pool), 2, replace=False))
            try:
                shortest_route(net, a, b, vclass=vc)
            except NoRouteError:
                continue
            break
        vtype = "bg_bus" if vc == "bus" else "bg_car"
        lines.append(f'    <trip id="bg{k}" type="{vtype}" depart="{t:.1f}" from="{a}" '
                     f'to="{b}" departLane="best" departSpeed="max"/>')
        k += 1
    text = "\n".join([
        '<?xml version="1.0" encoding="UTF-8"?>',
        f"<!-- Written by make_city_traffic.py (seed {args.seed}, period {args.period:g} s, "
        f"end {args.end:g} s): {k} random trips. -->",
        "<routes>",
        '    <vType id="bg_car" length="4.5" width="1.8" vClass="passenger" speedDev="0.1"/>',
        '    <vType id="bg_bus" length="12.0" width="2.5" vClass="bus" speedDev="0.05"/>',
        *lines,
        "</routes>",
        "",
    ])
    Path(args.out).write_text(text)
    print(f"{k} trips written to {args.out}")


if __name__ == "__main__":
    main()
