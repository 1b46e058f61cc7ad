"""Passing a car parked just ahead: how fast the planned curve lets the vehicle go.

``python -m benchmarks passing [--speeds 8 13 20] [--ahead 12 15 20 25 30 40]``.
A straight road of two 3.5 m lanes, the vehicle in the centre of the right one at the
given speed (``s_max`` 20 m/s, the default car and margins), a 4.5 x 1.8 m car parked in
the centre of that lane the given distance ahead (centre to centre).
:func:`splineplan.planner.plan_corridor` plans past it; printed per case: feasible, the
curve's first speed (the vehicle's speed unless the curve is too sharp for it near the
start), its lowest speed until 10 m past the parked car, the time to get there, and the
planning time. The physics: a lateral offset of about 2 m over the gap before the car
allows some 18 m/s where that gap is 20 m long; with a gap of 10 m at 20 m/s the vehicle
cannot brake in time and must swerve slowly.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from splineplan.corridor import Corridor
from splineplan.obstacles import Obstacles
from splineplan.planner import plan_corridor
from splineplan.trajectory import TrajectoryParams

LANE = 3.5


def case(ahead: float, speed: float) -> tuple[bool, float, float, float, float]:
    """Feasible, first speed [m/s], lowest speed until 10 m past the car [m/s], time to
    there [s] and planning time [ms] of one case."""
    road = Corridor.from_reference(np.array([[0.0, 0.0], [200.0, 0.0]]), np.full(2, LANE),
                                   np.full(2, -LANE))
    parked = Obstacles.from_boxes(np.array([[ahead, -LANE / 2.0]]), 0.0, 4.5, 1.8)
    t0 = time.perf_counter()
    tr = plan_corridor(road, parked, (0.0, -LANE / 2.0), 0.0,
                       params=TrajectoryParams(s_max=20.0), start_speed=speed,
                       end_speed=None).trajectory
    ms = 1e3 * (time.perf_counter() - t0)
    past = tr.s <= ahead + 10.0
    return (bool(tr.feasible), float(tr.speed[0]), float(np.min(tr.speed[past])),
            float(np.interp(ahead + 10.0, tr.s, tr.t)), ms)


def main(argv: list[str]) -> None:
    ap = argparse.ArgumentParser(prog="python -m benchmarks passing", description=__doc__)
    ap.add_argument("--speeds", type=float, nargs="+", default=[8.0, 13.0, 20.0])
    ap.add_argument("--ahead", type=float, nargs="+",
                    default=[12.0, 15.0, 20.0, 25.0, 30.0, 40.0])
    args = ap.parse_args(argv)
    case(30.0, 13.0)  # compile and warm up
    print("ahead [m]  speed [m/s]  feasible  first [m/s]  lowest [m/s]  time [s]  plan [ms]")
    for ahead in args.ahead:
        for speed in args.speeds:
            ok, first, low, t, ms = case(ahead, speed)
            print(f"{ahead:9.0f}  {speed:11.0f}  {ok!s:>8}  {first:11.1f}  {low:12.1f}  "
                  f"{t:8.2f}  {ms:9.1f}")
