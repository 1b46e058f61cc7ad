"""Lane keeping and the way back onto the corridor for planned vehicles among SUMO's
traffic (``splineplan.closedloop.lanes``), on plain corridors."""

from __future__ import annotations

import math

import numpy as np
from conftest import NETS

from splineplan.closedloop.lanes import ONTO_INSET, lane_band, lane_entry, onto_road, side_reach
from splineplan.corridor import Corridor
from splineplan.network import load_network, route_corridor
from splineplan.route import Route


def _street(length: float = 100.0, lanes: int = 2, width: float = 3.2) -> Corridor:
    """A straight street along x of ``lanes`` lanes one way, its reference in the middle."""
    half = lanes * width / 2.0
    ref = np.array([[0.0, 0.0], [length, 0.0]])
    return Corridor.from_reference(ref, np.full(2, half), np.full(2, -half))


def test_lane_band_keeps_the_footprint_in_the_lane_it_is_in() -> None:
    c = _street()
    for lateral, lo, hi in ((-1.2, -3.2, 0.0), (0.4, 0.0, 3.2)):
        band = lane_band(c, 10.0, lateral, lane_width=3.2, half_width=0.9)
        k_lo, k_hi = band.keep_at(np.array([20.0, 80.0]))
        # the centre within the lane, half the car's width from each of its sides
        assert np.allclose(k_lo, lo + 0.9) and np.allclose(k_hi, hi - 0.9)


def test_lane_band_changes_to_the_lane_the_route_needs() -> None:
    """Where the corridor's own keep offsets (before a junction) ask for the other lane,
    the band moves to that lane some way before, whole: the vehicle changes lanes there
    rather than drift across both."""
    c = _street()
    s = c.s
    keep_lo = np.where(s >= 70.0, 0.5, -1e9)
    keep_hi = np.where(s >= 70.0, 1e9, 1e9)
    c = Corridor(c.reference, c.s, c.left, c.right, keep_left=keep_hi, keep_right=keep_lo)
    band = lane_band(c, 5.0, -1.6, lane_width=3.2, half_width=0.9)
    lo, hi = band.keep_at(np.array([10.0, 60.0, 80.0]))
    assert np.isclose(lo[0], -2.3) and np.isclose(hi[0], -0.9)  # its lane
    assert np.isclose(lo[1], 0.9) and np.isclose(hi[1], 2.3)  # the lane that leads on
    assert np.isclose(lo[2], 0.9) and np.isclose(hi[2], 2.3)


def test_lane_after_follows_sumo_connections() -> None:
    """At the city's junction A1, a left turn from the north and a right turn from the
    south both lead into the two-lane street east: SUMO's connections put the left turn
    on its left lane and the right turn on its right one (no conflict between them)."""
    net = load_network(NETS / "city.net.xml")
    assert net.lane_after("A2A1", 0, "A1B1", "passenger") == 1
    assert net.lane_after("A0A1", 0, "A1B1", "passenger") == 0
    # in the junction, the internal lane under the vehicle decides
    assert net.lane_after("A2A1", 0, "A1B1", "passenger", via=":A1_4_0") == 1
    assert net.lane_after("A1A0", 0, "A0B0", "passenger") is None  # not joined


def test_lane_band_comes_out_of_a_turn_on_the_lane_the_connection_leads_to() -> None:
    """Out of the left turn at A1 the band holds the street's left lane, as SUMO's
    connection does (the right turn from the other side comes out on the right lane);
    the same index on the street after (the right lane) would cut across that turn."""
    net = load_network(NETS / "city.net.xml")
    c = route_corridor(net, Route(("A2A1", "A1B1"), 0.0, 0.0, "length", "passenger"))

    def leads_to(k: int, lane: int) -> int | None:
        return net.lane_after(c.edges[k], lane, c.edges[k + 1], "passenger")

    after = np.array([c.edge_starts[1] + 2.0, c.edge_starts[1] + 30.0, c.length - 5.0])
    right, _ = c.bounds_at(after)
    for links, lane in (({}, 0), ({"leads_to": leads_to}, 1)):
        band = lane_band(c, 50.0, 0.0, lane_width=3.2, half_width=0.9, **links)
        lo, hi = band.keep_at(after)
        assert np.allclose(lo - right, 3.2 * lane + 0.9, atol=0.05)
        assert np.allclose(hi - right, 3.2 * lane + 2.3, atol=0.05)
    # in the junction, the lane its internal lane leads to, wherever its centre lies
    mid = 0.5 * (c.edge_ends[0] + c.edge_starts[1])
    band = lane_band(c, mid, float(c.bounds_at(mid)[0]) + 0.3, lane_width=3.2,
                     half_width=0.9, arrive=1)
    lo, _ = band.keep_at(after)
    assert np.allclose(lo - right, 3.2 + 0.9, atol=0.05)


