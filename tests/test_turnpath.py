"""The search for a path through a junction's paving (:mod:`splineplan.turnpath`), checked
on random curved roads by shapely: an open road is always driven, the path's footprints
stay on it and its turns keep the turning limit; a road cut across is never driven."""

from __future__ import annotations

import math

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st
from shapely.geometry import Polygon
from shapely.ops import unary_union

from splineplan.turnpath import STEP, search

LENGTH, WIDTH, RADIUS = 4.5, 1.8, 4.2
STUB = 8.0


def _road(inner: float, width: float, turn: float, cut: float | None = None
          ) -> tuple[list[Polygon], np.ndarray, np.ndarray]:
    """A road that runs east for :data:`STUB` metres, turns left on a ring of ``inner``
    radius and ``width`` by ``turn`` [rad], and runs on for :data:`STUB` metres: its pieces
    (cut across by a 1 m gap at ``cut``, a share of the turn), a start pose on its centre
    line in the first stub and goal poses in the last."""
    mid = inner + width / 2.0
    centre = np.array([0.0, mid])  # the ring's centre: the road starts at (0, 0) heading east

    def ring(a0: float, a1: float) -> Polygon:
        a = np.linspace(a0, a1, max(int(abs(a1 - a0) / 0.02), 2))
        outer = centre + (inner + width) * np.column_stack((np.sin(a), -np.cos(a)))
        inside = centre + inner * np.column_stack((np.sin(a), -np.cos(a)))
        return Polygon(np.vstack((outer, inside[::-1])))

    half = width / 2.0
    first = Polygon([(-STUB, -half), (0.0, -half), (0.0, half), (-STUB, half)])
    d = np.array([math.cos(turn), math.sin(turn)])
    n = np.array([-d[1], d[0]])
    end = centre + mid * np.array([math.sin(turn), -math.cos(turn)])
    last = Polygon([end - half * n, end + STUB * d - half * n, end + STUB * d + half * n,
                    end + half * n])
    if cut is None:
        pieces = [first, ring(0.0, turn), last]
    else:
        gap = 1.0 / mid
        pieces = [first, ring(0.0, cut * turn - gap / 2), ring(cut * turn + gap / 2, turn),
                  last]
    start = np.array([[-STUB + LENGTH / 2.0 + 0.5, 0.0, 0.0]])
    goals = np.array([[*(end + u * d), turn] for u in np.arange(2.0, STUB - LENGTH / 2.0, 0.5)])
    return pieces, start, goals


def _packed(polys: list[Polygon]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    pts = [np.asarray(p.exterior.coords)[:-1] for p in polys]
    offsets = np.concatenate(([0], np.cumsum([len(p) for p in pts]))).astype(np.int64)
    xy = np.concatenate(pts)
    return np.ascontiguousarray(xy[:, 0]), np.ascontiguousarray(xy[:, 1]), offsets


def _footprint(x: float, y: float, h: float) -> Polygon:
    c, s = math.cos(h), math.sin(h)
    corners = [(a, b) for a, b in ((LENGTH / 2, WIDTH / 2), (-LENGTH / 2, WIDTH / 2),
                                   (-LENGTH / 2, -WIDTH / 2), (LENGTH / 2, -WIDTH / 2))]
    return Polygon([(x + a * c - b * s, y + a * s + b * c) for a, b in corners])


@settings(max_examples=25, deadline=None)
@given(inner=st.floats(5.0, 30.0), width=st.floats(3.5, 8.0),
       turn=st.floats(math.radians(30), math.radians(150)))
def test_an_open_curved_road_is_driven_on_the_paving(inner: float, width: float,
                                                     turn: float) -> None:
    """A curved road wide enough for the car (its ring's inner radius at least the turning
    radius plus a margin, as wide as a lane or more) is always driven; every pose's
    footprint lies on the road (shapely, within 1 cm: the raster's cells are 10 cm and the
    discs that cover the car reach beyond it), and the heading turns no faster than the
    turning limit allows over each step."""
    pieces, start, goals = _road(inner, width, turn)
    path = search(_packed(pieces), start, goals, np.full(len(goals), 0.5), length=LENGTH,
                  width=WIDTH, kappa_max=1.0 / RADIUS)
    assert path is not None
    road = unary_union(pieces).buffer(0.01)
    assert all(road.contains(_footprint(*p)) for p in path)
    steps = np.hypot(*np.diff(path[:, :2], axis=0).T)
    assert np.allclose(steps, STEP, atol=0.02)  # a chord of each arc
    turned = np.abs(np.diff(np.unwrap(path[:, 2])))
    assert turned.max() <= STEP / RADIUS + 1e-9
    assert abs(path[-1, 2] - turn) <= 0.13  # at a goal, heading along the road


@settings(max_examples=10, deadline=None)
@given(inner=st.floats(5.0, 30.0), width=st.floats(3.5, 8.0),
       turn=st.floats(math.radians(30), math.radians(150)), cut=st.floats(0.1, 0.9))
def test_a_road_cut_across_is_never_driven(inner: float, width: float, turn: float,
                                           cut: float) -> None:
    """The same road with a 1 m gap across its ring: no path."""
    pieces, start, goals = _road(inner, width, turn, cut)
    assert search(_packed(pieces), start, goals, np.full(len(goals), 0.5), length=LENGTH,
                  width=WIDTH, kappa_max=1.0 / RADIUS) is None


def test_a_ring_tighter_than_the_turning_circle_is_not_driven() -> None:
    """A lane-wide ring whose centre line bends on 3 m (the car turns on 4.2 m at best)
    leaves the car no path; the same ring on 9 m does."""
    for inner, found in ((1.5, False), (7.5, True)):
        pieces, start, goals = _road(inner, 3.2, math.radians(90))
        path = search(_packed(pieces), start, goals, np.full(len(goals), 0.5),
                      length=LENGTH, width=WIDTH, kappa_max=1.0 / RADIUS)
        assert (path is not None) == found
