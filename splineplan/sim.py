"""Closed loop in SUMO: the planner drives an ego vehicle among SUMO's own traffic.

The loop lives in :mod:`splineplan.closedloop` (:mod:`~splineplan.closedloop.run` over the
planned vehicles' :mod:`~splineplan.closedloop.driver`); SUMO is reached only through
:mod:`splineplan.sumo.world`. This module keeps the public names. Each step of a headless
SUMO run:

1. read the ego and the vehicles around it (one subscription each, no per-vehicle getters):
   stopped or parked vehicles,
   and polygons of type ``obstacle``, within the look-ahead along the route are obstacles;
2. replan (levels 2 and 3 on a window of the route's corridor, ``lookahead`` metres long)
   when the window runs short, when the set of obstacles ahead changes, when SUMO put the ego
   off the plan, and at level 1 with the blocked edge avoided when level 2 finds the road
   closed (new obstacles ahead and traffic beside the ego coming near the plan are looked
   for every :data:`TRIGGER_PERIOD` seconds, the rest every step);
3. advance along the trajectory at its speed, slowed to keep a time gap to whatever is in
   the ego's path (moving vehicles are handled by speed) and to stop at red lights;
4. move the ego with ``vehicle.moveToXY(..., keepRoute=3)``: SUMO's position is the middle
   of the front bumper and its angle is in degrees, 0 = north, clockwise; ``keepRoute=3``
   keeps the exact x, y (bit 2) and maps the vehicle onto its route only (bit 1), which is
   kept equal to the planned route with ``vehicle.setRoute``; its speed is set to the
   closed loop's with ``vehicle.setSpeed`` (SUMO would infer one from the move, measured
   along its lanes and capped by their speed limits: jumps at every lane boundary);
5. check that SUMO put the ego where asked, and check the ego's footprint against every
   other vehicle's footprint and against the road (SUMO's own collision check runs too, with
   ``--collision.action warn``; nothing is teleported: ``--time-to-teleport -1``).

Drivers (``driver=``): ``planner`` as above; ``sumo`` and ``sublane`` let SUMO's own models
drive the ego along the same level-1 route (the benchmark's baselines), with the same
observation and safety checks and no planning. The planner's runs use SUMO's sublane model
(``--lateral-resolution`` :data:`LATERAL_RESOLUTION`): the ego leans into a neighbouring lane
to pass an obstacle, and lane-based SUMO maps it onto one lane only, so cars on the other lane
do not see it (with two stopped cars closing two of three lanes and fast traffic on the
third, a car passed the ego with 0.05 m to spare lane-based, 0.96 m with sublanes).

Outputs in ``out_dir``: ``metrics.json``, ``trajectory.csv`` (the driven path), ``fcd.xml``
(SUMO's floating car data), ``ssm.xml`` (SUMO's surrogate safety measures,
:mod:`splineplan.sumo.ssm`), ``sumo.log``, and with ``plot=True`` pictures. A run that fails
midway writes all it has recorded, says why in ``metrics.json`` and raises
:class:`~splineplan.errors.SimulationError`.
"""

from __future__ import annotations

from splineplan.closedloop.control import (
    EMERGENCY_FACTOR,
    PATH_MARGIN,
    STOPPED_FOE_SPEED,
    YIELD_GAP,
    YIELD_STOP,
)
from splineplan.closedloop.driver import DRIVERS
from splineplan.closedloop.driver import DriverKind as Driver
from splineplan.closedloop.perception import BESIDE_LATERAL, SWEEP_TIME
from splineplan.closedloop.record import SimResult
from splineplan.closedloop.replan import TRIGGER_PERIOD, Replan
from splineplan.closedloop.run import LATERAL_RESOLUTION, MAX_PLAN_PICTURES, simulate
from splineplan.sumo.world import KEEP_ROUTE, stopped_vehicle_obstacles

__all__ = [
    "BESIDE_LATERAL", "DRIVERS", "EMERGENCY_FACTOR", "KEEP_ROUTE", "LATERAL_RESOLUTION",
    "MAX_PLAN_PICTURES", "PATH_MARGIN", "STOPPED_FOE_SPEED", "SWEEP_TIME", "TRIGGER_PERIOD",
    "YIELD_GAP", "YIELD_STOP", "Driver", "Replan", "SimResult", "simulate",
    "stopped_vehicle_obstacles",
]
