"""Bodies of long vehicles sweeping through junction turns (``splineplan.closedloop.bodies``):
the predicted rectangles against exact circle geometry and shapely."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st
from shapely.geometry import LineString, Polygon

from splineplan.closedloop.bodies import bodies_along, body_path, meeting, meetings


def _arc(radius: float, n: int = 400) -> np.ndarray:
    """A left turn of a quarter circle about the origin, with 30 m straight before and
    after (the lanes before and after a junction)."""
    a = np.linspace(-math.pi / 2.0, 0.0, n)
    arc = np.column_stack((radius * np.cos(a), radius * np.sin(a)))
    before = np.array([[-30.0, -radius], [0.0, -radius]])
    after = np.array([[radius, 0.0], [radius, 30.0]])
    return np.vstack((before, arc[1:], after[1:]))


@settings(max_examples=60, deadline=None)
@given(radius=st.floats(6.0, 30.0), length=st.floats(7.0, 18.0), speed=st.floats(0.5, 12.0))
def test_a_body_on_a_turn_is_the_chord_between_its_back_and_front(radius: float,
                                                                 length: float,
                                                                 speed: float) -> None:
    """While front and back are both on the arc (``length`` apart along it), the body's
    centre is the middle of the chord between them, R cos(L / 2R) from the turn's centre
    (inside the lane's centre line), and it heads square to that radius."""
    assume(length < radius * math.pi / 2.0)
    line = _arc(radius)
    path = body_path([(line, float(LineString(line).length))])
    t, centres, heads = bodies_along(path, 30.0 + length, speed, length, horizon=4.0)
    front = 30.0 + length + speed * t
    on_arc = front <= 30.0 + radius * math.pi / 2.0
    assert on_arc.any()
    r = np.hypot(centres[on_arc, 0], centres[on_arc, 1])
    assert np.allclose(r, radius * math.cos(length / (2.0 * radius)), atol=0.01)
    # heading square to the radius through the centre, turning left
    radial = np.arctan2(centres[on_arc, 1], centres[on_arc, 0])
    off = np.remainder(heads[on_arc] - radial - math.pi / 2.0 + math.pi, 2 * math.pi) - math.pi
    assert np.all(np.abs(off) < 0.02)


@given(speed=st.floats(0.1, 10.0), accel=st.floats(0.5, 3.0), top=st.floats(0.0, 12.0))
def test_a_body_speeding_up_covers_what_the_motion_law_says(speed: float, accel: float,
                                                             top: float) -> None:
    """A body inside a junction is predicted speeding up from ``speed`` at ``accel`` to
    ``top`` (SUMO's drivers drive on out of a junction): along a straight lane its centre
    covers v t + a t^2 / 2 until it is at ``top``, then ``top`` t on; at ``top`` below its
    speed, it keeps its speed."""
    line = np.array([[0.0, 0.0], [400.0, 0.0]])
    path = body_path([(line, 400.0)])
    t, centres, heads = bodies_along(path, 20.0, speed, 12.0, accel=accel, top=top,
                                     horizon=8.0)
    # the distance: the speed, min(v + a t, max(top, v)), summed over a fine grid
    fine = np.linspace(0.0, t[-1], 80001)
    v = np.minimum(speed + accel * fine, max(top, speed))
    covered = np.concatenate(([0.0], np.cumsum(0.5 * (v[1:] + v[:-1]) * np.diff(fine))))
    want = np.interp(t, fine, covered)
    assert np.allclose(centres[:, 0] - centres[0, 0], want, atol=1e-4)
    assert np.allclose(centres[:, 1], 0.0) and np.allclose(heads, 0.0)
    # never slower than at constant speed
    assert np.all(np.diff(centres[:, 0]) >= speed * np.diff(t) - 1e-9)


def test_a_long_body_sweeps_over_the_lane_beside_its_turn() -> None:
    """A 12 m bus turning on a 10 m radius lies 1.75 m inside its lane's centre line at
    its middle, over the lane beside the curve's inside: a car's path along that lane is
    met where and while the bus's body reaches it (shapely for the overlaps)."""
    radius, length, width = 10.0, 12.0, 2.5
    line = _arc(radius)
    path = body_path([(line, float(LineString(line).length))])
    t, centres, heads = bodies_along(path, 30.0, 8.0, length)
    # a car's path along the tangent of the circle 3.2 m inside the bus's lane, at the
    # turn's middle (45 degrees round it)
    inward = np.array([-math.sqrt(0.5), math.sqrt(0.5)])  # towards the turn's centre
    along = np.array([math.sqrt(0.5), math.sqrt(0.5)])
    mid = radius * -inward
    s = np.linspace(-4.0, 4.0, 81)
    xy = mid + 3.2 * inward + s[:, None] * along
    h = np.full(len(s), math.pi / 4.0)
    met = meeting(t, centres, heads, (length, width), s, xy, h, (4.5, 1.8), 0.0)
    assert met is not None
    s_in, s_out, t_in, t_out = met
    # shapely: the car's footprint at each sample against each body
    def box(c: np.ndarray, hd: float, ln: float, wd: float) -> Polygon:
        u, n = np.array([math.cos(hd), math.sin(hd)]), np.array([-math.sin(hd), math.cos(hd)])
        return Polygon([c + u * ln / 2 + n * wd / 2, c + u * ln / 2 - n * wd / 2,
                        c - u * ln / 2 - n * wd / 2, c - u * ln / 2 + n * wd / 2])
    bodies = [box(c, hd, length, width) for c, hd in zip(centres, heads, strict=True)]
    hits = [(k, i) for k, b in enumerate(bodies) for i in range(len(s))
            if b.intersects(box(xy[i], h[i], 4.5, 1.8))]
    assert hits
    assert math.isclose(s_in, min(s[i] for _, i in hits), abs_tol=1e-9)
    assert math.isclose(s_out, max(s[i] for _, i in hits), abs_tol=1e-9)
    assert math.isclose(t_in, min(t[k] for k, _ in hits), abs_tol=1e-9)
    assert math.isclose(t_out, max(t[k] for k, _ in hits), abs_tol=1e-9)
    # the same path 3 m farther inside is never met
    assert meeting(t, centres, heads, (length, width), s, xy + 3.0 * inward, h, (4.5, 1.8),
                   0.0) is None


def _box(c: np.ndarray, hd: float, ln: float, wd: float) -> Polygon:
    u, n = np.array([math.cos(hd), math.sin(hd)]), np.array([-math.sin(hd), math.cos(hd)])
    return Polygon([c + u * ln / 2 + n * wd / 2, c + u * ln / 2 - n * wd / 2,
                    c - u * ln / 2 - n * wd / 2, c - u * ln / 2 + n * wd / 2])


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), n_bodies=st.integers(1, 4))
def test_meetings_of_several_bodies_are_shapelys(seed: int, n_bodies: int) -> None:
    """Random rectangles of several bodies (each its size and margin) around a curved
    path: each body's first and last station and time met are those of the pairs whose
    shapely distance is within that body's margin."""
    rng = np.random.default_rng(seed)
    s = np.linspace(0.0, 30.0, 61)
    xy = np.column_stack((s, 0.01 * (s - 10.0) ** 2))
    h = np.arctan(0.02 * (s - 10.0))
    rows = rng.integers(3, 9, n_bodies)
    body = np.repeat(np.arange(n_bodies), rows)
    k = len(body)
    times = rng.uniform(0.0, 6.0, k)
    centres = np.column_stack((rng.uniform(-5.0, 35.0, k), rng.uniform(-6.0, 10.0, k)))
    heads = rng.uniform(-math.pi, math.pi, k)
    lengths = np.repeat(rng.uniform(4.0, 18.0, n_bodies), rows)
    widths = np.repeat(rng.uniform(1.6, 2.6, n_bodies), rows)
    margins = np.repeat(rng.uniform(0.0, 1.0, n_bodies), rows)
    got = meetings(body, n_bodies, times, centres, heads, lengths, widths, margins, s, xy,
                   h, (4.5, 1.8))
    ego = [_box(xy[i], h[i], 4.5, 1.8) for i in range(len(s))]
    for b in range(n_bodies):
        hits = [(times[r], s[i]) for r in np.flatnonzero(body == b) for i in range(len(s))
                if _box(centres[r], heads[r], lengths[r], widths[r]).distance(ego[i])
                <= margins[r] + 1e-9]
        if not hits:
            assert np.isnan(got[b]).all()
            continue
        tt, ss = zip(*hits, strict=True)
        assert got[b] == pytest.approx([min(ss), max(ss), min(tt), max(tt)])
