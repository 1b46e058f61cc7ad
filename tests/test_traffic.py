"""The closed loop's per-step road and traffic checks (splineplan.traffic) against
independent oracles: shapely, sumolib's lanes, a k-d tree and numpy brute force."""

from __future__ import annotations

import math

import numpy as np
import pytest
import sumolib
from conftest import NETS
from hypothesis import assume, given, settings
from hypothesis import strategies as st
from shapely.geometry import Polygon

from splineplan.metrics import footprint
from splineplan.network import load_network, route_corridor
from splineplan.route import shortest_route


def test_road_check_matches_shapely_lane_bands() -> None:
    """The per-step road check (lane segments kept near the ego, the ones that held it last
    step tried first) against an independent oracle: sumolib's lanes buffered by half their
    width plus the tolerance, and the junction areas, in shapely. Footprints wander along
    the city route and off it."""
    from shapely.geometry import LineString, Point
    from shapely.ops import unary_union
    from shapely.prepared import prep

    from splineplan.traffic import OFF_ROAD_TOLERANCE, RoadCheck

    path = NETS / "city.net.xml"
    snet = sumolib.net.readNet(str(path), withInternal=True)
    lanes = [ln for e in snet.getEdges(withInternal=True) for ln in e.getLanes()
             if ln.allows("passenger") and len(ln.getShape()) >= 2]
    junctions = [Polygon(n.getShape()) for n in snet.getNodes() if len(n.getShape()) >= 3]
    road = unary_union([LineString(ln.getShape()).buffer(ln.getWidth() / 2 + OFF_ROAD_TOLERANCE)
                        for ln in lanes] + [j.buffer(OFF_ROAD_TOLERANCE) for j in junctions])
    inside, edge = prep(road), road.boundary
    mine = load_network(path)
    check = RoadCheck(mine, "passenger")
    check.add_junctions([np.asarray(n.getShape()) for n in snet.getNodes()
                         if len(n.getShape()) >= 3])
    corridor = route_corridor(mine, shortest_route(mine, "SWA0", "G1G2"))
    rng = np.random.default_rng(5)
    lat, agree, off = 0.0, 0, 0
    for s in np.arange(2.0, corridor.length - 2.0, 0.4):
        r, lft = (float(v[0]) for v in corridor.bounds_at([s]))
        lat = float(np.clip(lat + rng.normal(0.0, 0.25), r - 1.5, lft + 1.5))
        x, y = corridor.to_xy([s], [lat])[0]
        h = float(corridor.heading_at([s])[0]) + rng.normal(0.0, 0.1)
        box = footprint([x, y], h, 4.5, 1.8)
        probe = np.vstack((box, (box + np.roll(box, -1, axis=0)) / 2.0))
        if min(edge.distance(Point(p)) for p in probe) < 1e-3:
            continue  # on the oracle's polygonal boundary: either answer is right
        want = all(inside.contains(Point(p)) for p in probe)
        got = check.contains_all(probe, centre=(float(x), float(y)),
                                 radius=math.hypot(4.5, 1.8) / 2.0)
        assert got == want, (s, lat)
        assert bool(check.contains(probe).all()) == want
        agree += 1
        off += not want
    assert agree > 2000 and 50 < off < agree - 500


# ---- the per-step checks' shortcuts: never less strict than the exact checks ---------------

_coord = st.floats(-30.0, 30.0, allow_nan=False)
_size = st.floats(0.5, 12.0, allow_nan=False)
_angle = st.floats(-4.0, 4.0, allow_nan=False)


@settings(max_examples=60, deadline=None)
@given(x=_coord, y=_coord, h=_angle, length=_size, width=_size, ox=_coord, oy=_coord,
       oh=_angle, olength=_size, owidth=_size)
def test_bounding_circles_never_drop_a_collision(x: float, y: float, h: float, length: float,
                                                  width: float, ox: float, oy: float,
                                                  oh: float, olength: float,
                                                  owidth: float) -> None:
    """The safety check measures exactly only the vehicles whose bounding circles come within
    2 m of the ego's: their gap is a lower bound of the rectangles' distance (shapely)."""
    from splineplan.metrics import rectangle_distances

    bound = math.dist((x, y), (ox, oy)) - 0.5 * (math.hypot(length, width)
                                                 + math.hypot(olength, owidth))
    exact = Polygon(footprint([x, y], h, length, width)).distance(
        Polygon(footprint([ox, oy], oh, olength, owidth)))
    assert bound <= exact + 1e-9
    got = rectangle_distances((x, y), h, length, width, [[ox, oy]], [oh], [olength], [owidth])
    assert got[0] == pytest.approx(exact, abs=1e-9)


