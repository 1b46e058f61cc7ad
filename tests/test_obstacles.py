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
