"""Tests of splineplan.network: loading, the per-class edge graph, lane geometry, corridors."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import sumolib
from conftest import GRID_CORNERS, GRID_TURNS, NETS
from hypothesis import given, settings
from hypothesis import strategies as st
from oracle import corridor_excess, paved_area
from shapely.geometry import Point, Polygon

from splineplan.errors import (
    NetworkError,
    SplineplanError,
    UnknownEdgeError,
    VehicleClassError,
)
from splineplan.network import load_network, route_corridor
from splineplan.route import shortest_route

BUNDLED = sorted(NETS.glob("*.net.xml"))


def test_bundled_networks_exist() -> None:
    names = {p.name for p in BUNDLED}
    assert {"straight.net.xml", "grid.net.xml", "city.net.xml"} <= names
    for p in BUNDLED:
        assert p.stat().st_size < 1_000_000


def _check_against_sumolib(path: Path, vclasses: tuple[str, ...]) -> None:
    net = load_network(path)
    sn = sumolib.net.readNet(str(path), withInternal=True)
    normal = [e for e in sn.getEdges() if e.getFunction() == ""]
    assert set(net.edge_ids) == {e.getID() for e in normal}
    assert not any(e.startswith(":") for e in net.edge_ids)
    for e in normal:
        i = net.edge_index(e.getID())
        assert net.lengths[i] == pytest.approx(e.getLength())
        assert net.speeds[i] == pytest.approx(e.getSpeed())
        lanes = net.lanes_of(e.getID())
        assert [ln.id for ln in lanes] == [ln.getID() for ln in e.getLanes()]
        for ln, sl in zip(lanes, e.getLanes(), strict=True):
            assert ln.width == pytest.approx(sl.getWidth())
            assert np.allclose(ln.shape, np.asarray(sl.getShape())[:, :2])
    for vc in vclasses:
        g = net.graph(vc)
        for e in normal:
            i = net.edge_index(e.getID())
            mine = {net.edge_ids[j] for j in g.indices[g.indptr[i]:g.indptr[i + 1]]}
            theirs = {f.getID() for f in e.getAllowedOutgoing(vc) if f.getFunction() == ""}
            assert mine == theirs, e.getID()
            assert bool(g.usable[i]) == e.allows(vc)


@pytest.mark.parametrize("path", BUNDLED, ids=lambda p: p.name)
def test_graph_matches_sumolib(path: Path) -> None:
    _check_against_sumolib(path, ("passenger", "bus", "bicycle"))


def test_graph_matches_sumolib_monaco(monaco_net: Path) -> None:
    _check_against_sumolib(monaco_net, ("passenger",))


def test_city_has_the_promised_features() -> None:
    net = load_network(NETS / "city.net.xml")
    assert net.n_edges >= 60
    assert not net.allows("bus_B1C2", "passenger") and net.allows("bus_B1C2", "bus")
    assert net.allows("bike_A2B3", "bicycle") and not net.allows("bike_A2B3", "passenger")
    assert not net.connections_between("B1C1", "C1C2")  # a forbidden turn
    assert net.connections_between("B1C1", "C1D1", vclass="passenger")
    # one-way street: no edge back
    assert "C1B1" not in net
    conns = net.connections_between("C1C2", "C2C3", vclass="passenger")
    assert conns and all(c.via for c in conns)
    via = net.internal_lane(conns[0].via[0])
    assert via.shape.shape[1] == 2 and via.length > 0


def test_missing_file() -> None:
    with pytest.raises(NetworkError, match=r"nope\.net\.xml"):
        load_network("nope.net.xml")


def test_not_a_network(tmp_path: Path) -> None:
    bad = tmp_path / "bad.net.xml"
    bad.write_text("this is not xml")
    with pytest.raises(NetworkError, match=r"bad\.net\.xml"):
        load_network(bad)
    routes = tmp_path / "routes.xml"
    routes.write_text('<routes><vType id="a"/></routes>')
    with pytest.raises(NetworkError, match=r"routes\.xml"):
        load_network(routes)


def test_unknown_vclass_and_edge() -> None:
    net = load_network(NETS / "grid.net.xml")
    with pytest.raises(VehicleClassError, match="car"):
        net.graph("car")
    with pytest.raises(UnknownEdgeError, match="nowhere"):
        net.lanes_of("nowhere")


# ---- corridor adapter -------------------------------------------------------------------

def _lane_points(lane_shape: np.ndarray, trim: float = 0.1) -> np.ndarray:
    """Points along a lane centre line, without its ends."""
    s = np.concatenate(([0.0], np.cumsum(np.hypot(*np.diff(lane_shape, axis=0).T))))
    t = np.linspace(trim * s[-1], (1 - trim) * s[-1], 15)
    return np.column_stack((np.interp(t, s, lane_shape[:, 0]), np.interp(t, s, lane_shape[:, 1])))


def _check_corridor(net_path: Path, frm: str, to: str, vclass: str) -> None:
    net = load_network(net_path)
    route = shortest_route(net, frm, to, vclass=vclass)
    cor = route_corridor(net, route)
    poly = Polygon(cor.polygon()).buffer(1e-6)
    assert poly.is_valid
    assert cor.edges == route.edges
    for i, eid in enumerate(route.edges):
        allowed = [ln for ln in net.lanes_of(eid) if ln.allows(vclass)]
        onward = ({c.from_lane for c in net.connections_between(eid, route.edges[i + 1],
                                                                  vclass=vclass)}
                  if 0 < i < len(route.edges) - 1 else {ln.index for ln in allowed})
        for ln in allowed:
            # lanes that do not lead on along the route: up to the approach to the junction
            pts = _lane_points(ln.shape)
            if ln.index not in onward:
                pts = pts[: len(pts) // 3]
            for p in pts:
                assert poly.contains(Point(p)), (eid, ln.id, p)
        # edge_at of the middle of the edge's lanes is that edge
        mid = _lane_points(allowed[0].shape, 0.5)[0]
        s = cor.to_sl(mid[None])[0, 0]
        assert cor.edge_at(float(s)) == eid
        # width in the middle of the edge: the allowed lanes side by side
        right, left = cor.bounds_at(s)
        expect = sum(ln.width for ln in net.lanes_of(eid)[allowed[0].index:allowed[-1].index + 1])
        assert float(left - right) == pytest.approx(expect, abs=0.05)


def test_corridor_straight() -> None:
    _check_corridor(NETS / "straight.net.xml", "e0", "e2", "passenger")
    net = load_network(NETS / "straight.net.xml")
    cor = route_corridor(net, shortest_route(net, "e0", "e2"))
    right, left = cor.bounds_at(np.array([100.0, 300.0, 500.0]))
    assert np.allclose(left - right, 9.6, atol=1e-6)
    assert cor.length == pytest.approx(600.0, abs=1.0)


def test_corridor_city() -> None:
    _check_corridor(NETS / "city.net.xml", "SWA0", "G1G2", "passenger")
    _check_corridor(NETS / "city.net.xml", "C0C1", "C2C3", "passenger")  # bus lane excluded
    _check_corridor(NETS / "city.net.xml", "C0C1", "C2C3", "bus")
    net = load_network(NETS / "city.net.xml")
    cor_p = route_corridor(net, shortest_route(net, "C0C1", "C2C3"))
    cor_b = route_corridor(net, shortest_route(net, "C0C1", "C2C3", vclass="bus"))
    s_p = cor_p.edge_starts[0] + 30.0
    s_b = cor_b.edge_starts[0] + 30.0
    wp = np.subtract(*cor_p.bounds_at(s_p)[::-1])
    wb = np.subtract(*cor_b.bounds_at(s_b)[::-1])
    assert wp == pytest.approx(3.2, abs=1e-6) and wb == pytest.approx(6.4, abs=1e-6)


def _excess_on_edges_and_junctions(net_path: Path, start: str, goal: str,
                                   paved: object = None) -> tuple[np.ndarray, np.ndarray]:
    net = load_network(net_path)
    cor = route_corridor(net, shortest_route(net, start, goal, turnarounds=False))
    if paved is None:  # the paved area near the corridor
        paved = paved_area(net_path, within=Polygon(cor.polygon()).buffer(10.0))
    stations, excess = corridor_excess(cor, paved)
    junction = np.array([cor.junction_at(s) is not None for s in stations])
    return excess[~junction], excess[junction]


@pytest.mark.parametrize("name", ["grid.net.xml", "city.net.xml"])
def test_corridor_stays_on_the_pavement_station_by_station(name: str) -> None:
    """On seeded random routes, across the road at every metre, the corridor reaches
    beyond sumolib's paved area by at most 5 cm on the edges (their lanes' band) and
    0.2 m in junctions (the kerb curves cut to SUMO's junction outlines), and by more
    than 5 cm at under 1 % of the stations."""
    import random

    path = NETS / name
    net, paved = load_network(path), paved_area(path)
    rng = random.Random(3)
    usable = [e for e in net.edge_ids if net.allows(e, "passenger")]
    done = 0
    while done < 4:
        a, b = rng.choice(usable), rng.choice(usable)
        try:
            if shortest_route(net, a, b, turnarounds=False).length < 300.0:
                continue
        except SplineplanError:
            continue
        on_edges, in_junctions = _excess_on_edges_and_junctions(path, a, b, paved)
        assert on_edges.max() <= 0.05, (a, b, on_edges.max())
        assert in_junctions.max() <= 0.2, (a, b, in_junctions.max())
        assert np.mean(np.concatenate((on_edges, in_junctions)) > 0.05) < 0.01
        done += 1


@pytest.mark.parametrize(("start", "goal", "junctions"), [
    # a 0.8 m edge between two junctions; a lane whose end meets the junction's outline
    # at a slant (the normal runs along the sliver between them)
    ("-1718#11", "1878#0", [("-2081#1", "4126#1"), ("4126#1", "4126#2"),
                           ("4126#2", "1878#0")]),
])
def test_corridor_in_monaco_junctions_is_paved_and_keeps_the_lane(
        monaco_net: Path, start: str, goal: str, junctions: list[tuple[str, str]]) -> None:
    """Through these junctions the corridor stays within the paved area (5 cm) and
    keeps at least the width of the internal lane it turns along (3.2 m)."""
    net = load_network(monaco_net)
    cor = route_corridor(net, shortest_route(net, start, goal, turnarounds=False))
    s = np.arange(0.25, cor.length, 0.25)
    inside = np.array([cor.junction_at(x) in junctions for x in s])
    right, left = cor.bounds_at(s[inside])
    assert inside.sum() > 20 and float(np.min(left - right)) >= 3.2 - 0.05
    paved = paved_area(monaco_net, within=Polygon(cor.polygon()).buffer(10.0))
    stations, excess = corridor_excess(cor, paved, step=0.5)
    near = np.array([cor.junction_at(x) in junctions for x in stations])
    assert float(excess[near].max()) <= 0.05


def test_corridor_follows_an_edge_after_a_hairpin_junction(monaco_net: Path) -> None:
    """Monaco: 1253#3 turns back onto 1135#0 through a hairpin junction. The corridor
    once cut a 5 m chord across 1135#0 there (its points behind the junction's end were
    dropped as an overlap); now it follows the lane."""
    on_edges, in_junctions = _excess_on_edges_and_junctions(monaco_net, "-2225", "-1293#3")
    excess = np.concatenate((on_edges, in_junctions))
    assert np.mean(excess > 0.05) < 0.01
    assert on_edges.max() < 0.5


def test_corridor_follows_a_road_split(monaco_net: Path) -> None:
    """Monaco 1729#3 (three lanes) -> 1729#4 (one lane): the next edge's shape starts 7 m
    behind the end of the last, where the roads split. The corridor once bridged the
    trimmed gap by interpolation, across the unpaved ground between the two roads (its
    middle unpaved at 6 stations); now the next edge starts where its lane crosses the
    end of the last."""
    on_edges, in_junctions = _excess_on_edges_and_junctions(monaco_net, "-756#1", "1729#4")
    excess = np.concatenate((on_edges, in_junctions))
    assert np.isinf(excess).sum() <= 1
    assert np.mean(excess > 0.05) < 0.012


def test_corridor_of_a_route_that_passes_a_place_twice(monaco_net: Path) -> None:
    """Monaco 2951#5 -> 1520 runs out along 2951, round a loop (-2437, one 3.2 m lane) and
    back along -2951 beside its way out. Projected onto the nearest part of the reference
    line, bands of one pass landed on the other and widened -2437's stretch to 3.4 m,
    beyond the pavement at 14 % of the route's stations; each piece now projects onto its
    own part of the route."""
    net = load_network(monaco_net)
    cor = route_corridor(net, shortest_route(net, "2951#5", "1520", turnarounds=False))
    i = cor.edges.index("-2437")
    s = np.linspace(cor.edge_starts[i] + 5.0, cor.edge_ends[i] - 5.0, 50)
    right, left = cor.bounds_at(s)
    assert np.allclose(left - right, 3.2, atol=0.05)
    on_edges, in_junctions = _excess_on_edges_and_junctions(monaco_net, "2951#5", "1520")
    assert np.mean(np.concatenate((on_edges, in_junctions)) > 0.05) < 0.01


@pytest.mark.parametrize(("start", "goal"), [("A1B1", "D1D0"), ("B0C0", "C0C1")])
def test_corridor_knows_its_junctions(start: str, goal: str) -> None:
    """Each edge's own stretch is as long as its lanes (sumolib), and the stations
    between its end and the next edge's start lie in that junction's outline."""
    path = NETS / "grid.net.xml"
    net, sn = load_network(path), sumolib.net.readNet(str(path))
    cor = route_corridor(net, shortest_route(net, start, goal))
    assert len(cor.edge_ends) == len(cor.edges)
    window = cor.slice(100.0, cor.length)
    for i, edge in enumerate(cor.edges):
        start_s, end_s = cor.edge_starts[i], cor.edge_ends[i]
        assert end_s - start_s == pytest.approx(sn.getEdge(edge).getLength(), abs=1.0)
        assert cor.junction_at((start_s + end_s) / 2.0) is None
        if i + 1 == len(cor.edges):
            continue
        mid = (end_s + cor.edge_starts[i + 1]) / 2.0
        assert cor.junction_at(mid) == (edge, cor.edges[i + 1])
        outline = Polygon(sn.getEdge(edge).getToNode().getShape())
        assert outline.contains(Point(cor.to_xy(mid, 0.0)))
        if mid > 100.0:  # a slice keeps them
            assert window.junction_at(mid - 100.0) == (edge, cor.edges[i + 1])


@pytest.mark.parametrize(("start", "goal"), GRID_TURNS + GRID_CORNERS)
def test_corridor_through_junctions_is_paved_and_wide(start: str, goal: str) -> None:
    """Through a junction the corridor spans from the allowed lanes of one edge to those
    of the next (the kerb rounded as SUMO rounds it), not only the internal lanes' band,
    and stays on the paved area (lanes and junction outlines)."""
    path = NETS / "grid.net.xml"
    net = load_network(path)
    route = shortest_route(net, start, goal, turnarounds=False)
    cor = route_corridor(net, route)
    # both directions have two 3.2 m lanes: the corridor is never narrower than those
    assert float(np.min(cor.left - cor.right)) >= 6.4 - 0.05
    outside = Polygon(cor.polygon()).buffer(0).difference(paved_area(path).buffer(0.05))
    junctions = len(route.edges) - 1
    assert outside.area <= 0.5 * max(junctions, 1), outside.area


def test_corridor_bands_kept_per_network_give_the_same_corridor() -> None:
    # the second corridor of a route reuses the network's bands: the same arrays as a
    # corridor built on a fresh network, and the kept bands cannot be written to
    net = load_network(NETS / "city.net.xml")
    route = shortest_route(net, "SWA0", "G1G2")
    first = route_corridor(net, route)
    again = route_corridor(net, route)
    fresh = route_corridor(load_network(NETS / "city.net.xml"), route)
    for cor in (again, fresh):
        for name in ("reference", "s", "left", "right", "edge_starts", "edge_ends"):
            np.testing.assert_array_equal(getattr(cor, name), getattr(first, name))
    assert net._bands
    kinds = {key[0] for key in net._bands}
    assert {"edge", "junction", "paving", "internal"} <= kinds
    for band in net._bands.values():
        for arr in band if band is not None else ():
            with pytest.raises(ValueError):
                arr[(0,) * arr.ndim] = 0


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(1, 5), gap=st.sampled_from([0.0, 0.3, 1.0]))
def test_paved_spans_match_shapely(seed: int, n: int, gap: float) -> None:
    """The stretch of a line within a union of polygons (star-shaped, so non-convex)
    that holds a given point equals shapely's cut of the line with the union, its pieces
    less than ``gap`` apart joined."""
    from shapely.geometry import LineString
    from shapely.ops import unary_union

    from splineplan.network import _paved_spans

    rng = np.random.default_rng(seed)
    polys = []
    for _ in range(n):
        k = int(rng.integers(3, 9))
        ang = (np.arange(k) + rng.uniform(-0.3, 0.3, k)) * (2.0 * np.pi / k)
        rad = rng.uniform(0.5, 3.0, k)
        c = rng.uniform(-3.0, 3.0, 2)
        polys.append(np.column_stack((c[0] + rad * np.cos(ang), c[1] + rad * np.sin(ang))))
    union = unary_union([Polygon(p) for p in polys])
    h = rng.uniform(-np.pi, np.pi)
    t, nrm = np.array([np.cos(h), np.sin(h)]), np.array([-np.sin(h), np.cos(h)])
    centre = rng.uniform(-2.0, 2.0, 2)
    mids = np.linspace(-8.0, 8.0, 41)
    offsets = np.concatenate(([0], np.cumsum([len(p) for p in polys]))).astype(np.int64)
    xy = np.concatenate(polys)
    m = len(mids)
    lo, hi = _paved_spans(np.full(m, centre[0]), np.full(m, centre[1]), np.full(m, t[0]),
                          np.full(m, t[1]), mids, xy[:, 0].copy(), xy[:, 1].copy(), offsets,
                          gap)
    cut = LineString([centre - 20.0 * nrm, centre + 20.0 * nrm]).intersection(union)
    spans = [(float(np.dot(np.asarray(g.coords[0]) - centre, nrm)),
              float(np.dot(np.asarray(g.coords[-1]) - centre, nrm)))
             for g in getattr(cut, "geoms", [cut]) if not g.is_empty and g.length > 0]
    joined: list[list[float]] = []
    for a, b in sorted(tuple(sorted(sp)) for sp in spans):
        if joined and a <= joined[-1][1] + gap:
            joined[-1][1] = max(joined[-1][1], b)
        else:
            joined.append([a, b])
    spans = [(a, b) for a, b in joined]
    for j, mid in enumerate(mids):
        hold = [sp for sp in spans if sp[0] - 1e-9 <= mid <= sp[1] + 1e-9]
        if not hold:
            assert np.isnan(lo[j]) or min(abs(mid - lo[j]), abs(mid - hi[j])) < 1e-6
            continue
        assert lo[j] == pytest.approx(hold[0][0], abs=1e-7)
        assert hi[j] == pytest.approx(hold[0][1], abs=1e-7)
