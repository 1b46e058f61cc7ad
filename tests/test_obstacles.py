"""Obstacles: boxes and polygons in one array form; distances against shapely."""

from __future__ import annotations

import numpy as np
import pytest
from shapely.geometry import Point, Polygon

from splineplan.errors import GeometryError
from splineplan.geometry import heading_from_sumo_angle
from splineplan.obstacles import Obstacles


def test_box_from_front_bumper_like_sumo() -> None:
    # SUMO: position = middle of the front bumper, angle 90 deg = heading east
    head = heading_from_sumo_angle([90.0, 0.0])
    obs = Obstacles.from_boxes([[10.0, 2.0], [0.0, 5.0]], head, [5.0, 4.0], [2.0, 1.8],
                               reference="front", ids=["v0", "v1"])
    east = Polygon(obs.polygon(0))
    assert east.bounds == pytest.approx((5.0, 1.0, 10.0, 3.0))
    north = Polygon(obs.polygon(1))  # facing north: front at y = 5, rear at y = 1
    assert north.bounds == pytest.approx((-0.9, 1.0, 0.9, 5.0))
    assert obs.ids == ("v0", "v1")
    centre = Obstacles.from_boxes([[7.5, 2.0]], head[:1], [5.0], [2.0])
    np.testing.assert_allclose(centre.polygon(0), obs.polygon(0))


def test_polygons_are_counter_clockwise_and_closed_rings_accepted() -> None:
    cw = np.array([[0, 0], [0, 1], [1, 1], [1, 0], [0, 0]], float)
    obs = Obstacles.from_polygons([cw])
    p = obs.polygon(0)
    assert len(p) == 4
    area2 = np.sum(p[:, 0] * np.roll(p[:, 1], -1) - np.roll(p[:, 0], -1) * p[:, 1])
    assert area2 > 0


def test_distance_matches_shapely() -> None:
    rng = np.random.default_rng(3)
    polys = [np.array([[0, 0], [4, 0], [4, 4], [2, 1], [0, 4]], float),  # non-convex
             np.array([[10, 0], [12, 1], [11, 3]], float)]
    obs = Obstacles.from_polygons(polys) + Obstacles.from_boxes(
        [[5.0, 8.0]], [0.4], [4.5], [1.8])
    pts = rng.uniform([-3, -3], [15, 12], (300, 2))
    shp = [Polygon(p) for p in obs.polygons()]
    want = np.array([min(s.distance(Point(q)) for s in shp) for q in pts])
    np.testing.assert_allclose(obs.distance(pts), want, atol=1e-9)
    assert len(obs) == 3


def test_near_subset_and_bbox() -> None:
    obs = Obstacles.from_boxes([[0.0, 0.0], [50.0, 0.0]], [0.0, 0.0], [4.0, 4.0], [2.0, 2.0],
                               ids=["a", "b"])
    np.testing.assert_allclose(obs.bbox, [[-2, -1, 2, 1], [48, -1, 52, 1]])
    assert obs.near([[10.0, 0.0]], 8.5).ids == ("a",)
    assert obs.near([[10.0, 0.0]], 7.5).ids == ()
    assert obs.subset([False, True]).ids == ("b",)
    assert len(Obstacles.empty()) == 0
    assert np.all(np.isinf(Obstacles.empty().distance([[0.0, 0.0]])))


def test_malformed_obstacles_raise() -> None:
    with pytest.raises(GeometryError):
        Obstacles.from_polygons([np.zeros((3, 3))])
    with pytest.raises(GeometryError):
        Obstacles.from_polygons([np.array([[0, 0], [1, 1], [2, 2]], float)])  # no area
    with pytest.raises(GeometryError):
        Obstacles.from_polygons([np.array([[0, 0], [1, 0], [1, 1]], float)], ids=["a", "b"])
    with pytest.raises(GeometryError):
        Obstacles.from_boxes([[0.0, 0.0]], [np.inf], [1.0], [1.0])
    with pytest.raises(GeometryError):
        Obstacles.from_boxes([[0.0, 0.0]], [0.0], [1.0], [1.0], reference="rear")  # type: ignore


@pytest.mark.parametrize("seed", range(4))
def test_elongated_matches_qhull_also_along_the_boxes_axes(seed: int) -> None:
    # the same hull vertices, in the same cyclic order, as scipy's Qhull; also where the
    # sweep runs along a box's own axis (corners that only rounding lifts off a side)
    from scipy.spatial import ConvexHull

    rng = np.random.default_rng(seed)
    k = 40
    pos = rng.uniform(-3000.0, 3000.0, (k, 2))
    head = rng.choice([0.0, np.pi / 2, -np.pi / 2, np.pi, 0.3], k) + rng.choice(
        [0.0, rng.uniform(-np.pi, np.pi)])
    boxes = Obstacles.from_boxes(pos, head, rng.uniform(1.0, 8.0, k), rng.uniform(1.0, 3.0, k))
    polys = Obstacles.from_polygons(
        [pos[i] + rng.uniform(-5.0, 5.0, (int(rng.integers(3, 9)), 2)) for i in range(k)])
    sweep = head + rng.choice([0.0, np.pi / 2, np.pi, 0.7], k)
    for obs in (boxes, polys):
        out = obs.elongated(sweep, 1.35)
        assert out.ids == obs.ids
        for i in range(k):
            shift = 1.35 * np.array([np.cos(sweep[i]), np.sin(sweep[i])])
            pts = np.concatenate((obs.polygon(i) + shift, obs.polygon(i) - shift))
            ref = pts[ConvexHull(pts).vertices]
            got = out.polygon(i)
            assert len(got) == len(ref)
            j = np.flatnonzero((got == ref[0]).all(axis=1))
            assert len(j) == 1
            np.testing.assert_array_equal(np.roll(got, -j[0], axis=0), ref)


def test_elongated_rejects_bad_input_and_keeps_zero() -> None:
    obs = Obstacles.from_boxes([[0.0, 0.0]], [0.0], [4.0], [2.0])
    assert obs.elongated([0.0], 0.0) is obs
    with pytest.raises(GeometryError, match="elongation"):
        obs.elongated([0.0], -1.0)
    with pytest.raises(GeometryError, match="directions"):
        obs.elongated([np.nan], 1.0)
