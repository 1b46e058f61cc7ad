"""Level 1, road selection: Dijkstra over the edge graph of a SUMO network.

The paper searches a graph of intersections and roads weighted by length. Here a vertex is
a SUMO edge and an arc is a connection the vehicle class may use (see
:mod:`splineplan.network`), so that forbidden turns stay forbidden. Route lengths follow
sumolib's convention, given in :mod:`splineplan.network`: the first edge from ``start_pos``
on, every later edge in full, plus the internal (junction) lanes between them.

The search is Dijkstra's with a binary heap that stops at the goal, guided by landmark
lower bounds (ALT: 16 landmarks per class graph and weight, built on the first query and
cached); the bounds are exact lower bounds, so the route is still a least-cost one.
"""

from __future__ import annotations

import heapq
import itertools
import logging
import weakref
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from splineplan.errors import NoRouteError, ParameterError, VehicleClassError
from splineplan.geometry import FloatArray
from splineplan.network import (
    CarShape,
    ClassGraph,
    RoadNetwork,
    bend_fits,
    searched_path,
    turn_fits,
)

log = logging.getLogger(__name__)

#: What a route may minimise: metres or seconds.
WEIGHTS = ("length", "time")


@dataclass(frozen=True)
class Route:
    """A road-level route.

    Attributes
    ----------
    edges
        SUMO edge ids from the origin edge to the destination edge (no internal edges).
    length
        Length [m] from ``start_pos`` on the first edge to the end of the last edge,
        including the junction lanes between edges (sumolib's convention).
    cost
        What was minimised: ``length`` [m] or travel time [s] at the speed limits.
    weight
        ``"length"`` or ``"time"``.
    vclass
        The vehicle class the route is for.
    start_pos
        Position [m] on the first edge the route starts at.
    tight_turns
        Turns ``(from_edge, to_edge)`` of the route that the car asked for cannot make
        within the paving (:func:`splineplan.network.turn_fits`): taken only where no
        route avoids them; empty where no car was given.
    tight_bends
        Edges of the route whose own bends the car cannot follow within their lanes
        (:func:`splineplan.network.bend_fits`): the origin and destination, or others
        where no route avoids them; empty where no car was given.
    """

    edges: tuple[str, ...]
    length: float
    cost: float
    weight: str
    vclass: str
    start_pos: float = 0.0
    tight_turns: tuple[tuple[str, str], ...] = ()
    tight_bends: tuple[str, ...] = ()

    @property
    def origin(self) -> str:
        """The first edge."""
        return self.edges[0]

    @property
    def destination(self) -> str:
        """The last edge."""
        return self.edges[-1]


