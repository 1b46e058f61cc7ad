"""Lane keeping and the way back onto the corridor for planned vehicles among SUMO's
traffic (``splineplan.closedloop.lanes``), on plain corridors."""

from __future__ import annotations

import numpy as np

from splineplan.closedloop.lanes import ONTO_INSET, lane_band, onto_road
from splineplan.corridor import Corridor


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


def test_onto_road_moves_a_start_just_outside_back_in() -> None:
    c = _street()
    x, y = onto_road(c, (50.0, 3.5)) or (np.nan, np.nan)
    assert np.isclose(x, 50.0) and np.isclose(y, 3.2 - ONTO_INSET)
    assert onto_road(c, (50.0, 1.0)) is None  # inside: as it is
    assert onto_road(c, (50.0, -4.5)) is None  # too far out to move
