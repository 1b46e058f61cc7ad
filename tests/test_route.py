"""Tests of splineplan.route: lengths equal to sumolib's, validity, avoidance, errors, SUMO."""

from __future__ import annotations

import itertools
import random
from functools import cache
from pathlib import Path
from typing import Any

import libsumo
import pytest
import sumolib
from conftest import NETS

from splineplan.errors import (
    NoRouteError,
    ParameterError,
    UnknownEdgeError,
    VehicleClassError,
)
from splineplan.network import RoadNetwork, load_network
from splineplan.route import Route, dijkstra, route_length, shortest_route

CITY = NETS / "city.net.xml"
CASES = [("straight.net.xml", "passenger"), ("grid.net.xml", "passenger"),
         ("city.net.xml", "passenger"), ("city.net.xml", "bus"), ("city.net.xml", "bicycle")]


@cache
def _nets(path: Path) -> tuple[RoadNetwork, Any]:
    return load_network(path), sumolib.net.readNet(str(path), withInternal=True)


def validate(sn: Any, route: Route) -> float:
    """Check a route against sumolib on its own; return its length re-added [m]."""
    edges = [sn.getEdge(e) for e in route.edges]
    assert all(e.getFunction() == "" for e in edges)
    assert edges[0].allows(route.vclass) and edges[-1].allows(route.vclass)
    length = edges[0].getLength() - route.start_pos
    for a, b in itertools.pairwise(edges):
        conns = a.getAllowedOutgoing(route.vclass).get(b)
        assert conns, f"{a.getID()} -> {b.getID()} is not a connection for {route.vclass}"
        vias = [c for c in conns if c.getViaLaneID()]
        internal = 0.0
        if vias:
            internal = min(sum(ln.getLength() for ln in _via_chain(sn, c)) for c in vias)
        length += internal + b.getLength()
    assert len(set(route.edges)) == len(route.edges)  # a shortest route has no loop
    return length


def _via_chain(sn: Any, c: Any) -> list[Any]:
    out, via = [], c.getViaLaneID()
    while via:
        lane = sn.getLane(via)
        out.append(lane)
        via = lane.getOutgoing()[0].getViaLaneID() if lane.getOutgoing() else ""
    return out


def _compare(net: RoadNetwork, sn: Any, vclass: str, pairs: int, seed: int) -> int:
    """Random OD pairs: splineplan's length equals sumolib's; returns routes found."""
    rng = random.Random(seed)
    usable = [e for e in net.edge_ids if net.allows(e, vclass)]
    found = 0
    for _ in range(pairs):
        a, b = rng.choice(usable), rng.choice(usable)
        path, cost = sn.getShortestPath(sn.getEdge(a), sn.getEdge(b), vClass=vclass)
        if path is None:
            with pytest.raises(NoRouteError, match=f"'{a}' to edge '{b}'"):
                shortest_route(net, a, b, vclass=vclass)
            continue
        route = shortest_route(net, a, b, vclass=vclass)
        assert route.length == pytest.approx(cost, rel=1e-6, abs=1e-6), (a, b)
        assert validate(sn, route) == pytest.approx(route.length, rel=1e-9, abs=1e-6)
        assert route.cost == route.length and route.edges[0] == a and route.edges[-1] == b
        found += 1
    return found


@pytest.mark.parametrize(("name", "vclass"), CASES)
def test_lengths_equal_sumolib(name: str, vclass: str) -> None:
    net, sn = _nets(NETS / name)
    assert _compare(net, sn, vclass, 200, seed=7) > 0


def test_lengths_equal_sumolib_monaco(monaco_net: Path) -> None:
    net, sn = _nets(monaco_net)
    assert _compare(net, sn, "passenger", 200, seed=11) > 150


@pytest.mark.slow
def test_lengths_equal_sumolib_monaco_many(monaco_net: Path) -> None:
    net, sn = _nets(monaco_net)
    assert _compare(net, sn, "passenger", 3000, seed=12) > 2000
    assert _compare(net, sn, "bus", 500, seed=13) > 0


