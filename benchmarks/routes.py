"""Seeded random routes with no turnaround, the draw the route benchmarks share.

``bench_feasible`` plans them open loop, ``bench_drive`` drives them closed loop; both take
the same pairs for the same seed. A pair of edges the passenger class may use, drawn with
``random.Random(seed)``, is kept when the shortest route without turnarounds
(:func:`splineplan.route.shortest_route`) is within the network's range of lengths
(:data:`NETS`, at most :data:`LONGEST`) and the route ``splineplan.pipeline.plan`` plans
with its defaults and no obstacles needs no turnaround (it may differ from the shortest one:
it avoids turns too tight for the car and closed edges). A pair whose plan raises counts
as a route too, with its error.
"""

from __future__ import annotations

import random
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parent.parent
#: Network file and shortest route length [m] of each network (Monaco in ``../shared/data``).
NETS = {"city": (ROOT / "sumo_nets" / "city.net.xml", 300.0),
        "grid": (ROOT / "sumo_nets" / "grid.net.xml", 300.0),
        "monaco": (ROOT.parent / "shared" / "data" / "monaco.net.xml.gz", 500.0)}
#: Longest route [m].
LONGEST = 3000.0
#: Pairs drawn per route asked for before the draw gives up.
TRIES_PER_ROUTE = 500


@dataclass(frozen=True)
class RandomRoute:
    """One drawn route: its edges' ids, the length [m] of the shortest route without
    turnarounds between them, the open-loop plan (``None`` where planning raised) and the
    error (a :class:`~splineplan.errors.SplineplanError`) where it did."""

    from_edge: str
    to_edge: str
    length: float
    plan: Any
    error: Exception | None = None


def random_routes(net: Any, n_routes: int, seed: int, shortest: float,
                  longest: float = LONGEST, roadmap_params: Any = None
                  ) -> Iterator[RandomRoute]:
    """Up to ``n_routes`` seeded random routes of ``shortest``-``longest`` [m] on ``net``
    (a :class:`~splineplan.network.RoadNetwork`) that need no turnaround, in draw order,
    planned with ``roadmap_params`` (default: level 2's defaults)."""
    from splineplan.errors import SplineplanError
    from splineplan.pipeline import plan, turnarounds
    from splineplan.route import shortest_route

    rng = random.Random(seed)
    usable = [e for e in net.edge_ids if net.allows(e, "passenger")]
    found = tries = 0
    while found < n_routes and tries < TRIES_PER_ROUTE * n_routes:
        tries += 1
        a, b = rng.choice(usable), rng.choice(usable)
        try:
            length = shortest_route(net, a, b, turnarounds=False).length
        except SplineplanError:
            continue
        if not shortest <= length <= longest:
            continue
        try:
            p = plan(net, a, b, roadmap_params=roadmap_params)
        except SplineplanError as err:
            found += 1
            yield RandomRoute(a, b, length, None, err)
            continue
        if turnarounds(net, p.route):
            continue
        found += 1
        yield RandomRoute(a, b, length, p)