def shortest_route(
    network: RoadNetwork,
    from_edge: str,
    to_edge: str,
    *,
    vclass: str = "passenger",
    weight: str = "length",
    avoid: Iterable[str] = (),
    start_pos: float = 0.0,
    turnarounds: bool = True,
    car: CarShape | None = None,
    avoid_limit_turns: bool = False,
) -> Route:
    """The least-cost route from ``from_edge`` to ``to_edge`` for vehicle class ``vclass``.

    Parameters
    ----------
    network
        The road network.
    from_edge, to_edge
        Origin and destination edge ids (normal edges).
    vclass
        SUMO vehicle class.
    weight
        ``"length"`` minimises metres, ``"time"`` travel time at the speed limits [s].
    avoid
        Edge ids the route must not use (e.g. found blocked).
    start_pos
        Position [m] along the origin edge, in ``[0, length]``; the route's length and
        cost count from there.
    turnarounds
        Whether the route may turn back onto the reverse edge where the only connection
        for that step is a turnaround (SUMO direction ``t``). Planners that drive forward
        only pass ``False``; the route is then the least-cost one without such a step.
    car
        The vehicle's footprint and turning radius. Where given, the route avoids junction
        turns that this car cannot make within the paving (:func:`~splineplan.network.
        turn_fits`) and edges whose bends it cannot follow within their lanes
        (:func:`~splineplan.network.bend_fits`), each tested on the routes found and
        cached per network and car: it is the least-cost route without them where one
        exists; where none does, the least-cost route, with a logged warning and
        :attr:`Route.tight_turns` and :attr:`Route.tight_bends` naming them.
    avoid_limit_turns
        With ``car``: avoid also the turns the car makes only on a path that level 1
        searched for, at its turning limit (:func:`~splineplan.network.searched_path`),
        where a route without them exists.

    Raises
    ------
    UnknownEdgeError
        An edge id (origin, destination or in ``avoid``) is not in the network.
    VehicleClassError
        ``vclass`` is unknown, or may not use the origin or destination edge.
    ParameterError
        ``weight`` or ``start_pos`` is out of range.
    NoRouteError
        No route leads from origin to destination (also when either is avoided).
    """
    if weight not in WEIGHTS:
        raise ParameterError(f"weight must be one of {', '.join(WEIGHTS)}, got {weight!r}")
    graph = network.graph(vclass)  # checks vclass
    src = network.edge_index(from_edge)
    dst = network.edge_index(to_edge)
    blocked = {network.edge_index(e) for e in avoid}
    for name, i in (("origin", src), ("destination", dst)):
        if not graph.usable[i]:
            raise VehicleClassError(
                f"vehicle class '{vclass}' may not use {name} edge '{network.edge_ids[i]}'")
    first_len = float(network.lengths[src])
    start_pos = float(start_pos)
    if not 0.0 <= start_pos <= first_len:
        raise ParameterError(
            f"start_pos {start_pos:g} m is outside edge '{from_edge}' [0, {first_len:g}] m")
    for name, i in (("origin", src), ("destination", dst)):
        if i in blocked:
            raise NoRouteError(f"no route from edge '{from_edge}' to edge '{to_edge}': "
                               f"the {name} edge '{network.edge_ids[i]}' is to be avoided")

    search = _search(network, graph, weight)
    adjacency = search.adjacency if turnarounds else _forward(network, graph, search)
    # the landmark bounds hold on the graph without turnarounds too (it only loses arcs)
    potential = search.potential(src, dst)
    path = dijkstra(adjacency, src, dst, blocked, potential)
    tight: list[tuple[int, int]] = []
    bends: list[int] = []
    if path is not None and car is not None:
        # with avoid_limit_turns, turns the car makes only at its turning limit are
        # avoided too where a route does; where none does, only those it cannot make
        found = _without_tight_turns(network, vclass, car, adjacency, path, blocked,
                                     potential, avoid_limit_turns=avoid_limit_turns)
        if found[1] and avoid_limit_turns:
            found = _without_tight_turns(network, vclass, car, adjacency, path, blocked,
                                         potential)
        path, tight, bends = found
    if path is None:
        msg = (f"no route from edge '{from_edge}' to edge '{to_edge}' "
               f"for vehicle class '{vclass}'")
        if not turnarounds:
            msg += " without turnarounds"
        if blocked:
            names = sorted(network.edge_ids[i] for i in blocked)
            shown = ", ".join(names[:10]) + (", ..." if len(names) > 10 else "")
            msg += f" avoiding {len(names)} edge(s): {shown}"
        raise NoRouteError(msg)

    length, time = _path_totals(network, graph, path)
    length -= start_pos
    time -= start_pos / float(network.speeds[src])
    cost = length if weight == "length" else time
    edges = tuple(network.edge_ids[i] for i in path)
    log.debug("route %s -> %s: %d edges, %.1f m", from_edge, to_edge, len(edges), length)
    turns = tuple((network.edge_ids[u], network.edge_ids[v]) for u, v in tight)
    if turns:
        where = "; ".join(
            f"at junction '{network.to_nodes[u] if network.to_nodes else '?'}' from edge "
            f"'{a}' to edge '{b}'" for (a, b), (u, _) in zip(turns, tight, strict=True))
        log.warning("route %s -> %s takes %d turn(s) too tight for the car (%s), as no route "
                    "avoids them: %s", from_edge, to_edge, len(turns), car, where)
    bent = tuple(network.edge_ids[i] for i in bends)
    if bent:
        log.warning("route %s -> %s takes %d edge(s) with a bend too tight for the car (%s), "
                    "as no route avoids them: %s", from_edge, to_edge, len(bent), car,
                    ", ".join(f"'{e}'" for e in bent))
    return Route(edges=edges, length=length, cost=cost, weight=weight, vclass=vclass,
                 start_pos=start_pos, tight_turns=turns, tight_bends=bent)


