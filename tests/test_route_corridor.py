"""Route corridors through SUMO junctions: inside the drivable region, drivable reference lines.

The oracle is shapely: the union of the route's lane areas (each lane's centre line buffered
by half its width, flat ends, round joins), the junction lanes of the connections taken, the
outlines of the junctions passed and, within OPPOSITE_REACH + 1 m of those outlines, the
lanes of the opposite-direction edges of the route edges at each junction (all of it road to
the simulation's off-road check), with gaps under 3 cm between neighbouring lanes closed
(SUMO rounds lane shapes to 1 cm).
"""

from __future__ import annotations

import numpy as np
import pytest
import shapely
from conftest import NETS
from shapely.geometry import LineString, Point, Polygon
from shapely.ops import unary_union

from splineplan.network import OPPOSITE_REACH, RoadNetwork, load_network, route_corridor
from splineplan.route import Route, shortest_route

GRID = NETS / "grid.net.xml"
CITY = NETS / "city.net.xml"

# (network, from, to): right and left turns, straight through, a roundabout, a route that
# passes a junction twice, one with a bus lane beside it
CASES = [
    (NETS / "straight.net.xml", "e0", "e2"),
    (GRID, "D1D0", "C0B0"),  # right turn
    (GRID, "A3A2", "C3C2"),  # left turns
    (GRID, "A0B0", "D1D0"),
    (GRID, "C2B2", "A0B0"),
    (CITY, "B3A3", "bridge_east"),
    (CITY, "G2F2", "RESE"),  # roundabout
    (CITY, "B0C0", "C1C0"),  # around the roundabout and back through C0
    (CITY, "C0C1", "C2C3"),  # bus lane excluded
    (CITY, "SWA0", "C3B3"),
]


def _region(net: RoadNetwork, route: Route, vclass: str = "passenger") -> shapely.Geometry:
    geoms = []
    for i, eid in enumerate(route.edges):
        for ln in net.lanes_of(eid):
            geoms.append(LineString(ln.shape).buffer(ln.width / 2, cap_style="flat"))
        if i + 1 == len(route.edges):
            continue
        for c in net.connections_between(eid, route.edges[i + 1], vclass=vclass):
            for v in c.via:
                ln = net.internal_lanes[v]
                geoms.append(LineString(ln.shape).buffer(ln.width / 2, cap_style="flat"))
        outline = net.junction_shapes.get(net.to_junctions[net.edge_index(eid)])
        if outline is not None:
            geoms.append(Polygon(outline).buffer(0))
            # the lanes of the edges back along the two route edges, near the junction
            near = Polygon(outline).buffer(OPPOSITE_REACH + 1.0)
            for k in (eid, route.edges[i + 1]):
                ends = (net.to_junctions[net.edge_index(k)],
                        net.from_junctions[net.edge_index(k)])
                for o, fj_tj in enumerate(zip(net.from_junctions, net.to_junctions, strict=True)):
                    if fj_tj == ends:
                        geoms.extend(
                            LineString(ln.shape).buffer(ln.width / 2, cap_style="flat")
                            .intersection(near)
                            for ln in net.lanes[o] if ln.allows(vclass))
    union = unary_union(geoms)
    return union.buffer(0.015, join_style="mitre").buffer(-0.015, join_style="mitre")


