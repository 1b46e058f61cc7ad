"""Metrics of driven paths: curvature and lateral acceleration from positions only."""

from __future__ import annotations

import numpy as np
import pytest

from splineplan.metrics import dynamics, path_curvature


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