def test_routes_without_turnarounds_monaco(monaco_net: Path) -> None:
    """``turnarounds=False``: valid, no turnaround step, and no shorter than the optimum;
    equal to it wherever the optimum has no turnaround."""
    net, sn = _nets(monaco_net)
    rng = random.Random(5)
    usable = [e for e in net.edge_ids if net.allows(e, "passenger")]
    differed = 0
    for _ in range(150):
        a, b = rng.choice(usable), rng.choice(usable)
        try:
            best = shortest_route(net, a, b)
        except NoRouteError:
            continue
        has_t = any({c.getDirection() for c in sn.getEdge(e).getConnections(sn.getEdge(f))}
                    == {"t"} for e, f in itertools.pairwise(best.edges))
        try:
            forward = shortest_route(net, a, b, turnarounds=False)
        except NoRouteError as err:  # only where the optimum itself must turn around
            assert has_t and "without turnarounds" in str(err)
            continue
        assert validate(sn, forward) == pytest.approx(forward.length, rel=1e-9, abs=1e-6)
        steps = list(itertools.pairwise(forward.edges))
        for e, f in steps:  # sumolib's own word on each step's connections
            dirs = {c.getDirection() for c in sn.getEdge(e).getConnections(sn.getEdge(f))}
            assert dirs != {"t"}, (a, b, e, f)
        assert forward.length >= best.length - 1e-6
        if not has_t:
            assert forward.length == pytest.approx(best.length, rel=1e-9)
        differed += has_t
    assert differed > 0  # the sample exercised routes that turn around


@pytest.mark.parametrize("name", ["grid.net.xml", "city.net.xml"])
def test_time_weight_equals_sumolib_fastest(name: str) -> None:
    net, sn = _nets(NETS / name)
    rng = random.Random(3)
    for _ in range(100):
        a, b = rng.choice(net.edge_ids), rng.choice(net.edge_ids)
        path, cost = sn.getFastestPath(sn.getEdge(a), sn.getEdge(b), vClass="passenger")
        if path is None or not (net.allows(a, "passenger") and net.allows(b, "passenger")):
            continue
        route = shortest_route(net, a, b, weight="time")
        assert route.cost == pytest.approx(cost, rel=1e-6)
        assert validate(sn, route) == pytest.approx(route.length)
        assert route.length >= shortest_route(net, a, b).length - 1e-9


def test_start_pos_matches_sumolib() -> None:
    net, sn = _nets(CITY)
    for a, b, pos in (("SWA0", "G1G2", 10.0), ("A0B0", "E3D3", 55.5), ("C0C1", "C0C1", 20.0)):
        route = shortest_route(net, a, b, start_pos=pos)
        _, cost = sn.getShortestPath(sn.getEdge(a), sn.getEdge(b), vClass="passenger",
                                     fromPos=pos)
        assert route.length == pytest.approx(cost)
        assert route.start_pos == pos
    with pytest.raises(ParameterError, match="start_pos"):
        shortest_route(net, "SWA0", "G1G2", start_pos=-1.0)
    with pytest.raises(ParameterError, match="start_pos"):
        shortest_route(net, "SWA0", "G1G2", start_pos=1e6)


def test_route_length_of_given_edges() -> None:
    """route_length re-adds a route's edges and junction lanes as sumolib does, from a start
    position; edges that do not connect are an error that names them."""
    net, sn = _nets(CITY)
    for a, b, pos in (("SWA0", "G1G2", 10.0), ("A0B0", "E3D3", 55.5)):
        route = shortest_route(net, a, b, start_pos=pos)
        assert route_length(net, route.edges, start_pos=pos) == pytest.approx(route.length)
        assert route_length(net, route.edges) == pytest.approx(validate(sn, route) + pos)
    with pytest.raises(NoRouteError, match="'SWA0' does not lead to edge 'G1G2'"):
        route_length(net, ("SWA0", "G1G2"))


def test_avoided_edges_are_never_used() -> None:
    net, sn = _nets(CITY)
    rng = random.Random(5)
    core = [e for e in net.edge_ids if net.allows(e, "passenger")]
    for _ in range(150):
        a, b = rng.choice(core), rng.choice(core)
        avoid = {e for e in rng.sample(core, 6) if e not in (a, b)}
        try:
            free = shortest_route(net, a, b)
        except NoRouteError:
            continue
        idx = {net.edge_index(e) for e in avoid}
        plain = dijkstra(_adjacency(net), net.edge_index(a), net.edge_index(b), idx)
        try:
            route = shortest_route(net, a, b, avoid=avoid)
        except NoRouteError as err:
            assert plain is None
            assert "avoiding" in str(err)
            continue
        assert plain is not None
        assert not avoid & set(route.edges)
        assert validate(sn, route) == pytest.approx(route.length)
        assert route.length >= free.length - 1e-9
        if not avoid & set(free.edges):
            assert route.length == pytest.approx(free.length)
        assert route.length == pytest.approx(_path_length(net, sn, plain))


def _adjacency(net: RoadNetwork) -> list[list[tuple[int, float]]]:
    from splineplan.route import _search
    return _search(net, net.graph("passenger"), "length").adjacency


def _path_length(net: RoadNetwork, sn: Any, path: list[int]) -> float:
    edges = tuple(net.edge_ids[i] for i in path)
    return validate(sn, Route(edges, 0.0, 0.0, "length", "passenger"))