def forward_route(
    network: RoadNetwork,
    from_edge: str,
    to_edge: str,
    *,
    vclass: str = "passenger",
    weight: str = "length",
    avoid: Iterable[str] = (),
    start_pos: float = 0.0,
    car: CarShape | None = None,
    avoid_limit_turns: bool = False,
) -> Route:
    """The route a planner that drives forward takes: :func:`shortest_route` without
    turnarounds, or with them where every route has one (a dead end); the arguments as
    there."""
    try:
        return shortest_route(network, from_edge, to_edge, vclass=vclass, weight=weight,
                              avoid=avoid, start_pos=start_pos, turnarounds=False, car=car,
                              avoid_limit_turns=avoid_limit_turns)
    except NoRouteError:
        log.info("every route %s -> %s turns around: taking the shortest", from_edge, to_edge)
        return shortest_route(network, from_edge, to_edge, vclass=vclass, weight=weight,
                              avoid=avoid, start_pos=start_pos, car=car,
                              avoid_limit_turns=avoid_limit_turns)


#: Routes :func:`_without_tight_turns` tries before it keeps the tight turns and bends.
MAX_TIGHT_DETOURS = 16


def _without_tight_turns(
    network: RoadNetwork, vclass: str, car: CarShape,
    adjacency: list[list[tuple[int, float]]], path: list[int], blocked: set[int],
    potential: list[float], *, avoid_limit_turns: bool = False,
) -> tuple[list[int], list[tuple[int, int]], list[int]]:
    """The least-cost path without turns the car cannot make (their arcs dropped one
    route at a time: the landmark bounds hold on a graph with fewer arcs) and without
    edges whose bends it cannot follow (blocked likewise, but the origin and
    destination), with the edges of tight bends it keeps; or ``path``, its tight turns
    and its edges of tight bends where none avoids them (within
    :data:`MAX_TIGHT_DETOURS` tries). With ``avoid_limit_turns``, turns the car makes only on a
    searched path (:func:`~splineplan.network.searched_path`: at its turning limit)
    count as tight too. Turnarounds are not tested, and a detour may not add one."""
    ids = network.edge_ids

    def bends_of(p: list[int]) -> list[int]:
        return [v for v in p if not bend_fits(network, ids[v], vclass, car)]

    def tight_of(p: list[int]) -> list[tuple[int, int]]:
        # turnarounds are no forward turn at all: the planner knows them apart
        return [(u, v) for u, v in itertools.pairwise(p)
                if (not turn_fits(network, ids[u], ids[v], vclass, car)
                    or (avoid_limit_turns
                        and searched_path(network, ids[u], ids[v], vclass, car)
                    is not None))
                and not is_turnaround(network, ids[u], ids[v], vclass)]

    def backs_of(p: list[int]) -> list[tuple[int, int]]:
        return [(u, v) for u, v in itertools.pairwise(p)
                if is_turnaround(network, ids[u], ids[v], vclass)]

    ends = {path[0], path[-1]}
    first, first_bent = tight_of(path), bends_of(path)
    if not first and ends.issuperset(first_bent):
        return path, [], first_bent
    skip = set(first)
    bent = set(first_bent) - ends
    allowed_backs = set(backs_of(path))  # a detour may not add a turnaround either
    for _ in range(MAX_TIGHT_DETOURS):
        adj = list(adjacency)
        for u in {u for u, _ in skip}:
            adj[u] = [(w, c) for w, c in adjacency[u] if (u, w) not in skip]
        alt = dijkstra(adj, path[0], path[-1], blocked | bent, potential)
        if alt is None:
            break
        bad = tight_of(alt) + [b for b in backs_of(alt) if b not in allowed_backs]
        alt_bent = set(bends_of(alt)) - ends
        if not bad and not alt_bent:
            return alt, [], bends_of(alt)
        skip.update(bad)
        bent |= alt_bent
    return path, first, first_bent


