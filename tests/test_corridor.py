"""Corridor: Frenet frame, boundaries, slicing, segments."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from shapely.geometry import Point, Polygon

from splineplan.corridor import Corridor
from splineplan.errors import GeometryError


def arc_corridor(radius: float = 30.0, angle: float = 1.5, width: float = 8.0) -> Corridor:
    """A left-turning arc about (0, radius), built from its two boundary polylines."""
    th = np.linspace(0.0, angle, 400)

    def ring(rad: float) -> np.ndarray:
        return np.column_stack((rad * np.sin(th), radius - rad * np.cos(th)))

    return Corridor.from_boundaries(ring(radius - width / 2), ring(radius + width / 2))


def test_straight_from_boundaries() -> None:
    c = Corridor.from_boundaries([[0, 3], [50, 3]], [[0, -1], [50, -1]])
    assert c.length == pytest.approx(50.0)
    np.testing.assert_allclose(c.left, 2.0)
    np.testing.assert_allclose(c.right, -2.0)
    np.testing.assert_allclose(c.reference[:, 1], 1.0)
    np.testing.assert_allclose(c.to_xy(10.0, 0.5), [10.0, 1.5])
    np.testing.assert_allclose(c.heading_at([0.0, 25.0, 50.0]), 0.0)
    assert Polygon(c.polygon()).area == pytest.approx(200.0)


def test_arc_offsets_and_stations() -> None:
    c = arc_corridor()
    np.testing.assert_allclose(c.left, 4.0, atol=2e-3)
    np.testing.assert_allclose(c.right, -4.0, atol=2e-3)
    assert c.length == pytest.approx(30.0 * 1.5, rel=1e-3)
    # stations grow along the centre arc: a point at angle t sits at s = 30 t
    t = 0.7
    sl = c.to_sl([[30.0 * np.sin(t), 30.0 - 30.0 * np.cos(t)]])[0]
    assert sl[0] == pytest.approx(21.0, abs=1e-2) and sl[1] == pytest.approx(0.0, abs=2e-3)
    # left of travel is towards the turn's centre
    sl = c.to_sl([[26.0 * np.sin(t), 30.0 - 26.0 * np.cos(t)]])[0]
    assert sl[1] == pytest.approx(4.0, abs=2e-3)
    assert c.heading_at(21.0) == pytest.approx(0.7, abs=1e-2)


@settings(max_examples=40, deadline=None)
@given(s=st.floats(0.0, 44.9), lat=st.floats(-3.99, 3.99))
def test_to_sl_inverts_to_xy_on_a_curve(s: float, lat: float) -> None:
    c = arc_corridor()
    xy = c.to_xy(s, lat)
    back = c.to_sl(xy[None])[0]
    np.testing.assert_allclose(c.to_xy(*back), xy, atol=1e-6)
    # the reference is a polyline: on the inner side of a vertex the normals of its two
    # segments overlap, so (s, l) is unique only up to |l| times the heading step there
    step = float(np.max(np.abs(np.diff(c.heading_at((c.s[:-1] + c.s[1:]) / 2)))))
    assert back[0] == pytest.approx(s, abs=abs(lat) * step + 1e-6)
    assert back[1] == pytest.approx(lat, abs=abs(lat) * step**2 + 1e-6)


def test_contains_and_bounds_agree_with_shapely() -> None:
    c = arc_corridor()
    rng = np.random.default_rng(1)
    pts = rng.uniform([-5, -5], [35, 40], (400, 2))
    poly = Polygon(c.polygon())
    inside = np.array([poly.contains(Point(p)) for p in pts])
    near_edge = np.array([poly.exterior.distance(Point(p)) < 0.05 for p in pts])
    got = c.contains(pts)
    assert np.all(got[~near_edge] == inside[~near_edge])
    # with a margin: inside by at least the margin (up to the polyline's sagitta)
    deep = c.contains(pts, margin=1.0)
    assert all(poly.exterior.distance(Point(p)) >= 1.0 - 0.01 for p in pts[deep])


def test_slice_and_edges() -> None:
    ref = np.array([[0.0, 0.0], [100.0, 0.0]])
    c = Corridor.from_reference(ref, [3, 3], [-3, -3], edges=("a", "b", "c"),
                                edge_starts=(0, 40, 70), offset=10.0)
    assert [c.edge_at(s) for s in (0, 39.9, 40, 69, 99)] == ["a", "a", "b", "b", "c"]
    part = c.slice(50.0, 80.0)
    assert part.length == pytest.approx(30.0)
    assert part.offset == pytest.approx(60.0)
    assert part.edges == ("b", "c")
    np.testing.assert_allclose(part.edge_starts, [0.0, 20.0])
    np.testing.assert_allclose(part.to_xy(0.0, 1.0), [50.0, 1.0])
    with pytest.raises(GeometryError):
        c.slice(50.0, 50.0)


def test_extend_back_adds_road_before_the_start() -> None:
    """A corridor extended back by 4 m: straight along its first segment, with its first
    boundaries; stations restart there, the whole route's stations (offset) stay, and the
    first edge covers the extension. A point 2 m behind the old start lies on it."""
    ref = np.array([[0.0, 0.0], [0.0, 100.0]])
    c = Corridor.from_reference(ref, [3, 2], [-3, -2], edges=("a", "b"), edge_starts=(0, 40),
                                offset=10.0)
    e = c.extend_back(4.0)
    assert e.length == pytest.approx(104.0)
    assert e.offset == pytest.approx(6.0)
    assert e.edges == ("a", "b")
    np.testing.assert_allclose(e.edge_starts, [0.0, 44.0])
    np.testing.assert_allclose(e.to_xy(0.0, 0.0), [0.0, -4.0], atol=1e-9)
    s, lat = e.to_sl(np.array([[1.0, -2.0]]))[0]
    assert s == pytest.approx(2.0) and lat == pytest.approx(-1.0)
    assert bool(e.contains(np.array([[1.0, -2.0]]))[0])
    np.testing.assert_allclose(e.bounds_at([1.0]), ([-3.0], [3.0]))
    np.testing.assert_allclose(e.to_xy(44.0, 0.0), c.to_xy(40.0, 0.0), atol=1e-9)
    assert c.extend_back(0.0) is c


@given(s=st.floats(0.0, 44.9), lat=st.floats(-5.0, 5.0), back=st.floats(0.1, 10.0))
def test_extend_back_keeps_the_road_and_leads_into_it(s: float, lat: float,
                                                     back: float) -> None:
    """On a curved corridor extended back: every point of the road is where it was, at its
    station plus the extension; a point the extension covers lies on the line of the first
    segment, within the first boundaries."""
    c = arc_corridor()
    e = c.extend_back(back)
    np.testing.assert_allclose(e.to_xy(s + back, lat), c.to_xy(s, lat), atol=1e-6)
    np.testing.assert_allclose(e.bounds_at([s + back]), c.bounds_at([s]), atol=1e-9)
    behind = e.to_xy(back / 2.0, lat)
    d = c.reference[1] - c.reference[0]
    d = d / np.hypot(*d)
    rel = behind - c.reference[0]
    assert float(rel @ d) == pytest.approx(-back / 2.0, abs=1e-6)
    assert bool(e.contains(behind[None])[0]) == bool(c.right[0] <= lat <= c.left[0])


@pytest.mark.parametrize(("length", "overlap"), [(30.0, 0.0), (30.0, 5.0), (200.0, 10.0)])
def test_segments_cover_the_corridor(length: float, overlap: float) -> None:
    c = arc_corridor()
    parts = c.segments(length, overlap)
    assert parts[0].offset == 0.0
    assert parts[-1].offset + parts[-1].length == pytest.approx(c.length)
    for a, b in itertools.pairwise(parts):
        assert a.length <= length + 1e-9
        assert a.offset + a.length - b.offset == pytest.approx(overlap)
        np.testing.assert_allclose(b.to_xy(0.0, 2.0), c.to_xy(b.offset, 2.0), atol=1e-9)
    with pytest.raises(GeometryError):
        c.segments(5.0, 5.0)


def test_malformed_corridors_raise() -> None:
    with pytest.raises(GeometryError):
        Corridor.from_boundaries([[0, 1]], [[0, -1]])
    with pytest.raises(GeometryError):
        Corridor.from_boundaries([[0, 1], [0, 1]], [[0, -1], [0, -1]])
    with pytest.raises(GeometryError):
        Corridor.from_boundaries([[0, 1], [np.nan, 1]], [[0, -1], [5, -1]])
    with pytest.raises(GeometryError):  # no width
        Corridor.from_reference([[0, 0], [10, 0]], [1, 1], [1, 1])
    with pytest.raises(GeometryError):
        Corridor.from_reference([[0, 0], [10, 0]], [1, 1, 1], [-1, -1])
    with pytest.raises(GeometryError):
        Corridor.from_reference([[0, 0], [10, 0]], [1, 1], [-1, -1], edges=("a",))


def test_keep_offsets_are_checked_sliced_and_unbounded_by_default() -> None:
    """Keep offsets come in pairs, one value per station; a slice carries them at its
    stations; without them ``keep_at`` is unbounded."""
    from splineplan.corridor import UNBOUNDED

    ref = np.array([[0.0, 0.0], [100.0, 0.0]])
    plain = Corridor.from_reference(ref, np.full(2, 3.2), np.full(2, -3.2))
    n = len(plain.s)
    right, left = plain.keep_at([0.0, 50.0])
    assert np.all(right == -UNBOUNDED) and np.all(left == UNBOUNDED)
    keep_l = np.where(plain.s > 70.0, 0.0, UNBOUNDED)
    keep_r = np.where(plain.s > 70.0, -3.2, -UNBOUNDED)
    kept = Corridor(plain.reference, plain.s, plain.left, plain.right,
                    keep_left=keep_l, keep_right=keep_r)
    part = kept.slice(60.0, 90.0)
    r, lft = part.keep_at([5.0, 20.0])  # stations 65 and 80 of the whole
    assert lft[0] == UNBOUNDED and r[0] == -UNBOUNDED
    assert lft[1] == pytest.approx(0.0) and r[1] == pytest.approx(-3.2)
    with pytest.raises(GeometryError, match="keep offsets"):
        Corridor(plain.reference, plain.s, plain.left, plain.right, keep_left=keep_l)
    with pytest.raises(GeometryError, match="keep offsets"):
        Corridor(plain.reference, plain.s, plain.left, plain.right,
                 keep_left=keep_l[: n - 1], keep_right=keep_r[: n - 1])


@settings(max_examples=40, deadline=None)
@given(st.integers(0, 10_000), st.sampled_from(["spiral", "hairpin", "straight"]))
def test_nearest_reference_vertex_from_the_bucket_grid_is_the_true_nearest(
        seed: int, shape: str) -> None:
    """to_sl's nearest-vertex search (a bucket grid; -1 hands far points to a k-d tree)
    against brute force, on reference lines that come back near themselves; and to_sl
    against the same projection from the k-d tree's nearest vertex."""
    from scipy.spatial import cKDTree
    from scipy.spatial.distance import cdist

    from splineplan.corridor import GRID_RINGS, _grid_nearest, _project_kernel

    rng = np.random.default_rng(seed)
    t = np.linspace(0.0, 1.0, 400)
    if shape == "spiral":
        ref = np.column_stack((np.cos(9 * t) * (20 + 60 * t), np.sin(9 * t) * (20 + 60 * t)))
    elif shape == "hairpin":
        ref = np.column_stack((np.where(t < 0.5, 200 * t, 200 * (1 - t)),
                               np.where(t < 0.5, 0.0, 7.0) + np.sin(40 * t)))
    else:
        ref = np.column_stack((300 * t, np.zeros_like(t)))
    road = Corridor.from_reference(ref, np.full(len(t), 3.0), np.full(len(t), -3.0))
    near = road.reference[rng.integers(0, len(road.reference), 300)] + rng.normal(0, 3, (300, 2))
    far = rng.uniform(-500, 500, (30, 2))
    pts = np.vstack((near, far))
    px, py = pts[:, 0].copy(), pts[:, 1].copy()
    got = _grid_nearest(px, py, road._ref_x, road._ref_y, *road._grid, GRID_RINGS)
    want = np.argmin(cdist(pts, road.reference), axis=1)
    found = got >= 0
    assert found[:300].all()  # points within a few metres of the road: never the tree
    np.testing.assert_array_equal(got[found], want[found])
    k = cKDTree(road.reference).query(pts)[1].astype(np.int64)
    np.testing.assert_array_equal(
        road.to_sl(pts),
        _project_kernel(px, py, k, road._ref_x, road._ref_y, road._cos, road._sin, road._s))
