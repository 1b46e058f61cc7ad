"""Metrics of driven paths: curvature and lateral acceleration from positions only."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from shapely.geometry import Polygon

from splineplan.metrics import dynamics, footprint, path_curvature, rectangle_distances


@pytest.mark.parametrize(("radius", "spacing"), [(8.0, 0.1), (20.0, 0.5), (60.0, 1.4)])
def test_curvature_of_a_circle(radius: float, spacing: float) -> None:
    """A circle driven counter-clockwise, sampled as a vehicle would at 0.1 s steps: the
    curvature is 1/R everywhere (three points of a circle)."""
    th = np.arange(0.0, 2.5, spacing / radius)
    k = path_curvature(radius * np.cos(th), radius * np.sin(th))
    assert k == pytest.approx(np.full(len(th), 1.0 / radius), rel=1e-9)
    # clockwise: negative
    k2 = path_curvature(radius * np.cos(-th), radius * np.sin(-th))
    assert k2 == pytest.approx(-k, rel=1e-9)


def test_standing_and_straight_give_no_curvature() -> None:
    rng = np.random.default_rng(3)
    s = np.concatenate((np.zeros(30), np.cumsum(rng.uniform(0.0, 1.4, 200))))  # waits first
    h = 0.7
    x, y = 5.0 + s * np.cos(h), -2.0 + s * np.sin(h)
    assert np.abs(path_curvature(x, y)).max() < 1e-9


def test_lateral_acceleration_ignores_reported_heading() -> None:
    """v^2 / R on a circle at constant speed, from positions and time; a noisy heading (or a
    wrong one) cannot enter the metric: it takes none."""
    radius, v, dt = 15.0, 9.0, 0.1
    t = np.arange(0.0, 8.0, dt)
    th = v * t / radius
    d = dynamics(t, radius * np.cos(th), radius * np.sin(th), np.full(len(t), v))
    assert d["a_lat"] == pytest.approx(np.full(len(t), v * v / radius), rel=1e-9)
    assert np.abs(d["a_lon"]).max() < 1e-9
    assert d["jerk"].max() < 0.05


@settings(max_examples=40, deadline=None)
@given(st.integers(0, 2**32 - 1))
def test_rectangle_distances_match_shapely(seed: int) -> None:
    """Distances between rectangles from centres and headings, against shapely on their
    corners: apart, touching, crossing with no corner inside, one inside the other."""
    rng = np.random.default_rng(seed)
    k = 60
    c = rng.uniform(-8, 8, (k, 2))
    h = rng.uniform(-4, 4, k)
    ln = rng.uniform(0.3, 12, k)
    w = rng.uniform(0.3, 3, k)
    x0, y0, h0 = rng.uniform(-1, 1), rng.uniform(-1, 1), rng.uniform(-4, 4)
    a = Polygon(footprint([x0, y0], h0, 4.5, 1.8))
    want = [a.distance(Polygon(footprint(c[i], h[i], ln[i], w[i]))) for i in range(k)]
    got = rectangle_distances([x0, y0], h0, 4.5, 1.8, c, h, ln, w)
    assert got == pytest.approx(want, abs=1e-9)


def test_rectangle_distances_crossing_and_containment() -> None:
    got = rectangle_distances([0, 0], 0.0, 10, 1, [[0, 0], [0, 0], [0, 0.75]],
                              [math.pi / 2, 0.0, 0.0], [10, 1, 3], [1, 0.5, 0.5])
    assert got.tolist() == [0.0, 0.0, pytest.approx(0.0)]  # cross, inside, touching
    assert rectangle_distances([0, 0], 0.0, 4, 2, [[5, 0]], [0.0], [2], [2]).tolist() == [
        pytest.approx(2.0)]
    assert rectangle_distances([0, 0], 0.0, 4, 2, np.zeros((0, 2)), [], [], []).shape == (0,)