def dijkstra(
    adjacency: list[list[tuple[int, float]]],
    source: int,
    target: int,
    blocked: Iterable[int] = (),
    potential: list[float] | None = None,
) -> list[int] | None:
    """Least-cost vertex path from ``source`` to ``target``, or ``None`` if there is none.

    Dijkstra's algorithm with a binary heap, stopping when ``target`` is settled.
    ``adjacency[u]`` lists ``(v, cost)`` pairs with cost >= 0; vertices in ``blocked`` are
    never entered. ``potential``, if given, is a consistent lower bound of each vertex's
    cost to ``target`` (values >= ``UNREACHABLE`` mean it cannot reach it); the search
    then orders its heap by cost + potential (A*), which settles fewer vertices and finds
    a path of the same least cost.
    """
    if source == target:
        return [source]
    n = len(adjacency)
    h = potential if potential is not None else [0.0] * n
    if h[source] >= UNREACHABLE:
        return None
    inf = float("inf")
    dist = [inf] * n
    pred = [-1] * n
    done = bytearray(n)
    for b in blocked:
        done[b] = 1
    dist[source] = 0.0
    heap = [(h[source], source)]
    pop, push = heapq.heappop, heapq.heappush
    while heap:
        _, u = pop(heap)
        if done[u]:
            continue
        if u == target:
            path = [u]
            while pred[u] >= 0:
                u = pred[u]
                path.append(u)
            path.reverse()
            return path
        done[u] = 1
        d = dist[u]
        for v, c in adjacency[u]:
            nd = d + c
            if nd < dist[v] and not done[v]:
                hv = h[v]
                if hv >= UNREACHABLE:
                    continue
                dist[v] = nd
                pred[v] = u
                push(heap, (nd + hv, v))
    return None


#: Potentials at or above this value mark vertices that cannot reach the target.
UNREACHABLE = 1e14
#: Number of landmarks per graph and weight, and how many of them one query uses.
N_LANDMARKS = 16
N_ACTIVE = 3


@dataclass(frozen=True, eq=False)
class _Search:
    """What queries on one class graph and weight share: arc lists and landmark distances.

    ``to_landmark[i, v]`` is the least cost from ``v`` to landmark ``i``;
    ``from_landmark[i, v]`` from landmark ``i`` to ``v`` (``_BIG`` where there is no path).
    """

    adjacency: list[list[tuple[int, float]]]
    from_landmark: FloatArray
    to_landmark: FloatArray
    # the adjacency without turnaround steps, once built (a list of one: frozen class)
    forward: list[list[list[tuple[int, float]]]] = field(default_factory=list)

    def potential(self, source: int, target: int) -> list[float]:
        """Landmark lower bounds (ALT) of every vertex's cost to ``target``."""
        df, dt = self.from_landmark, self.to_landmark
        score = np.maximum(df[:, target] - df[:, source], dt[:, source] - dt[:, target])
        use = np.argsort(-score)[:N_ACTIVE]
        d1, d2 = df[use], dt[use]
        h = np.maximum((d1[:, target, None] - d1).max(axis=0),
                       (d2 - d2[:, target, None]).max(axis=0))
        return list(np.maximum(h, 0.0).tolist())


_BIG = 1e15
_SEARCHES: weakref.WeakKeyDictionary[ClassGraph, dict[str, _Search]] = (
    weakref.WeakKeyDictionary())


def _search(network: RoadNetwork, graph: ClassGraph, weight: str) -> _Search:
    """The shared search data of ``graph`` for ``weight`` (built on first use, cached)."""
    per_graph = _SEARCHES.setdefault(graph, {})
    found = per_graph.get(weight)
    if found is None:
        found = _build_search(_arc_costs(network, graph, weight), graph)
        per_graph[weight] = found
    return found


def is_turnaround(network: RoadNetwork, from_edge: str, to_edge: str, vclass: str) -> bool:
    """Whether every connection ``vclass`` may use from ``from_edge`` to ``to_edge`` is a
    turnaround (SUMO direction ``t``)."""
    conns = network.connections_between(from_edge, to_edge, vclass=vclass)
    return bool(conns) and all(c.direction == "t" for c in conns)


def _forward(network: RoadNetwork, graph: ClassGraph, search: _Search
             ) -> list[list[tuple[int, float]]]:
    """The search's arc lists without turnaround steps (built on first use, cached)."""
    if not search.forward:
        ids, vclass = network.edge_ids, graph.vclass
        search.forward.append(
            [[(v, c) for v, c in arcs if not is_turnaround(network, ids[u], ids[v], vclass)]
             for u, arcs in enumerate(search.adjacency)])
    return search.forward[0]