def test_blocking_the_bridge_cuts_off_the_east() -> None:
    net, _ = _nets(CITY)
    assert "bridge_east" in shortest_route(net, "SWA0", "G1G2").edges
    with pytest.raises(NoRouteError) as info:
        shortest_route(net, "SWA0", "G1G2", avoid=["bridge_east"])
    msg = str(info.value)
    assert "'SWA0'" in msg and "'G1G2'" in msg and "bridge_east" in msg
    # the way back does not need it
    assert shortest_route(net, "G1G2", "A0B0", avoid=["bridge_east"]).edges


def test_restricted_edges() -> None:
    net, _ = _nets(CITY)
    bus = shortest_route(net, "A1B1", "C2C3", vclass="bus")
    car = shortest_route(net, "A1B1", "C2C3")
    assert "bus_B1C2" in bus.edges and "bus_B1C2" not in car.edges
    assert bus.length < car.length
    with pytest.raises(VehicleClassError, match="bus_B1C2"):
        shortest_route(net, "bus_B1C2", "C2C3")
    with pytest.raises(VehicleClassError, match="bike_A2B3"):
        shortest_route(net, "A0B0", "bike_A2B3", vclass="passenger")


def test_errors() -> None:
    net, _ = _nets(CITY)
    with pytest.raises(UnknownEdgeError, match="'nowhere'"):
        shortest_route(net, "nowhere", "G1G2")
    with pytest.raises(UnknownEdgeError, match="'gone'"):
        shortest_route(net, "SWA0", "G1G2", avoid=["gone"])
    with pytest.raises(VehicleClassError, match="'car'"):
        shortest_route(net, "SWA0", "G1G2", vclass="car")
    with pytest.raises(ParameterError, match="weight"):
        shortest_route(net, "SWA0", "G1G2", weight="fuel")
    with pytest.raises(NoRouteError, match="origin edge 'SWA0'"):
        shortest_route(net, "SWA0", "G1G2", avoid=["SWA0"])
    with pytest.raises(NoRouteError, match="from edge 'RSS' to edge 'C0C1'"):
        shortest_route(net, "RSS", "C0C1")  # a dead end without turnaround
    single = shortest_route(net, "C0C1", "C0C1")
    assert single.edges == ("C0C1",) and single.length == pytest.approx(net.length_of("C0C1"))


# ---- every route is drivable in SUMO ----------------------------------------------------

def _drive(path: Path, routes: list[Route]) -> None:
    """Drive one vehicle per route in SUMO; each departs, arrives, never teleports."""
    libsumo.start(["sumo", "-n", str(path), "--no-step-log", "--time-to-teleport", "300",
                   "--collision.check-junctions", "--begin", "0"])
    try:
        types = {}
        for vc in {r.vclass for r in routes}:
            types[vc] = f"t_{vc}"
            libsumo.vehicletype.copy("DEFAULT_VEHTYPE", types[vc])
            libsumo.vehicletype.setVehicleClass(types[vc], vc)
        for k, r in enumerate(routes):
            libsumo.route.add(f"r{k}", list(r.edges))
            libsumo.vehicle.add(f"v{k}", f"r{k}", typeID=types[r.vclass], depart=str(5 * k),
                                departLane="best", departPos="base")
        departed, arrived, teleports = set(), set(), 0
        for _ in range(4000):
            libsumo.simulationStep()
            departed.update(libsumo.simulation.getDepartedIDList())
            arrived.update(libsumo.simulation.getArrivedIDList())
            teleports += libsumo.simulation.getStartingTeleportNumber()
            if len(arrived) == len(routes):
                break
        want = {f"v{k}" for k in range(len(routes))}
        assert departed == want
        assert arrived == want
        assert teleports == 0
    finally:
        libsumo.close()


@pytest.mark.parametrize("name", ["straight.net.xml", "grid.net.xml", "city.net.xml"])
def test_routes_are_drivable_in_sumo(name: str) -> None:
    net, _ = _nets(NETS / name)
    rng = random.Random(21)
    routes: list[Route] = []
    specs = [("passenger", "length"), ("passenger", "time"), ("bus", "length"),
             ("bicycle", "length")]
    tries = 0
    while len(routes) < 8 and tries < 500:
        tries += 1
        vc, w = specs[len(routes) % len(specs)] if name == "city.net.xml" else specs[tries % 2]
        a, b = rng.choice(net.edge_ids), rng.choice(net.edge_ids)
        try:
            routes.append(shortest_route(net, a, b, vclass=vc, weight=w))
        except (NoRouteError, VehicleClassError):
            continue
    assert routes
    if name == "city.net.xml":
        routes.append(shortest_route(net, "SWA0", "G1G2"))
        routes.append(shortest_route(net, "A1B1", "C2C3", vclass="bus"))
    _drive(NETS / name, routes)
