"""Bodies of long vehicles sweeping through junction turns (``splineplan.closedloop.bodies``):
the predicted rectangles against exact circle geometry, shapely and SUMO's own."""

from __future__ import annotations

import math

import libsumo
import numpy as np
import pytest
from conftest import NETS
from hypothesis import assume, given, settings
from hypothesis import strategies as st
from shapely.geometry import LineString, Polygon

from splineplan.closedloop.bodies import bodies_along, body_path, meeting, meetings
from splineplan.geometry import heading_from_sumo_angle
from splineplan.network import load_network


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
def test_a_body_on_a_turn_is_sumos_rectangle_from_its_front(radius: float, length: float,
                                                           speed: float) -> None:
    """While front and back are both on the arc (``length`` apart along it), the body heads
    along the chord from back to front and its front edge's middle is the front: the
    rectangle of ``length`` behind the front reaches (L - chord) past the back."""
    assume(length < radius * math.pi / 2.0)
    line = _arc(radius)
    path = body_path([(line, float(LineString(line).length))])
    t, centres, heads = bodies_along(path, 30.0 + length, speed, length, horizon=4.0)
    front = 30.0 + length + speed * t
    on_arc = front <= 30.0 + radius * math.pi / 2.0
    assert on_arc.any()
    # the front and back on the arc: angles from the turn's start (-pi/2) by arc length
    a_front = -math.pi / 2.0 + (front[on_arc] - 30.0) / radius
    a_back = a_front - length / radius
    f = radius * np.column_stack((np.cos(a_front), np.sin(a_front)))
    b = radius * np.column_stack((np.cos(a_back), np.sin(a_back)))
    u = (f - b) / np.hypot(*(f - b).T)[:, None]
    assert np.allclose(centres[on_arc], f - 0.5 * length * u, atol=0.01)
    assert np.allclose(np.cos(heads[on_arc]), u[:, 0], atol=1e-3)
    assert np.allclose(np.sin(heads[on_arc]), u[:, 1], atol=1e-3)
    chord = 2.0 * radius * math.sin(length / (2.0 * radius))
    rear = centres[on_arc] - 0.5 * length * u
    assert np.allclose(np.hypot(*(rear - b).T), length - chord, atol=0.01)


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


def test_a_bus_body_is_predicted_where_sumo_puts_it_round_a_corner() -> None:
    """A 12 m bus drives round the city's square corner E3 (from D3E3 to E3E2): at every
    step, the body predicted from its lane and position is SUMO's own rectangle (its
    length behind the front, at SUMO's angle: the one the run's collision check counts)
    within 1 cm and 0.002 rad (1 cm at the bus's ends), and the body predicted 1 s on at
    its speed is SUMO's then within what its change of speed moves it (the centre moves
    at most twice as far as the front round the corner, where the body turns). Round the
    corner that rectangle reaches more than 2 m past the bus's back on its lanes."""
    net = load_network(NETS / "city.net.xml")
    chain = ["D3E3_0", ":E3_1_0", "E3E2_0"]
    path = body_path([(net.lane(ln).shape, net.lane(ln).length) for ln in chain])
    length = 12.0
    now_off, ahead_off, reach = [], [], 0.0
    predicted: dict[int, tuple[np.ndarray, float]] = {}
    libsumo.start(["sumo", "-n", str(NETS / "city.net.xml"), "--no-step-log", "true",
                   "--step-length", "0.1"])
    try:
        libsumo.vehicletype.copy("DEFAULT_VEHTYPE", "bus")
        libsumo.vehicletype.setLength("bus", length)
        libsumo.vehicletype.setWidth("bus", 2.5)
        libsumo.route.add("r", ["D3E3", "E3E2"])
        libsumo.vehicle.add("b", "r", typeID="bus", departPos="70", departSpeed="max")
        for step in range(1, 400):
            libsumo.simulationStep()
            if "b" not in libsumo.vehicle.getIDList():
                break
            lane = libsumo.vehicle.getLaneID("b")
            at = (path.station(chain.index(lane), libsumo.vehicle.getLanePosition("b"))
                  if lane in chain else -1.0)
            if at < length:
                continue  # its back is not on the path yet
            x, y = libsumo.vehicle.getPosition("b")
            h = float(heading_from_sumo_angle(libsumo.vehicle.getAngle("b")))
            u = np.array([math.cos(h), math.sin(h)])
            centre = np.array([x, y]) - 0.5 * length * u
            speed = libsumo.vehicle.getSpeed("b")
            _, c, hd = bodies_along(path, at, speed, length, horizon=1.0, step=1.0)
            now_off.append((float(np.hypot(*(c[0] - centre))),
                            abs(math.remainder(float(hd[0]) - h, 2.0 * math.pi))))
            if step in predicted:
                then, v0 = predicted[step]
                ahead_off.append(float(np.hypot(*(then - centre)))
                                 - 2.0 * abs(speed - v0) * 1.0)
            predicted[step + 10] = (c[1], speed)  # 1 s on: 10 steps
            back = np.array([np.interp(at - length, path.s, path.xy[:, 0]),
                             np.interp(at - length, path.s, path.xy[:, 1])])
            reach = max(reach, float(np.hypot(*(centre - 0.5 * length * u - back))))
    finally:
        libsumo.close()
    assert len(now_off) > 10 and len(ahead_off) > 5
    assert max(d for d, _ in now_off) < 0.01 and max(a for _, a in now_off) < 0.002
    assert max(ahead_off) < 0.05
    assert reach > 2.0