@pytest.mark.parametrize(("path", "frm", "to"), CASES, ids=lambda v: getattr(v, "name", v))
def test_corridor_lies_in_the_drivable_region(path, frm: str, to: str) -> None:
    net = load_network(path)
    route = shortest_route(net, frm, to)
    cor = route_corridor(net, route)
    region = _region(net, route).buffer(1e-6)
    # in pieces of 120 vertices (60 m): a route that passes a place twice overlaps itself
    rxy, lxy = cor.right_xy(), cor.left_xy()
    for i in range(0, len(cor.s) - 1, 120):
        j = min(i + 121, len(cor.s))
        poly = shapely.make_valid(Polygon(np.concatenate((rxy[i:j], lxy[i:j][::-1]))))
        outside = poly.buffer(-0.01).difference(region)
        assert outside.area < 1e-6, (frm, to, cor.s[i], outside.bounds)
    # lane centres of every route edge lie in the corridor
    for eid in route.edges:
        lanes = [ln for ln in net.lanes_of(eid) if ln.allows("passenger")]
        for ln in lanes:
            s = np.concatenate(([0.0], np.cumsum(np.hypot(*np.diff(ln.shape, axis=0).T))))
            t = np.linspace(0.1 * s[-1], 0.9 * s[-1], 9)
            pts = np.column_stack((np.interp(t, s, ln.shape[:, 0]),
                                   np.interp(t, s, ln.shape[:, 1])))
            assert cor.contains(pts, margin=-1e-6).all() or all(
                shapely.make_valid(Polygon(cor.polygon())).buffer(1e-6).contains(Point(p))
                for p in pts), (eid, ln.id)
    # the reference line stays in the corridor
    assert np.all(cor.right < 0) and np.all(cor.left > 0)


def _turn_curvature(net: RoadNetwork, frm: str, to: str) -> float:
    cor = route_corridor(net, shortest_route(net, frm, to))
    d = np.diff(cor.reference, axis=0)
    h = np.unwrap(np.arctan2(d[:, 1], d[:, 0]))
    return float(np.max(np.abs(np.diff(h)) / np.hypot(*d[1:].T)))


@pytest.mark.parametrize(("frm", "to"), [("D1D0", "C0B0"), ("A3A2", "C3C2"),
                                         ("A0B0", "D1D0"), ("C2B2", "A0B0")])
def test_reference_turns_with_a_drivable_radius(frm: str, to: str) -> None:
    # the grid's junctions are 12.8 m across: room to turn with a 5 m radius
    assert _turn_curvature(load_network(GRID), frm, to) <= 1 / 5.0


def test_edge_starts_unchanged_semantics() -> None:
    net = load_network(GRID)
    route = shortest_route(net, "A3A2", "C3C2")
    cor = route_corridor(net, route)
    assert cor.edges == route.edges
    assert cor.edge_starts[0] == 0.0 and np.all(np.diff(cor.edge_starts) > 0)
    for eid in route.edges:
        lane = net.lanes_of(eid)[0]
        mid = lane.shape[0] + 0.5 * (lane.shape[-1] - lane.shape[0])
        assert cor.edge_at(float(cor.to_sl(mid[None])[0, 0])) == eid
    # junction stretches count towards the edge before them
    end_first = cor.to_sl(net.lanes_of(route.edges[0])[0].shape[-1][None])[0, 0]
    assert cor.edge_at(float(end_first) + 2.0) == route.edges[0]


def test_straight_width_is_the_lanes() -> None:
    net = load_network(NETS / "straight.net.xml")
    cor = route_corridor(net, shortest_route(net, "e0", "e2"))
    s = np.arange(0.0, cor.length + 0.01, 1.0)
    right, left = cor.bounds_at(s)
    away = (np.abs(s - 200.0) > 10.0) & (np.abs(s - 400.0) > 2.0)  # from the junctions
    assert np.allclose((left - right)[away], 9.6, atol=1e-6)  # the ends included
    # the side road's junction widens the corridor, by at most JUNCTION_REACH each side
    assert (left - right)[np.abs(s - 202.0) < 3.0].max() > 10.0


def _random_routes(net: RoadNetwork, n: int, seed: int) -> list[Route]:
    rng = np.random.default_rng(seed)
    usable = [e for e in net.edge_ids if net.allows(e, "passenger")]
    routes: list[Route] = []
    while len(routes) < n:
        a, b = rng.choice(usable, size=2)
        try:
            routes.append(shortest_route(net, str(a), str(b)))
        except Exception:
            continue
    return routes