def _arc_costs(network: RoadNetwork, graph: ClassGraph, weight: str) -> FloatArray:
    """Cost of each arc: the internal lanes plus the edge entered, [m] or [s]."""
    to = graph.indices
    if weight == "length":
        return np.asarray(graph.via_length + network.lengths[to])
    return np.asarray(graph.via_time + network.lengths[to] / network.speeds[to])


def _build_search(cost: FloatArray, graph: ClassGraph, *, seed: int = 0) -> _Search:
    """Arc lists and landmarks, chosen farthest-first from a seeded random vertex."""
    from scipy.sparse import csr_matrix
    from scipy.sparse.csgraph import dijkstra as sp_dijkstra

    n = len(graph.indptr) - 1
    ind, cst, ptr = graph.indices.tolist(), cost.tolist(), graph.indptr.tolist()
    adjacency = [list(zip(ind[a:b], cst[a:b], strict=True))
                 for a, b in itertools.pairwise(ptr)]
    # scipy drops explicit zeros; costs here are > 0 (edges have positive length)
    fwd = csr_matrix((np.maximum(cost, 1e-12), graph.indices, graph.indptr), shape=(n, n))
    bwd = fwd.T.tocsr()
    k = min(N_LANDMARKS, n)
    rng = np.random.default_rng(seed)
    chosen: list[int] = []
    nearest = np.full(n, np.inf)
    cur = int(rng.integers(n))
    for _ in range(k):
        chosen.append(cur)
        d = np.minimum(sp_dijkstra(fwd, indices=cur), sp_dijkstra(bwd, indices=cur))
        nearest = np.minimum(nearest, d)
        score = np.where(np.isfinite(nearest), nearest, -1.0)
        score[chosen] = -2.0
        cur = int(np.argmax(score))
    df = np.atleast_2d(sp_dijkstra(fwd, indices=chosen))
    dt = np.atleast_2d(sp_dijkstra(bwd, indices=chosen))
    df[~np.isfinite(df)] = _BIG
    dt[~np.isfinite(dt)] = _BIG
    log.debug("landmarks %s", chosen)
    return _Search(adjacency, df, dt)


def route_length(network: RoadNetwork, edges: Sequence[str], *, vclass: str = "passenger",
                 start_pos: float = 0.0) -> float:
    """Length [m] of the route through ``edges`` as :attr:`Route.length` counts it: from
    ``start_pos`` on the first edge to the end of the last, the junction lanes between
    consecutive edges included.

    Raises
    ------
    UnknownEdgeError
        An edge id is not in the network.
    NoRouteError
        Two consecutive edges are not connected for ``vclass``.
    """
    graph = network.graph(vclass)
    path = [network.edge_index(e) for e in edges]
    if not path:
        return 0.0
    for u, v in itertools.pairwise(path):
        if v not in graph.indices[graph.indptr[u]:graph.indptr[u + 1]]:
            raise NoRouteError(f"edge '{network.edge_ids[u]}' does not lead to edge "
                               f"'{network.edge_ids[v]}' for vehicle class '{vclass}'")
    return _path_totals(network, graph, path)[0] - float(start_pos)


def _path_totals(network: RoadNetwork, graph: ClassGraph, path: list[int]) -> tuple[float, float]:
    """Length [m] and travel time [s] of a vertex path, the first edge in full."""
    lists = _LISTS.get(graph)
    if lists is None:
        lists = (graph.indptr.tolist(), graph.indices.tolist(), graph.via_length.tolist(),
                 graph.via_time.tolist(), network.lengths.tolist(), network.speeds.tolist())
        _LISTS[graph] = lists
    ptr, ind, vlen, vtime, lengths, speeds = lists
    length = lengths[path[0]]
    time = length / speeds[path[0]]
    for u, v in itertools.pairwise(path):
        k = ind.index(v, ptr[u], ptr[u + 1])
        length += vlen[k] + lengths[v]
        time += vtime[k] + lengths[v] / speeds[v]
    return length, time


_LISTS: weakref.WeakKeyDictionary[ClassGraph, tuple[list[Any], ...]] = (
    weakref.WeakKeyDictionary())
