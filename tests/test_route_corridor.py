"""Route corridors through SUMO junctions: inside the drivable region, drivable reference lines.

The oracle is shapely: the union of the route's lane areas (each lane's centre line buffered
by half its width, flat ends, round joins), the junction lanes of the connections taken and
the outlines of the junctions passed, with gaps under 3 cm between neighbouring lanes closed
(SUMO rounds lane shapes to 1 cm).
"""

from __future__ import annotations

import numpy as np
import pytest
import shapely
from conftest import NETS
from shapely.geometry import LineString, Point, Polygon
from shapely.ops import unary_union

from splineplan.network import RoadNetwork, load_network, route_corridor
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