@settings(max_examples=60, deadline=None)
@given(cx=_coord, cy=_coord, h=_angle, length=_size, width=_size, reach=st.floats(0.1, 2.0),
       seed=st.integers(0, 2**16))
def test_path_samples_in_reach_are_in_the_bounding_circle(cx: float, cy: float, h: float,
                                                          length: float, width: float,
                                                          reach: float, seed: int) -> None:
    """The time-gap check looks only at the path samples within a vehicle's bounding circle
    plus the reach (a walk that jumps over samples the distance bound rules out); any
    sample within reach of its footprint is among them, the walk finds the circle's
    first sample (as a k-d tree query), and the first one in reach of the footprint found
    with plain floats is shapely's first (a path crossing a long side between the
    corners counts)."""
    from scipy.spatial import cKDTree
    from shapely.geometry import Point, Polygon

    from splineplan.traffic import first_in_box_reach, next_in_circle

    rng = np.random.default_rng(seed)
    # a random walk near the vehicle: consecutive samples at most 0.5 m apart
    steps = rng.uniform(-0.35, 0.35, (400, 2))
    samples = np.array([cx, cy]) + rng.uniform(-12, 12, 2) + np.cumsum(steps, axis=0)
    xs, ys = samples[:, 0].tolist(), samples[:, 1].tolist()
    step = float(np.hypot(*np.diff(samples, axis=0).T).max()) * (1.0 + 1e-9)
    c, s = math.cos(h), math.sin(h)
    body = Polygon([(cx + a * c - b * s, cy + a * s + b * c)
                    for a, b in ((length / 2, width / 2), (-length / 2, width / 2),
                                 (-length / 2, -width / 2), (length / 2, -width / 2))])
    dist = np.array([body.distance(Point(p)) for p in samples])
    assume(not np.any(np.abs(dist - reach) < 1e-9))  # none on the boundary's rounding
    want = np.flatnonzero(dist <= reach)
    r = 0.5 * math.hypot(length, width) + reach
    ball = cKDTree(samples).query_ball_point([[cx, cy]], [r], return_sorted=True)[0]
    assert set(want.tolist()) <= set(ball)
    start = int(rng.integers(0, len(samples) + 1))
    later_ball = [i for i in ball if i >= start]
    lo = next_in_circle(xs, ys, start, cx, cy, r, step)
    assert lo == (later_ball[0] if later_ball else -1)
    later = want[want >= start]
    got = first_in_box_reach(start, (cx, cy, r, step), (c, s, length / 2.0, width / 2.0),
                             xs, ys, reach)
    assert got == (int(later[0]) if len(later) else -1)


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**16), n_seg=st.integers(1, 6))
def test_lane_bands_with_plain_floats_match_arrays(seed: int, n_seg: int) -> None:
    """The road check's common case (the footprint against the lane segments that held it
    last step, with plain floats) agrees with the array version."""
    from splineplan.traffic import _in_bands, _in_rows

    rng = np.random.default_rng(seed)
    a = rng.uniform(-10, 10, (n_seg, 2))
    ab = rng.uniform(-8, 8, (n_seg, 2))
    ab[0] = 0.0  # a zero-length segment
    ln2 = (ab**2).sum(axis=1)
    segs = (a[:, 0], a[:, 1], ab[:, 0], ab[:, 1], 1.0 / np.where(ln2 > 0, ln2, 1.0),
            rng.uniform(0.5, 3.0, n_seg) ** 2)
    rows = list(zip(*(v.tolist() for v in segs), strict=True))
    for _ in range(20):
        pts = rng.uniform(-12, 12, (8, 2))
        assert _in_rows(pts.tolist(), rows) == bool(_in_bands(pts, segs).all())
        pick = rng.integers(0, n_seg, 8)
        near = a[pick] + rng.uniform(0, 1, (8, 1)) * ab[pick] + rng.uniform(-1, 1, (8, 2))
        assert _in_rows(near.tolist(), rows) == bool(_in_bands(near, segs).all())
