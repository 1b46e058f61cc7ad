"""Safety between pairs of vehicles from an FCD file (:mod:`splineplan.closedloop.pairs`),
against the time-to-collision worked out by hand for a car closing on a standing one."""

from __future__ import annotations

from pathlib import Path

import pytest

from splineplan.closedloop.pairs import TET_THRESHOLD, pair_safety

STEP = 0.1
SPEED = 10.0
GAP0 = 25.0  # between the follower's front and the leader's rear at t = 0 [m]
LENGTH = 4.5


def _fcd(path: Path, steps: int) -> None:
    """A car at ``SPEED`` along x closing on a standing one, both heading east (SUMO's
    angle 90), front bumpers written as SUMO does."""
    rows = ['<fcd-export>']
    for k in range(steps):
        t = k * STEP
        rows.append(f'<timestep time="{t:.2f}">'
                    f'<vehicle id="f" x="{SPEED * t:.3f}" y="0" angle="90" type="car" '
                    f'speed="{SPEED}"/>'
                    f'<vehicle id="l" x="{GAP0 + LENGTH:.3f}" y="0" angle="90" type="car" '
                    'speed="0"/></timestep>')
    rows.append('</fcd-export>')
    path.write_text("\n".join(rows))


@pytest.mark.parametrize("planned", [["f"], []])
def test_time_exposed_to_a_low_ttc(tmp_path: Path, planned: list[str]) -> None:
    """The follower's time-to-collision is (GAP0 - SPEED t) / SPEED: below the threshold
    from t = GAP0 / SPEED - TET_THRESHOLD on. The pair-seconds exposed, per vehicle-hour
    of the two cars, come out as that stretch, to one step (TTC is found in steps)."""
    steps = 20
    fcd = tmp_path / "fcd.xml"
    _fcd(fcd, steps)
    s = pair_safety(fcd, {"car": (LENGTH, 1.8)}, planned)
    t_low = GAP0 / SPEED - TET_THRESHOLD
    exposed = (steps - 1) * STEP - t_low  # the last step is at (steps - 1) * STEP
    hours = 2 * steps * STEP / 3600.0
    assert s["tet_threshold"] == TET_THRESHOLD
    assert s["tet_per_vehicle_hour"] == pytest.approx(exposed / hours, abs=STEP / hours)
    assert s["tet_planned_per_vehicle_hour"] == (
        pytest.approx(exposed / hours, abs=STEP / hours) if planned else 0.0)
    assert s["min_ttc"]["value"] == pytest.approx(
        (GAP0 - SPEED * (steps - 1) * STEP) / SPEED, abs=STEP)
    assert s["collision_pairs_planned"] == []


@pytest.mark.parametrize("planned", [["f"], []])
def test_overlapping_pairs_by_whether_one_is_planned(tmp_path: Path, planned: list[str]
                                                     ) -> None:
    """The follower drives on into the standing car: their footprints overlap from
    t = GAP0 / SPEED on, counted among the pairs with a planned vehicle (with its first
    time, to one step) or among those of two vehicles not planned."""
    fcd = tmp_path / "fcd.xml"
    _fcd(fcd, 30)
    s = pair_safety(fcd, {"car": (LENGTH, 1.8)}, planned)
    if planned:
        (hit,) = s["collision_pairs_planned"]
        assert hit["pair"] == ["f", "l"]
        assert hit["time"] == pytest.approx(GAP0 / SPEED, abs=STEP + 1e-9)
        assert s["overlapping_pairs_unplanned"] == 0
    else:
        assert s["collision_pairs_planned"] == []
        assert s["overlapping_pairs_unplanned"] == 1