def test_lane_entry_finds_where_the_footprint_reaches_over_the_line() -> None:
    """A path from the middle of the left lane of two (3.2 m) drifting right: its 1.8 m
    wide footprint reaches over the line between them where its centre comes within
    0.9 m (plus the slack) of it, or sooner where it heads across the line (shapely's
    rotated rectangle for the reach)."""
    from shapely.affinity import rotate
    from shapely.geometry import box

    lateral = np.linspace(4.8, 1.6, 33)  # from the left lane's centre to the right's
    right = np.zeros(33)
    square = np.full(33, 0.9)
    k, lane, end = lane_entry(lateral, right, square, lane_width=3.2) or (-1, -1, -1)
    assert lane == 0 and lateral[k] - 0.9 < 3.2 - 0.1 <= lateral[k - 1] - 0.9
    # inside the right lane again where its left side is back over the line
    assert k < end < 33 and lateral[end] + 0.9 <= 3.2 + 0.1 < lateral[end - 1] + 0.9
    turned = side_reach(np.full(33, -0.25), 2.25, 0.9)
    rect = rotate(box(-2.25, -0.9, 2.25, 0.9), -0.25, use_radians=True)
    assert np.isclose(turned[0], -rect.bounds[1]) and np.isclose(turned[0], rect.bounds[3])
    k2, _, _ = lane_entry(lateral, right, turned, lane_width=3.2) or (-1, -1, -1)
    assert 0 <= k2 < k
    assert lane_entry(np.full(5, 4.8), np.zeros(5), np.full(5, 0.9), lane_width=3.2) is None


def test_onto_road_moves_a_start_just_outside_back_in() -> None:
    c = _street()
    x, y = onto_road(c, (50.0, 3.5)) or (np.nan, np.nan)
    assert np.isclose(x, 50.0) and np.isclose(y, 3.2 - ONTO_INSET)
    assert onto_road(c, (50.0, 1.0)) is None  # inside: as it is
    assert onto_road(c, (50.0, -4.5)) is None  # too far out to move


def test_a_stop_across_a_lane_line_moves_before_the_lane_change() -> None:
    """Where the plan reaches over the line from 20 m to 30 m ahead, a vehicle that would
    stand anywhere in that stretch stands 1 m (``YIELD_STOP``) before it instead, if it can
    still stop there at its emergency braking; a stand before or after the stretch, or a
    lane change already begun, is left as it is."""
    from types import SimpleNamespace

    from splineplan.closedloop.control import EMERGENCY_FACTOR, YIELD_STOP, Control
    from splineplan.closedloop.lanes import LaneChange

    b = 4.5
    change = LaneChange(at=25.0, lane=0, width=3.2, lane_id="e_0", end=35.0)

    def stand(where: float, *, u: float = 5.0, v: float = 5.0) -> float:
        me = SimpleNamespace(lane_change=change, u=u, v=v,
                             sc=SimpleNamespace(trajectory=SimpleNamespace(b_max=b)))
        me._cannot_stop = lambda d: Control._cannot_stop(me, d)  # type: ignore[arg-type]
        return float(Control._before_change(me, where))  # type: ignore[arg-type]

    for where in (20.0, 25.0, 29.9):  # in the stretch: before it
        assert stand(where) == 20.0 - YIELD_STOP
    assert stand(19.0) == 19.0 and stand(30.0) == 30.0  # before, after
    assert stand(25.0, u=26.0) == 25.0  # changing already
    assert LaneChange(at=1.0, lane=0, width=3.2, lane_id="e_0").end == math.inf
    # just too fast to stop 19 m on at twice the comfortable braking: stands where it was
    fast = math.sqrt(2.0 * EMERGENCY_FACTOR * b * (20.0 - YIELD_STOP)) + 0.01
    assert stand(25.0, v=fast) == 25.0
    assert stand(25.0, v=fast - 0.02) == 20.0 - YIELD_STOP