def _narrowest_lane(net: RoadNetwork, route: Route) -> float:
    widths = [ln.width for eid in route.edges for ln in net.lanes_of(eid)
              if ln.allows("passenger")]
    for a, b in zip(route.edges[:-1], route.edges[1:], strict=True):
        widths.extend(net.internal_lanes[v].width
                      for c in net.connections_between(a, b, vclass="passenger")
                      for v in c.via)
    return min(widths)


def test_corridor_never_narrower_than_a_lane() -> None:
    # random routes, with ones out of the small roundabout (RWSW, RWRS), whose exits are
    # too tight for a smoothed reference line
    net = load_network(CITY)
    routes = _random_routes(net, 40, seed=7)
    routes += [shortest_route(net, "B3A3", "B0C0"), shortest_route(net, "E0E1", "RESE")]
    assert sum(("RWSW" in r.edges) or ("RWRS" in r.edges) for r in routes) >= 4
    for route in routes:
        cor = route_corridor(net, route)
        width = cor.left - cor.right
        i = int(np.argmin(width))
        assert width[i] >= _narrowest_lane(net, route) - 0.08, (
            route.edges[0], route.edges[-1], cor.s[i], cor.edge_at(float(cor.s[i])))
        region = _region(net, route).buffer(1e-6)
        rxy, lxy = cor.right_xy(), cor.left_xy()
        for k in range(0, len(cor.s) - 1, 120):
            j = min(k + 121, len(cor.s))
            poly = shapely.make_valid(Polygon(np.concatenate((rxy[k:j], lxy[k:j][::-1]))))
            outside = poly.buffer(-0.01).difference(region)
            assert outside.area < 1e-6, (route.edges[0], route.edges[-1], cor.s[k],
                                         outside.bounds)


def _opposite_lanes(net: RoadNetwork, eid: str) -> list[shapely.Geometry]:
    ends = (net.to_junctions[net.edge_index(eid)], net.from_junctions[net.edge_index(eid)])
    return [LineString(ln.shape).buffer(ln.width / 2, cap_style="flat")
            for o, fj_tj in enumerate(zip(net.from_junctions, net.to_junctions, strict=True))
            if fj_tj == ends for ln in net.lanes[o] if ln.allows("passenger")]


def test_turns_between_narrow_streets_cut_the_inner_corner() -> None:
    # one-lane streets: a left turn may use the oncoming lanes near the junction (G1), a
    # junction passed straight may not
    net = load_network(CITY)
    route = shortest_route(net, "SWA0", "G1G2")
    cor = route_corridor(net, route)
    poly = shapely.make_valid(Polygon(cor.polygon()))
    used = {}
    for a, b in zip(route.edges[:-1], route.edges[1:], strict=True):
        jid = net.to_junctions[net.edge_index(a)]
        near = Polygon(net.junction_shapes[jid]).buffer(20.0)
        own = unary_union([LineString(ln.shape).buffer(ln.width / 2, cap_style="flat")
                           for k in (a, b) for ln in net.lanes_of(k)])
        opp = unary_union(_opposite_lanes(net, a) + _opposite_lanes(net, b))
        opp = opp.intersection(near).difference(own)  # the lane shapes overlap by ~1 cm
        da = net.lanes_of(a)[0].shape[-1] - net.lanes_of(a)[0].shape[-2]
        db = net.lanes_of(b)[0].shape[1] - net.lanes_of(b)[0].shape[0]
        turn = abs(np.degrees(np.arctan2(da[0] * db[1] - da[1] * db[0], da @ db)))
        used[jid] = (turn, poly.intersection(opp).area)
    turn, area = used["G1"]
    assert turn > 60.0 and area > 10.0
    straight = [v for v in used.values() if v[0] < 15.0]
    assert straight and all(area < 1e-3 for _, area in straight)
