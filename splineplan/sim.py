"""Closed loop in SUMO: the planner drives an ego vehicle among SUMO's own traffic.

This is the only module that imports ``libsumo`` (and ``traci``, for ``gui=True``). Each step
of a headless SUMO run:

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
(SUMO's floating car data), ``sumo.log``, and with ``plot=True`` pictures. A run that fails
midway writes all it has recorded, says why in ``metrics.json`` and raises
:class:`~splineplan.errors.SimulationError`.
"""

from __future__ import annotations

import bisect
import contextlib
import csv
import json
import logging
import math
import os
import sys
import time
import xml.etree.ElementTree as ET
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal, get_args

import numpy as np

from splineplan._signals import sigint_deferred, sigint_ignored
from splineplan.corridor import Corridor
from splineplan.errors import (
    GeometryError,
    Interrupted,
    NoRouteError,
    ParameterError,
    RoadBlockedError,
    ScenarioError,
    SimulationError,
    SplineplanError,
    TrajectoryError,
    VehicleClassError,
)
from splineplan.geometry import (
    FloatArray,
    heading_from_sumo_angle,
    sumo_angle_from_heading,
)
from splineplan.metrics import (
    CURVATURE_SPAN,
    dynamics,
    finite_or_none,
    footprints,
    rectangle_distances,
    summary_stats,
)
from splineplan.obstacles import Obstacles
from splineplan.scenario import Scenario
from splineplan.traffic import (
    NO_OTHERS,
    OFF_ROAD_TOLERANCE,
    Others,
    RoadCheck,
    first_in_reach,
    next_in_circle,
    probe_points,
    safe_speed,
)

log = logging.getLogger(__name__)

#: ``moveToXY`` keepRoute: bit 1 maps onto the vehicle's route only, bit 2 keeps the exact x, y.
KEEP_ROUTE = 3
#: Lateral slack [m] beyond the ego's half width within which a vehicle counts as in its path.
PATH_MARGIN = 0.15
#: Spacing [m] of the path samples used to find vehicles in the ego's path.
_PATH_SPACING = 0.5
#: Seconds between retries when no plan could be made.
_RETRY_AFTER = 1.0
#: Straight extension [m] of the path beyond the trajectory's end, to see what is in the way.
_PATH_EXTENSION = 60.0
#: Re-routes tried in one replan before giving up.
_MAX_REROUTES = 5
#: A moving vehicle whose centre is at least this far [m] to the side of the ego's centre
#: (across the route) is *beside* the ego, not ahead in its path: level 2 and 3 plan around
#: where it goes in the next :data:`SWEEP_TIME` (its swept footprint), so that the ego keeps
#: a lateral separation from it; a vehicle within it is handled by speed (time gap).
BESIDE_LATERAL = 1.0
#: Horizon [s] of a beside vehicle's swept footprint (constant speed along the route).
SWEEP_TIME = 2.0
#: Stations [m] behind and ahead of the ego's centre within which vehicles count as beside.
_BESIDE_BACK = 15.0
_BESIDE_AHEAD = 40.0
#: A swept footprint starts at least this far [m], and this many seconds at the ego's speed,
#: ahead of the ego's front bumper.
_SWEEP_CLIP = 3.0
_SWEEP_CLIP_TIME = 1.0
#: Prediction times [s] of the check for a beside vehicle coming near the planned path.
_CONFLICT_TIMES: tuple[float, ...] = tuple(0.5 * k for k in range(7))
#: Longitudinal slack [m] of that check.
_CONFLICT_SLACK = 1.0
#: Time [s] the ego keeps between its passage of a junction's conflict area and that of a
#: vehicle it must yield to; it stops this far [m] before the area to let that one pass.
YIELD_GAP = 1.5
YIELD_STOP = 1.0
#: A vehicle slower than this [m/s] outside a conflict area is waiting there, not coming.
STOPPED_FOE_SPEED = 0.1
#: At most one ``traffic`` replan per this many seconds.
_TRAFFIC_REPLAN_EVERY = 0.5
#: Period [s] of the checks for new obstacles ahead and for traffic beside the ego coming
#: near the plan (a reaction time well below a driver's; the deviation and horizon checks,
#: and the ego's own safety checks, run every step).
TRIGGER_PERIOD = 0.3

#: The closed loop's emergency deceleration, a multiple of the planner's ``b_max``: the
#: speed control brakes up to this hard when something comes into the ego's path (and SUMO's
#: vehicle type of the ego has it as its ``emergencyDecel``).
EMERGENCY_FACTOR = 2.0

#: Who drives the ego: ``planner`` (splineplan, through ``moveToXY``), ``sumo`` (SUMO's
#: default car-following and lane-change models, lane-based: SUMO started without
#: ``--lateral-resolution``) or ``sublane`` (SUMO's sublane model, which can shift within a
#: lane to pass an obstacle: ``--lateral-resolution`` :data:`LATERAL_RESOLUTION`).
Driver = Literal["planner", "sumo", "sublane"]
DRIVERS: tuple[str, ...] = get_args(Driver)
#: Width [m] of SUMO's sublanes for the ``planner`` and ``sublane`` drivers. The planner's
#: runs need the sublane model: the ego leans into a neighbouring lane to pass an obstacle,
#: and only with sublanes do SUMO's vehicles on that lane see the part of the ego that is in
#: it (lane-based, SUMO puts the ego on one lane and a car on the next lane drives past it
#: with centimetres to spare; see the module's docs).
LATERAL_RESOLUTION = 0.4


@dataclass(frozen=True)
class Replan:
    """One planning call of the closed loop.

    Attributes
    ----------
    time
        Simulation time [s].
    reason
        ``start``, ``horizon`` (the window ran short), ``obstacles`` (new obstacles ahead),
        ``deviation`` (SUMO put the ego off the plan), ``traffic`` (a moving vehicle beside
        the ego comes near the planned path), ``reroute`` (level 1 after level 2 found the
        road closed) or ``retry`` (after a failed plan).
    planning_time
        Wall time [s] of the planning (levels 1 to 3 as needed).
    station
        The ego's station [m] on the route at that time.
    ok
        Whether a trajectory came out.
    detail
        What triggered it or what failed.
    """

    time: float
    reason: str
    planning_time: float
    station: float
    ok: bool = True
    detail: str = ""


@dataclass(frozen=True, eq=False)
class SimResult:
    """Outcome of :func:`simulate`.

    Attributes
    ----------
    status
        ``arrived``, ``timeout`` (duration reached), ``failed`` or ``interrupted``
        (Ctrl-C).
    reason
        Why the run stopped, in words.
    out_dir
        Where the outputs are.
    metrics
        What ``metrics.json`` holds.
    replans
        Every planning call.
    route
        The route's edges from the ego's start (after a re-route: the edges driven before
        it, then the new route).
    driven
        Columns of ``trajectory.csv``, as arrays.
    plans
        ``(time, roadmaps, trajectory, corridor window)`` of each successful plan (for plots).
    """

    status: str
    reason: str
    out_dir: Path
    metrics: dict[str, Any]
    replans: tuple[Replan, ...]
    route: tuple[str, ...]
    driven: dict[str, np.ndarray]
    plans: tuple[Any, ...] = field(default=(), repr=False)

    @property
    def arrived(self) -> bool:
        """Whether the ego reached its goal."""
        return self.status == "arrived"


# ---- public entry -------------------------------------------------------------------------

def simulate(
    scenario: Scenario,
    *,
    out_dir: str | Path,
    plot: bool = False,
    gui: bool = False,
    seed: int | None = None,
    progress: bool | None = None,
    on_step: Callable[[float], None] | None = None,
    driver: Driver = "planner",
) -> SimResult:
    """Run a scenario in SUMO with the planner driving the ego vehicle.

    Parameters
    ----------
    scenario
        The experiment (:func:`splineplan.scenario.load_scenario`).
    out_dir
        Folder for the outputs (created).
    plot
        Also draw the route on the network and each plan's roadmap and trajectory.
    gui
        Run ``sumo-gui`` through ``traci`` instead of headless ``libsumo``.
    seed
        SUMO's random seed; default the scenario's.
    progress
        Show a progress bar on stderr; default: when stderr is a terminal.
    on_step
        Called with the simulation time [s] after every step (a hook for tests and tools).
    driver
        ``"planner"`` (splineplan drives), ``"sumo"`` (SUMO's default lane-based driver
        model drives the ego along the same level-1 route; SUMO runs without sublanes) or
        ``"sublane"`` (SUMO's sublane model drives it; ``--lateral-resolution``
        :data:`LATERAL_RESOLUTION`, as for the planner). Nothing is teleported
        (``--time-to-teleport -1``): a SUMO driver stuck behind a blockage stands until the
        duration ends, and the run's status is ``timeout``, saying so.

    Raises
    ------
    ScenarioError, UnknownEdgeError, VehicleClassError, NoRouteError
        Bad input (missing file, unknown edge, an edge the ego's class may not use).
    SimulationError
        SUMO failed to start or to step, or the ego left the simulation unplanned; with
        ``gui=True``, no display to show ``sumo-gui`` on (checked before anything starts).
    Interrupted
        Ctrl-C (``KeyboardInterrupt``) during the run: SUMO is closed (``fcd.xml`` complete),
        ``trajectory.csv`` and ``metrics.json`` (status ``interrupted``, the time reached)
        are written, no pictures; the exception's ``result`` is the :class:`SimResult`.
    """
    if seed is not None:
        scenario = scenario.with_seed(seed)
    if driver not in DRIVERS:
        raise ParameterError(f"driver must be one of {', '.join(map(repr, DRIVERS))}, "
                             f"not {driver!r}")
    if gui:
        _check_display()
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    run = _Run(scenario, out, driver=driver, gui=gui, on_step=on_step,
               progress=_want_progress(progress))
    with _run_log(out / "run.log"):
        return _simulate(run, scenario, plot=plot)


def _simulate(run: _Run, scenario: Scenario, *, plot: bool) -> SimResult:
    try:
        run.setup()
        run.loop()
    except KeyboardInterrupt as err:  # Ctrl-C: close SUMO, write the record, then stop
        with sigint_ignored():
            run.interrupt()
            result = run.finish(plot=False)
        raise Interrupted(f"{scenario.name}: interrupted {run.when()}; the record up to "
                          f"then is in {run.out}", result) from err
    except SplineplanError as err:
        run.fail(err)
        run.finish(plot=plot)
        if isinstance(err, SimulationError):
            raise
        if run.sumo_started:
            raise SimulationError(f"{scenario.name}: {err}") from err
        raise
    except Exception as err:  # SUMO's exceptions and anything unforeseen: keep what we have
        run.fail(err)
        run.finish(plot=plot)
        raise SimulationError(f"{scenario.name}: simulation stopped at "
                              f"t={run.time:.1f} s: {_sumo_message(err)}") from err
    return run.finish(plot=plot)


def stopped_vehicle_obstacles(
    sumo: Any, vehicle_ids: Any = None, *, stopped_speed: float = 0.1
) -> Obstacles:
    """Obstacles of the stopped or parked vehicles of a running SUMO simulation.

    Each is the oriented rectangle of the vehicle: SUMO's position (the middle of the front
    bumper), angle (degrees, 0 = north, clockwise), length and width. A vehicle counts as
    stopped when it is at a stop or parked and slower than ``stopped_speed`` [m/s].

    Parameters
    ----------
    sumo
        The ``libsumo`` (or ``traci``) module, with a simulation running.
    vehicle_ids
        Vehicles to look at; default every vehicle in the simulation.
    """
    ids = list(sumo.vehicle.getIDList() if vehicle_ids is None else vehicle_ids)
    keep = [v for v in ids
            if sumo.vehicle.getStopState(v) & 3 and sumo.vehicle.getSpeed(v) < stopped_speed]
    if not keep:
        return Obstacles.empty()
    fronts = np.array([sumo.vehicle.getPosition(v) for v in keep], dtype=float)
    heads = heading_from_sumo_angle([sumo.vehicle.getAngle(v) for v in keep])
    lens = np.array([sumo.vehicle.getLength(v) for v in keep], dtype=float)
    wids = np.array([sumo.vehicle.getWidth(v) for v in keep], dtype=float)
    return Obstacles.from_boxes(fronts, heads, lens, wids, reference="front", ids=keep)


# ---- the run ------------------------------------------------------------------------------

class _Run:
    """State of one closed-loop run (internal)."""

    def __init__(self, scenario: Scenario, out: Path, *, driver: Driver, gui: bool,
                 on_step: Callable[[float], None] | None, progress: bool) -> None:
        self.sc = scenario
        self.out = out
        self.driver = driver
        self.gui = gui
        self.on_step = on_step
        self.progress = progress
        self.ego = scenario.ego.id
        self.dt = scenario.sim.step_length
        self.time = 0.0
        self.status = "running"
        self.reason = ""
        self.sumo_started = False
        self.sumo: Any = None
        self.rows: list[tuple[Any, ...]] = []
        self.replans: list[Replan] = []
        self.plans: list[Any] = []
        self.collisions: list[dict[str, Any]] = []
        self.sumo_collisions: list[dict[str, Any]] = []
        self.position_errors: list[float] = []
        self.avoid: set[str] = set()
        self.route_edges: tuple[str, ...] = ()  # the route planned from where it was set
        self.driven_before: tuple[str, ...] = ()  # edges driven before its first edge
        self.route_length = math.nan  # [m] of the whole route, from the ego's start
        self.corridor: Corridor | None = None
        self.net: Any = None
        self.in_sim = False
        self.depart_time: float | None = None
        self.wall_start = time.perf_counter()
        self.wall_time = 0.0
        self.polygons = Obstacles.empty()
        # motion state
        self.traj: Any = None
        self.path_s: FloatArray = np.zeros(0)
        self.path_xy: FloatArray = np.zeros((0, 2))
        self.path_heading: FloatArray = np.zeros(0)
        self.path_speed: FloatArray = np.zeros(0)
        self.ext_s: FloatArray = np.zeros(0)
        self.ext_xy: FloatArray = np.zeros((0, 2))
        self.ext_heading: FloatArray = np.zeros(0)
        self.u = 0.0  # station [m] along the current trajectory
        self.v = 0.0  # speed [m/s]
        self.pose = np.zeros(3)  # centre x, y, heading
        self.planned_ids: frozenset[str] = frozenset()
        self.window_end = 0.0
        self.truncated = False
        self.stop_at: float | None = None  # station on the trajectory to stop before
        self.retry_at: float | None = None
        self.goal_station = math.nan
        self.last_lane = ""
        self.teleports = 0  # of any vehicle
        self.ego_teleports: list[float] = []
        self.check_seconds = 0.0  # wall time [s] of the loop's own safety checks
        self.sumo_seconds = 0.0  # wall time [s] inside SUMO (start, steps, moves, reads)
        self.plan_seconds = 0.0  # wall time [s] of the planning calls
        self.c: Any = None  # libsumo.constants
        self._obs_cache: dict[tuple[str, float, float], tuple[float, float, bool]] = {}
        self.lateral = 0.0  # the ego's lateral offset [m] on the route
        self.traffic_after = 0.0  # no traffic replan before this time [s]
        self.trigger_after = 0.0  # no obstacle or traffic check before this time [s]
        self.others = NO_OTHERS
        self._beside_at: tuple[float, float] | None = None
        self._cand_at: tuple[float, float] | None = None
        self._lane_of: tuple[str, int] = ("", 0)  # the last lane's id and index
        self._ahead_box: tuple[list[float], ...] = ([], [], [], [])
        self._sample_step = 0.0
        self._cand_was: list[int] = []
        self._turn_key: tuple[Corridor, float] | None = None
        self._turn_window: FloatArray = np.zeros(0)
        self._beside_was: tuple[np.ndarray, FloatArray] = (np.zeros(0, dtype=np.int64),
                                                           np.zeros((0, 2)))

    # -- setup ----------------------------------------------------------------------------
    def setup(self) -> None:
        from splineplan.network import load_network, route_corridor
        from splineplan.route import shortest_route

        sc, ego = self.sc, self.sc.ego
        for p in (sc.network, *sc.routes, *sc.additional):
            if not Path(p).is_file():
                raise ScenarioError(f"{sc.name}: file not found: {p}")
        self.net = load_network(sc.network)
        self.net.edge_index(ego.start_edge)
        self.net.edge_index(ego.goal_edge)
        lanes = self.net.lanes_of(ego.start_edge)
        if ego.start_lane >= len(lanes):
            raise ScenarioError(f"{sc.name}: ego.start_lane {ego.start_lane} does not exist on "
                                f"edge '{ego.start_edge}' ({len(lanes)} lanes)")
        if not lanes[ego.start_lane].allows(ego.vclass):
            raise VehicleClassError(f"vehicle class '{ego.vclass}' may not use lane "
                                    f"{ego.start_lane} of start edge '{ego.start_edge}'")
        if ego.start_pos < ego.length:
            raise ScenarioError(f"{sc.name}: ego.start_pos ({ego.start_pos} m) must be at least "
                                f"the ego's length ({ego.length} m): the position is the front "
                                "bumper's")
        route = shortest_route(self.net, ego.start_edge, ego.goal_edge, vclass=ego.vclass,
                               start_pos=ego.start_pos)
        goal_len = self.net.length_of(ego.goal_edge)
        if ego.goal_pos is not None and ego.goal_pos > goal_len:
            raise ScenarioError(f"{sc.name}: ego.goal_pos {ego.goal_pos} m is beyond the end of "
                                f"goal edge '{ego.goal_edge}' ({goal_len:.1f} m)")
        self._set_route(route_corridor(self.net, route, vclass=ego.vclass), route.edges)
        if self.driver == "planner":
            from splineplan.planner import warm_up

            warm_up()  # the compiled loops, loaded before the loop rather than in a replan
        self.road = RoadCheck(self.net, ego.vclass)
        self.route_length = route.length
        for p in (*sc.routes, *sc.additional):
            _check_xml(Path(p))
        self._start_sumo()
        self._add_ego()

    def _set_route(self, corridor: Corridor, edges: tuple[str, ...]) -> None:
        ego = self.sc.ego
        self.corridor = corridor
        self.route_edges = tuple(edges)
        ref = np.asarray(corridor.reference, dtype=float)
        self._ref_a = ref[:-1]
        self._ref_ab = np.diff(ref, axis=0)
        seg_len = np.hypot(self._ref_ab[:, 0], self._ref_ab[:, 1])
        self._ref_len = np.where(seg_len > 0, seg_len, 1.0)  # zero-length: t = 0, l = 0
        self._ref_heading = np.arctan2(self._ref_ab[:, 1], self._ref_ab[:, 0])
        # the same as contiguous columns, and the stations as a list, for :meth:`_project`
        self._ref_cols = (self._ref_a[:, 0].copy(), self._ref_a[:, 1].copy(),
                          self._ref_ab[:, 0].copy(), self._ref_ab[:, 1].copy(),
                          self._ref_len * self._ref_len)
        self._ref_s = np.asarray(corridor.s, dtype=float).tolist()
        self._edge_starts = np.asarray(corridor.edge_starts, dtype=float).tolist()
        self._obs_cache = {}
        i = len(edges) - 1
        goal_len = self.net.length_of(ego.goal_edge)
        goal_pos = ego.goal_pos if ego.goal_pos is not None else max(
            goal_len - self.sc.sim.goal_margin, 0.0)
        # the goal edge's stretch on the corridor: scale SUMO's lane position onto it
        start = float(corridor.edge_starts[i])
        stretch = corridor.length - start
        front = start + goal_pos * (stretch / goal_len if goal_len > 0 else 1.0)
        self.goal_station = front - ego.length / 2.0

    def _start_sumo(self) -> None:
        sc = self.sc
        if self.gui:
            import traci as sumo_mod

            binary = "sumo-gui"
        else:
            import libsumo as sumo_mod

            binary = "sumo"
        try:
            import sumolib

            binary = sumolib.checkBinary(binary)
        except Exception:
            pass
        cmd = [binary, "-n", str(sc.network),
               "--step-length", f"{self.dt:g}", "--seed", str(sc.sim.seed),
               "--collision.action", "warn", "--collision.check-junctions", "true",
               "--time-to-teleport", "-1", *self._lateral_options(),
               "--fcd-output", str(self.out / "fcd.xml"),
               # everything SUMO says goes to sumo.log, nothing to the console: with
               # --no-warnings, warnings reach only the error log (the same file)
               "--log", str(self.out / "sumo.log"), "--error-log", str(self.out / "sumo.log"),
               "--no-warnings", "true",
               "--no-step-log", "true", "--duration-log.disable", "true"]
        if sc.routes:
            cmd += ["-r", ",".join(str(p) for p in sc.routes)]
        if sc.additional:
            cmd += ["-a", ",".join(str(p) for p in sc.additional)]
        if self.gui:
            cmd += ["--start", "--quit-on-end"]
        self.sumo = sumo_mod
        t0 = time.perf_counter()
        try:
            sumo_mod.start(cmd)
        except Exception as err:
            _safe_close(sumo_mod)
            log_text = _tail(self.out / "sumo.log")
            raise SimulationError(
                f"SUMO failed to start for scenario '{sc.name}': {_sumo_message(err)}"
                + (f"; SUMO says: {log_text}" if log_text else "")) from err
        self.sumo_started = True
        self.sumo_seconds += time.perf_counter() - t0
        self.polygons = self._read_polygons()
        self.road.add_junctions(self._junction_shapes())

    def _lateral_options(self) -> list[str]:
        if self.driver == "sumo":
            return []
        return ["--lateral-resolution", f"{LATERAL_RESOLUTION:g}"]

    def _junction_shapes(self) -> list[FloatArray]:
        s = self.sumo
        shapes = []
        for jid in s.junction.getIDList():
            if jid.startswith(":"):
                continue
            shape = np.asarray(s.junction.getShape(jid), dtype=float)
            if len(shape) >= 3:
                shapes.append(shape)
        return shapes

    def _read_polygons(self) -> Obstacles:
        s = self.sumo
        polys, ids = [], []
        for pid in s.polygon.getIDList():
            if s.polygon.getType(pid).lower().startswith("obstacle"):
                shape = np.asarray(s.polygon.getShape(pid), dtype=float)
                if len(shape) >= 3:
                    polys.append(shape)
                    ids.append(f"polygon:{pid}")
        return Obstacles.from_polygons(polys, ids) if polys else Obstacles.empty()

    def _add_ego(self) -> None:
        s, ego = self.sumo, self.sc.ego
        vtype = f"{ego.id}_type"
        s.vehicletype.copy("DEFAULT_VEHTYPE", vtype)
        s.vehicletype.setLength(vtype, ego.length)
        s.vehicletype.setWidth(vtype, ego.width)
        s.vehicletype.setVehicleClass(vtype, ego.vclass)
        s.vehicletype.setMaxSpeed(vtype, ego.max_speed)
        if self.driver == "planner":
            # SUMO's view of the ego's limits: the planner's, with the closed loop's
            # emergency braking (twice b_max, see _drive) as the physical limit; SUMO's
            # other drivers read these for the ego as a leader
            tp = self.sc.trajectory
            s.vehicletype.setAccel(vtype, tp.a_max)
            s.vehicletype.setDecel(vtype, tp.b_max)
            s.vehicletype.setEmergencyDecel(vtype, EMERGENCY_FACTOR * tp.b_max)
        s.vehicletype.setColor(vtype, (255, 0, 0, 255))
        rid = f"{ego.id}_route"
        s.route.add(rid, list(self.route_edges))
        extra = {}
        if self.driver != "planner":  # SUMO's drivers end their trip at the goal
            goal_len = self.net.length_of(ego.goal_edge)
            goal = ego.goal_pos if ego.goal_pos is not None else max(
                goal_len - self.sc.sim.goal_margin, 0.0)
            extra["arrivalPos"] = f"{goal:g}"
        s.vehicle.add(ego.id, rid, typeID=vtype, depart=f"{ego.depart:g}",
                      departPos=f"{ego.start_pos:g}", departLane=str(ego.start_lane),
                      departSpeed="0", **extra)

    # -- main loop --------------------------------------------------------------------------
    def loop(self) -> None:
        sc = self.sc
        bar = _progress_bar(sc.sim.duration, sc.name) if self.progress else None
        steps = round(sc.sim.duration / self.dt)
        planner = self.driver == "planner"
        try:
            with sigint_deferred() as ctrl_c:  # Ctrl-C stops between steps
                for k in range(steps):
                    ctrl_c.check()
                    if self.in_sim and planner:
                        self._drive()
                    self._step()
                    if self.on_step is not None:
                        self.on_step(self.time)
                    if bar is not None and k % 10 == 0:
                        bar.update(10 * self.dt)
                    if not self.in_sim:
                        if (self.depart_time is not None
                                or self.ego not in self.sumo.simulation.getDepartedIDList()):
                            continue
                        self._enter()
                    elif not planner and self.ego in self.sumo.simulation.getArrivedIDList():
                        self.status = "arrived"
                        self.reason = (f"SUMO's driver reached the end of its route at "
                                       f"t={self.time:.1f} s")
                        self.in_sim = False
                        break
                    self._observe()
                    if self.status != "running":
                        break
                    if planner:
                        if not self.replans:
                            self._replan("start", "")
                        else:
                            self._maybe_replan()
                else:
                    self.status = "timeout"
                    self.reason = self._timeout_reason()
        finally:
            if bar is not None:
                bar.close()

    def _timeout_reason(self) -> str:
        text = f"duration {self.sc.sim.duration:g} s reached before the ego arrived"
        if self.depart_time is None:
            return text + " (the ego was never inserted)"
        # how long the ego has been standing: SUMO's drivers wait behind a blockage forever
        # (--time-to-teleport -1)
        moving = [r[0] for r in self.rows if r[4] > 0.1]
        since = moving[-1] if moving else self.depart_time
        if self.time - since >= 5.0:
            text += (f" (standing still for the last {self.time - since:.0f} s on lane "
                     f"'{self.last_lane}')")
        if self.reason:
            text += f" ({self.reason})"
        return text

    def _step(self) -> None:
        s = self.sumo
        t0 = time.perf_counter()
        try:
            s.simulationStep()
        except Exception as err:
            if self.in_sim and self.ego not in s.vehicle.getIDList():
                raise SimulationError(
                    f"ego vehicle '{self.ego}' left the simulation at t={self.time:.1f} s "
                    "(removed by someone else)") from err
            raise SimulationError(f"SUMO failed at t={self.time:.1f} s: "
                                  f"{_sumo_message(err)}") from err
        self.time = float(s.simulation.getTime())
        self.sumo_seconds += time.perf_counter() - t0
        for c in s.simulation.getCollisions():
            rec = {"time": self.time, "collider": c.collider, "victim": c.victim,
                   "type": c.type, "lane": c.lane, "pos": c.pos}
            self.sumo_collisions.append(rec)
        tele = s.simulation.getStartingTeleportIDList()
        if tele:
            self.teleports += len(tele)
            if self.ego in tele:
                self.ego_teleports.append(self.time)

    def _enter(self) -> None:
        """The ego has just been inserted: subscribe to it and to the vehicles around it."""
        s, ego = self.sumo, self.sc.ego
        self.in_sim = True
        self.depart_time = self.time
        c = s.constants
        self.c = c
        s.vehicle.subscribe(self.ego, [c.VAR_POSITION, c.VAR_ANGLE, c.VAR_SPEED,
                                       c.VAR_LANE_ID])
        rng = self.sc.sim.lookahead + ego.length + 20.0
        s.vehicle.subscribeContext(self.ego, c.CMD_GET_VEHICLE_VARIABLE, rng,
                                   [c.VAR_POSITION, c.VAR_ANGLE, c.VAR_SPEED, c.VAR_LENGTH,
                                    c.VAR_WIDTH, c.VAR_STOPSTATE])
        if self.driver != "planner":
            return
        s.vehicle.setSpeedMode(self.ego, 0)
        s.vehicle.setLaneChangeMode(self.ego, 0)
        self._set_pose_from_sumo()
        self.v = 0.0

    # -- observation --------------------------------------------------------------------------
    def _read_others(self) -> None:
        """The vehicles around the ego, from the context subscription (one call), as
        arrays (:class:`~splineplan.traffic.Others`)."""
        c = self.c
        t0 = time.perf_counter()
        res = self.sumo.vehicle.getContextSubscriptionResults(self.ego)
        self.sumo_seconds += time.perf_counter() - t0
        ids = [vid for vid in res or () if vid != self.ego]
        if not ids:
            self.others = NO_OTHERS
            return
        pos, ang, spd = c.VAR_POSITION, c.VAR_ANGLE, c.VAR_SPEED
        lng, wid, stop = c.VAR_LENGTH, c.VAR_WIDTH, c.VAR_STOPSTATE
        a = np.array([(*v[pos], v[ang], v[lng], v[wid], v[spd], v[stop])
                      for v in map(res.__getitem__, ids)], dtype=float)
        self.others = Others(ids, a, self.sc.sim.stopped_speed)

    def _observe(self) -> None:
        """Read the world after a step; check where SUMO put the ego; safety checks."""
        s, ego = self.sumo, self.sc.ego
        c = self.c
        st = s.vehicle.getSubscriptionResults(self.ego)
        try:  # subscription results outlive a removal until the next step
            s.vehicle.getLaneID(self.ego)
        except Exception:
            st = None
        if not st:
            raise SimulationError(f"ego vehicle '{self.ego}' left the simulation at "
                                  f"t={self.time:.1f} s (removed by someone else)")
        fx, fy = st[c.VAR_POSITION]
        lane = st[c.VAR_LANE_ID]
        half = ego.length / 2.0
        if self.driver == "planner":
            x, y, h = (float(v) for v in self.pose)
            pos_err = math.hypot(fx - (x + half * math.cos(h)), fy - (y + half * math.sin(h)))
            self.position_errors.append(pos_err)
            self.deviation = pos_err
        else:
            h = float(heading_from_sumo_angle(st[c.VAR_ANGLE]))
            x, y = fx - half * math.cos(h), fy - half * math.sin(h)
            self.pose = np.array([x, y, h])
            self.v = float(st[c.VAR_SPEED])
            pos_err = math.nan
        self.last_lane = lane
        self._read_others()
        t0 = time.perf_counter()
        clear_obs, clear_veh, off_road = self._safety(x, y, h)
        self.check_seconds += time.perf_counter() - t0
        sl = self._project(np.array([x, y]))
        self.station = float(sl[0])
        self.lateral = float(sl[1])
        self.rows.append((self.time, x, y, h, self.v, self.station, float(sl[1]), lane,
                          float(fx), float(fy), pos_err, clear_obs, clear_veh, int(off_road),
                          self.limited))
        if self.station >= self.goal_station:
            self.status = "arrived"
            self.reason = (f"front bumper reached the goal on edge '{ego.goal_edge}' at "
                           f"t={self.time:.1f} s")
            _safe_remove(s, self.ego)
            self.in_sim = False

    def _safety(self, x: float, y: float, h: float) -> tuple[float, float, bool]:
        """Clearance [m] to stopped and to moving vehicles (and obstacle polygons), collisions
        (recorded), and whether the ego's footprint leaves the road.

        Every vehicle around the ego is checked: a lower bound of its distance from its
        bounding circle (one array pass), the exact footprint distance where that comes
        within 2 m.
        """
        ego, o = self.sc.ego, self.others
        # corners, centre and edge midpoints; the centre is not needed by the road check
        pts = probe_points(x, y, math.cos(h), math.sin(h), ego.length / 2.0, ego.width / 2.0)
        corners = pts[:4]
        clear_obs = clear_veh = math.inf
        r_ego = 0.5 * math.hypot(ego.length, ego.width)
        if o.n:
            dist = np.hypot(o.cx - x, o.cy - y) - (o.radius + r_ego)
            close = np.flatnonzero(dist < 2.0)
            if len(close):
                dist[close] = rectangle_distances(
                    (x, y), h, ego.length, ego.width, np.column_stack((o.cx[close],
                                                                     o.cy[close])),
                    o.head[close], o.length[close], o.width[close])
                for j in close[dist[close] <= 0.0]:
                    self.collisions.append({"time": self.time, "other": o.ids[j],
                                            "other_stopped": bool(o.stopped[j]),
                                            "source": "footprint"})
            if o.n_stopped:
                clear_obs = float(dist[o.stopped].min())
            if o.n_stopped < o.n:
                clear_veh = float(dist[~o.stopped].min() if o.n_stopped else dist.min())
        if len(self.polygons):
            ego_box = np.array(corners)
            near = self.polygons.near(ego_box, self.sc.sim.lookahead)
            if len(near):
                clear_obs = min(clear_obs, float(near.distance(ego_box).min()))
        probe = corners + pts[5:]
        off_road = not self.road.contains_all(probe, centre=(x, y), radius=r_ego)
        return clear_obs, clear_veh, off_road

    def _project(self, xy: FloatArray, *, back: float = 10.0, ahead: float = 20.0
                 ) -> FloatArray:
        """Stations and lateral offsets ``(k, 2)`` of points ``(k, 2)`` (or ``(2,)`` of one
        point ``(2,)``) near the ego.

        A local search over the corridor's reference segments from ``back`` [m] behind to
        ``ahead`` [m] ahead of the ego's last station (the ego moves a few decimetres a
        step); a full projection (:meth:`Corridor.to_sl`) for points whose nearest segment
        is at the window's edge.
        """
        c = self.corridor
        assert c is not None
        pts = np.asarray(xy, dtype=float)
        one = pts.ndim == 1
        pts = pts.reshape(-1, 2)
        s = c.s
        nseg = len(s) - 1
        lo = max(bisect.bisect_left(self._ref_s, self.station - back) - 1, 0)
        hi = min(bisect.bisect_left(self._ref_s, self.station + ahead) + 1, nseg)
        if hi <= lo:
            out = np.asarray(c.to_sl(pts))
            return out[0] if one else out
        cols = self._ref_cols
        ax, ay, abx, aby, len2 = (cols[0][lo:hi], cols[1][lo:hi], cols[2][lo:hi],
                                  cols[3][lo:hi], cols[4][lo:hi])
        if one:  # one point: the same arithmetic on (n,) rows, then plain floats
            px, py = float(pts[0, 0]), float(pts[0, 1])
            dx1 = px - ax
            dy1 = py - ay
            t1 = np.minimum(np.maximum((dx1 * abx + dy1 * aby) / len2, 0.0), 1.0)
            ex1 = dx1 - t1 * abx
            ey1 = dy1 - t1 * aby
            k1 = int(np.argmin(ex1 * ex1 + ey1 * ey1))
            if (k1 == 0 and lo > 0) or (k1 == hi - lo - 1 and hi < nseg):
                return np.asarray(c.to_sl(pts))[0]
            ln1 = float(self._ref_len[lo + k1])
            return np.array([float(s[lo + k1]) + float(t1[k1]) * ln1,
                             (float(abx[k1]) * float(dy1[k1]) - float(aby[k1])
                              * float(dx1[k1])) / ln1])
        dx = pts[:, 0, None] - ax  # (k, n)
        dy = pts[:, 1, None] - ay
        t = np.minimum(np.maximum((dx * abx + dy * aby) / len2, 0.0), 1.0)
        ex = dx - t * abx
        ey = dy - t * aby
        k = np.argmin(ex * ex + ey * ey, axis=1)
        r = np.arange(len(pts))
        ln = self._ref_len[lo + k]
        out = np.column_stack((s[lo + k] + t[r, k] * ln,
                               (abx[k] * dy[r, k] - aby[k] * dx[r, k]) / ln))
        edge = ((k == 0) & (lo > 0)) | ((k == hi - lo - 1) & (hi < nseg))
        if edge.any():
            out[edge] = c.to_sl(pts[edge])
        return out[0] if one else out

    def _edge_at(self, station: float) -> str:
        """:meth:`Corridor.edge_at` of the route's corridor (``""`` for none), on a list."""
        assert self.corridor is not None
        edges = self.corridor.edges
        if not edges:
            return ""
        return edges[max(bisect.bisect_right(self._edge_starts, station) - 1, 0)] or ""

    limited = 0
    deviation = 0.0
    station = 0.0
    others: Others

    # -- obstacles ahead ----------------------------------------------------------------------
    def _ahead(self) -> tuple[np.ndarray, np.ndarray]:
        """Indices of the stopped vehicles (in ``self.others``) and of the obstacle polygons
        near the route within the look-ahead.

        Where an obstacle lies on the route is computed once per obstacle and position (a
        stopped vehicle does not move) and route.
        """
        o = self.others
        sim, ego = self.sc.sim, self.sc.ego
        lo = self.station - ego.length - 5.0
        assert self.corridor is not None
        hi = min(self.station + sim.lookahead, self.corridor.length) + 5.0
        veh = np.flatnonzero(o.stopped) if o.n_stopped else ()
        keep_v = []
        for i in veh:
            fx, fy = o.front[i]
            key = (o.ids[i], round(float(fx), 1), round(float(fy), 1))
            where = self._obs_cache.get(key)
            if where is None:
                box = footprints(o.front[i:i + 1], o.head[i:i + 1], o.length[i:i + 1],
                                 o.width[i:i + 1])[0]
                where = self._on_route(box)
                self._obs_cache[key] = where
            if where[2] and where[1] >= lo and where[0] <= hi:
                keep_v.append(i)
        keep_p: list[int] = []
        for j in range(len(self.polygons)):
            key = (f"polygon:{j}", 0.0, 0.0)
            where = self._obs_cache.get(key)
            if where is None:
                where = self._on_route(self.polygons.polygon(j))
                self._obs_cache[key] = where
            if where[2] and where[1] >= lo and where[0] <= hi:
                keep_p.append(j)
        return np.asarray(keep_v, dtype=np.int64), np.asarray(keep_p, dtype=np.int64)

    def _on_route(self, poly: FloatArray) -> tuple[float, float, bool]:
        """Station range [m] of a polygon on the route, and whether it is within 1 m of the
        drivable area laterally."""
        assert self.corridor is not None
        sl = self.corridor.to_sl(poly)
        r, lft = self.corridor.bounds_at(np.clip(sl[:, 0], 0.0, self.corridor.length))
        lateral = bool((sl[:, 1].max() >= r.min() - 1.0) and (sl[:, 1].min() <= lft.max() + 1.0))
        return float(sl[:, 0].min()), float(sl[:, 0].max()), lateral

    def _ahead_ids(self, veh: np.ndarray, poly: np.ndarray) -> set[str]:
        if not len(veh) and not len(poly):
            return set()
        ids = self.others.ids
        return {ids[i] for i in veh} | {self.polygons.ids[j] for j in poly}

    def _obstacles_ahead(self, ahead: tuple[np.ndarray, np.ndarray] | None = None
                         ) -> Obstacles:
        """Stopped vehicles and obstacle polygons near the route within the look-ahead."""
        veh, poly = self._ahead() if ahead is None else ahead
        o = self.others
        obs = Obstacles.empty()
        if len(veh):
            obs = Obstacles.from_boxes(o.front[veh], o.head[veh], o.length[veh], o.width[veh],
                                       reference="front", ids=[o.ids[i] for i in veh])
        if len(poly):
            obs = obs + self.polygons.subset(poly)
        return obs

    # -- planning ----------------------------------------------------------------------------
    def _maybe_replan(self) -> None:
        """Replan when needed: retry after a failure, SUMO put the ego off the plan, the plan
        runs short (every step), a new obstacle ahead, a vehicle beside the ego comes near
        the plan (every :data:`TRIGGER_PERIOD`)."""
        sim = self.sc.sim
        if self.traj is None or self.retry_at is not None:
            if self.retry_at is not None and self.time >= self.retry_at:
                self._replan("retry", self.reason)
            return
        if self.deviation > sim.deviation_tolerance:
            self._set_pose_from_sumo()
            self._replan("deviation", f"SUMO placed the ego {self.deviation:.2f} m off the plan")
            return
        ahead = None
        if self.time >= self.trigger_after:
            self.trigger_after = self.time + TRIGGER_PERIOD - 0.5 * self.dt
            ahead = self._ahead()
            new = self._ahead_ids(*ahead) - self.planned_ids
            if new:
                self._replan("obstacles", "new obstacle(s) ahead: " + ", ".join(sorted(new)),
                             obstacles=self._obstacles_ahead(ahead))
                return
            if self.time >= self.traffic_after:
                near = self._traffic_conflict()
                if near is not None:
                    self.traffic_after = self.time + _TRAFFIC_REPLAN_EVERY
                    self._replan("traffic", f"vehicle '{near}' beside the ego comes near the "
                                            "planned path", obstacles=self._obstacles_ahead(ahead))
                    return
        assert self.corridor is not None
        left = float(self.path_s[-1]) - self.u
        if (self.window_end < self.corridor.length - 1e-6 or self.truncated) and (
                left < sim.replan_distance):
            self._replan("horizon", f"{left:.1f} m of the plan left",
                         obstacles=self._obstacles_ahead(ahead))

    def _set_pose_from_sumo(self) -> None:
        s, ego = self.sumo, self.sc.ego
        front = np.asarray(s.vehicle.getPosition(self.ego), dtype=float)
        h = float(heading_from_sumo_angle(s.vehicle.getAngle(self.ego)))
        c = front - ego.length / 2.0 * np.array([math.cos(h), math.sin(h)])
        self.pose = np.array([c[0], c[1], h])

    def _replan(self, reason: str, detail: str, *, obstacles: Obstacles | None = None) -> None:
        t0 = time.perf_counter()
        obstacles = self._obstacles_ahead() if obstacles is None else obstacles
        ok, msg = self._plan(obstacles)
        reroutes = 0
        while not ok and isinstance(msg, RoadBlockedError) and reroutes < _MAX_REROUTES:
            reroutes += 1
            done, why = self._reroute(msg)
            if not done:
                msg = why
                break
            obstacles = self._obstacles_ahead()
            ok, msg = self._plan(obstacles)
            if ok:
                reason = "reroute"
                detail = why
        elapsed = time.perf_counter() - t0
        self.plan_seconds += elapsed
        station = self.station
        if ok:
            self.retry_at = None
            self.stop_at = None
            self.planned_ids = frozenset(obstacles.ids)
            self.replans.append(Replan(self.time, reason, elapsed, station, True, detail))
            log.debug("t=%.1f replan (%s) in %.1f ms", self.time, reason, 1e3 * elapsed)
            return
        text = str(msg)
        self.replans.append(Replan(self.time, reason, elapsed, station, False,
                                   f"{detail}; failed: {text}" if detail else text))
        log.info("t=%.1f plan failed: %s", self.time, text)
        self.reason = f"no plan: {text}"
        self.retry_at = self.time + _RETRY_AFTER
        self._brake_before_blockage(msg)

    def _plan(self, obstacles: Obstacles) -> tuple[bool, Any]:
        """Levels 2 and 3 on the window ahead. Returns (ok, error).

        Moving vehicles beside the ego (:meth:`_moving_obstacles`) are planned around too
        where that gives a trajectory that keeps the safety margin; otherwise the plan is
        made among the stopped obstacles alone and the moving vehicles are left to the
        time-gap speed control.
        """
        moving = self._moving_obstacles()
        if len(moving):
            ok, err = self._plan_among(obstacles, moving)
            if ok:
                return ok, err
            log.debug("t=%.1f no plan around the traffic beside the ego (%s): planning "
                      "among the stopped obstacles only", self.time, err)
        return self._plan_among(obstacles, None)

    def _plan_among(self, obstacles: Obstacles, moving: Obstacles | None
                    ) -> tuple[bool, Any]:
        """Levels 2 and 3 among ``obstacles`` (and ``moving``, strictly: any failure or a
        trajectory short of the margin is a refusal, never a truncated plan)."""
        from splineplan.planner import plan_corridor

        sc, ego = self.sc, self.sc.ego
        assert self.corridor is not None
        s0 = max(self.station - ego.length, 0.0)
        s1 = self.station + sc.sim.lookahead
        if len(obstacles):  # reach past every obstacle seen, so a closed road shows at once
            far = float(self.corridor.to_sl(obstacles.vertices)[:, 0].max())
            s1 = max(s1, far + ego.length + 2.0 * sc.roadmap.d)
        s1 = min(s1, self.corridor.length)
        if s1 - s0 < 2.0 * sc.roadmap.d + ego.length:
            s0 = max(s1 - 2.0 * sc.roadmap.d - ego.length, 0.0)
        final = s1 >= self.corridor.length - 1e-6
        everything = obstacles if moving is None else obstacles + moving
        try:
            window = self.corridor.slice(s0, s1)
            roadmaps, traj = plan_corridor(
                window, everything, self.pose[:2], float(self.pose[2]),
                roadmap_params=sc.roadmap, params=sc.trajectory,
                start_speed=float(self.v), end_speed=0.0 if final else None)
        except RoadBlockedError as err:
            if moving is not None:
                return False, err
            blocked = err
            if blocked.edge is None:
                blocked = RoadBlockedError(str(err), station=err.station,
                                           edge=self.corridor.edge_at(float(err.station)),
                                           junction=self.corridor.junction_at(
                                               float(err.station)))
            blocked.station_on_route = float(blocked.station)  # type: ignore[attr-defined]
            return False, blocked
        except (TrajectoryError, GeometryError) as err:
            return False, err
        bad = np.flatnonzero(np.asarray(traj.clearance_obstacles)
                             < sc.roadmap.safety_margin - 1e-6)
        usable = None
        if len(bad) and moving is not None:
            return False, TrajectoryError("trajectory comes too near the traffic beside")
        if len(bad):
            # level 3 reports a curve that comes closer than the margin: drive only the part
            # that keeps clear, stop before the rest, and replan on the way
            usable = float(traj.s[bad[0]]) - sc.roadmap.d
            if usable < max(2.0 * sc.roadmap.d, 0.5 * float(self.v) ** 2 / (
                    sc.trajectory.b_max)):
                return False, TrajectoryError(
                    f"trajectory passes {float(np.min(traj.clearance_obstacles)):.2f} m "
                    f"from an obstacle {float(traj.s[bad[0]]):.1f} m ahead")
            log.info("t=%.1f trajectory infeasible %.1f m ahead: driving %.1f m of it",
                     self.time, float(traj.s[bad[0]]), usable)
        self._take(traj, s1, usable=usable)
        self.plans.append((self.time, roadmaps, traj, window, everything))
        return True, None

    def _beside(self) -> tuple[np.ndarray, FloatArray]:
        """Moving vehicles beside the ego: indices into ``self.others`` and their centres'
        station and lateral offset ``(k, 2)`` on the route.

        Beside: not stopped, driving the route's way (within 45 degrees), on the route's
        road, between :data:`_BESIDE_BACK` behind and :data:`_BESIDE_AHEAD` ahead of the
        ego's centre, and at least :data:`BESIDE_LATERAL` to its side.
        """
        o = self.others
        if not o.n or self.corridor is None:
            return np.zeros(0, dtype=np.int64), np.zeros((0, 2))
        if self._beside_at == (self.time, self.station):
            return self._beside_was
        self._beside_at = (self.time, self.station)
        self._beside_was = self._beside_now()
        return self._beside_was

    def _beside_now(self) -> tuple[np.ndarray, FloatArray]:
        o = self.others
        assert self.corridor is not None
        picked = self._beside_candidates()
        if not picked:
            return np.zeros(0, dtype=np.int64), np.zeros((0, 2))
        cand = np.asarray(picked, dtype=np.int64)
        c = self.corridor
        sl = self._project(np.column_stack((o.cx[cand], o.cy[cand])),
                           back=_BESIDE_BACK + 15.0, ahead=_BESIDE_AHEAD + 15.0)
        s_in = np.minimum(np.maximum(sl[:, 0], 0.0), c.length)
        right, left = c.bounds_at(s_in)
        seg = np.minimum(np.searchsorted(c.s, s_in, side="right") - 1, len(c.s) - 2)
        along = np.cos(o.head[cand] - self._ref_heading[seg]) > math.cos(math.pi / 4.0)
        keep = (along & (sl[:, 0] >= self.station - _BESIDE_BACK)
                & (sl[:, 0] <= self.station + _BESIDE_AHEAD)
                & (sl[:, 1] >= right - 0.5) & (sl[:, 1] <= left + 0.5)
                & (np.abs(sl[:, 1] - self.lateral) >= BESIDE_LATERAL))
        return cand[keep], sl[keep]

    def _beside_candidates(self) -> list[int]:
        """Increasing indices into ``self.others`` of the vehicles that may be beside the ego
        (:meth:`_beside`): a cheap first cut in the ego's own frame, a superset of those
        beside, before projecting onto the route. Cached per time and station."""
        if self._cand_at == (self.time, self.station):
            return self._cand_was
        o = self.others
        x, y, h = (float(v) for v in self.pose)
        ch, sh = math.cos(h), math.sin(h)
        window = self._route_window()
        cos_min = math.nan  # computed once a vehicle needs it
        picked = []
        # plain floats: a few vehicles
        for i, (cx, cy, co, si, stopped) in enumerate(zip(
                o.cx.tolist(), o.cy.tolist(), o.cos.tolist(), o.sin.tolist(),
                o.stopped.tolist(), strict=True)):
            if stopped:
                continue
            dx, dy = cx - x, cy - y
            lon = dx * ch + dy * sh
            lat = abs(dy * ch - dx * sh)
            if not (-_BESIDE_BACK - 5.0 < lon < _BESIDE_AHEAD + 5.0
                    and BESIDE_LATERAL - 0.5 < lat < 10.0):
                continue
            if math.isnan(cos_min):
                # a vehicle heading more than 45 degrees plus the route's largest turn away
                # from the ego's heading (within the beside stations) cannot drive the
                # route's way
                cos_min = math.cos(min(math.pi / 4.0 + self._route_turn(h, window), math.pi))
            if co * ch + si * sh >= cos_min - 1e-9:
                picked.append(i)
        self._cand_at = (self.time, self.station)
        self._cand_was = picked
        return picked

    def _route_window(self) -> FloatArray:
        """Headings [rad] of the route's segments from a metre before :data:`_BESIDE_BACK`
        behind the ego's station to a metre after :data:`_BESIDE_AHEAD` ahead (the window
        moves on once the ego has driven a metre)."""
        c = self.corridor
        assert c is not None
        key = self._turn_key
        if key is None or key[0] is not c or abs(self.station - key[1]) > 1.0:
            lo = max(int(np.searchsorted(c.s, self.station - _BESIDE_BACK - 2.0)) - 1, 0)
            hi = int(np.searchsorted(c.s, self.station + _BESIDE_AHEAD + 2.0)) + 1
            self._turn_window = self._ref_heading[lo:hi]
            self._turn_key = (c, self.station)
        return self._turn_window

    @staticmethod
    def _route_turn(h: float, window: FloatArray) -> float:
        """Largest angle [rad] between a heading ``h`` and the headings ``window``
        (:meth:`_route_window`)."""
        d = np.abs(np.mod(window - h + math.pi, 2.0 * math.pi) - math.pi)
        return float(d.max()) if len(d) else math.pi

    def _moving_obstacles(self) -> Obstacles:
        """Swept footprints of the moving vehicles beside the ego (:meth:`_beside`).

        Each is the band of the vehicle's width at its lateral offset on the route, from its
        rear to where its front will be after :data:`SWEEP_TIME` at its speed, following the
        road; it starts some way ahead of the ego's front bumper (:data:`_SWEEP_CLIP`; the
        ego cannot leave the place it is in, and a plan that starts inside an obstacle
        would be refused).
        """
        idx, sl = self._beside()
        if not len(idx):
            return Obstacles.empty()
        assert self.corridor is not None
        c, ego = self.corridor, self.sc.ego
        o = self.others
        ids, lens, wids, speeds = o.ids, o.length, o.width, o.speed
        clip = self.station + ego.length / 2.0 + max(_SWEEP_CLIP, self.v * _SWEEP_CLIP_TIME)
        polys, names = [], []
        for j, i in enumerate(idx):
            s_c, l_c = float(sl[j, 0]), float(sl[j, 1])
            s_lo = max(s_c - lens[i] / 2.0, clip)
            s_hi = min(s_c + lens[i] / 2.0 + max(float(speeds[i]), 0.0) * SWEEP_TIME,
                       c.length)
            if s_hi - s_lo < 0.5:
                continue
            ss = np.linspace(s_lo, s_hi, max(math.ceil((s_hi - s_lo) / 2.0), 1) + 1)
            half = wids[i] / 2.0
            polys.append(np.vstack((c.to_xy(ss, l_c - half), c.to_xy(ss[::-1], l_c + half))))
            names.append(f"moving:{ids[i]}")
        return Obstacles.from_polygons(polys, names) if polys else Obstacles.empty()

    def _traffic_conflict(self) -> str | None:
        """The first moving vehicle beside the ego that, driving on at its speed and
        heading, comes within the ego's width plus the safety margin of where the ego will
        be along its plan in the next few seconds; ``None`` if none does."""
        if self.traj is None or not self.others.n or self.corridor is None:
            return None
        # the test on the cheap superset of the vehicles beside first: usually none comes
        # near, and then none of those beside does either
        cand = self._beside_candidates()
        if not cand:
            return None
        hits = self._conflicts(cand)
        if not hits:
            return None
        idx, _ = self._beside()
        first = [i for i in idx.tolist() if i in hits]
        return self.others.ids[first[0]] if first else None

    def _conflicts(self, idx: list[int]) -> list[int]:
        """Those of the vehicles ``idx`` (indices into ``self.others``) that, driving on at
        their speed and heading, come near the plan (:meth:`_traffic_conflict`).

        Plain floats: a few vehicles at a few prediction times."""
        ego, margin = self.sc.ego, self.sc.roadmap.safety_margin
        o = self.others
        ps, px, py, ph, _ = self._pl
        end = ps[-1]
        poses = []  # where the ego will be: x, y, cos, sin of the heading
        for tau in _CONFLICT_TIMES:
            j, f = _locate(min(self.u + self.v * tau, end), ps)
            if len(ps) < 2:
                x, y, h = px[0], py[0], ph[0]
            else:
                x = px[j] + f * (px[j + 1] - px[j])
                y = py[j] + f * (py[j + 1] - py[j])
                h = ph[j] + f * (ph[j + 1] - ph[j])
            poses.append((tau, x, y, math.cos(h), math.sin(h)))
        hits = []
        for i in idx:
            cx, cy, co, si = float(o.cx[i]), float(o.cy[i]), float(o.cos[i]), float(o.sin[i])
            v = float(o.speed[i])
            lon_max = (ego.length + float(o.length[i])) / 2.0 + _CONFLICT_SLACK
            lat_max = (ego.width + float(o.width[i])) / 2.0 + margin
            for tau, x, y, ce, se in poses:
                dx = cx + v * tau * co - x
                dy = cy + v * tau * si - y
                if abs(dx * ce + dy * se) < lon_max and abs(dy * ce - dx * se) < lat_max:
                    hits.append(i)
                    break
        return hits

    def _take(self, traj: Any, window_end: float, *, usable: float | None = None) -> None:
        s = np.asarray(traj.s, dtype=float)
        self.truncated = usable is not None
        if usable is not None:  # cut the trajectory: the ego stops at its new end
            cut = max(int(np.searchsorted(s, usable)), 2)
            traj = _Cut(s[:cut], np.asarray(traj.x)[:cut], np.asarray(traj.y)[:cut],
                        np.asarray(traj.heading)[:cut], np.asarray(traj.speed)[:cut])
            s = traj.s
        n = max(math.ceil(s[-1] / _PATH_SPACING), 1) + 1
        u = np.linspace(0.0, s[-1], n)
        self.path_s = u
        self.path_xy = np.column_stack((np.interp(u, s, traj.x), np.interp(u, s, traj.y)))
        self.path_heading = np.interp(u, s, np.unwrap(traj.heading))
        self.path_speed = np.interp(u, s, traj.speed)
        ext = np.arange(1, int(_PATH_EXTENSION / _PATH_SPACING) + 1) * _PATH_SPACING
        h_end = self.path_heading[-1]
        self.ext_s = u[-1] + ext
        self.ext_xy = self.path_xy[-1] + ext[:, None] * np.array([math.cos(h_end),
                                                                  math.sin(h_end)])
        self.ext_heading = np.full(len(ext), h_end)
        # the path and its straight extension, for the time-gap check
        self.full_xy = np.concatenate((self.path_xy, self.ext_xy))
        self.full_s = np.concatenate((self.path_s, self.ext_s))
        self.full_heading = np.concatenate((self.path_heading, self.ext_heading))
        # for the time-gap check: the bounding box (x min, x max, y min, y max) of the
        # samples from each on, and the largest distance between consecutive samples
        fx, fy = self.full_xy[:, 0], self.full_xy[:, 1]
        self._ahead_box = tuple(acc(v[::-1])[::-1].tolist() for acc, v in (
            (np.minimum.accumulate, fx), (np.maximum.accumulate, fx),
            (np.minimum.accumulate, fy), (np.maximum.accumulate, fy)))
        self._sample_step = (float(np.hypot(np.diff(fx), np.diff(fy)).max()) * (1.0 + 1e-9)
                             if len(fx) > 1 else 0.0)
        # plain lists for the per-step interpolation along the path
        self._pl = (u.tolist(), self.path_xy[:, 0].tolist(), self.path_xy[:, 1].tolist(),
                    self.path_heading.tolist(), (self.path_speed**2).tolist())
        self._full = (self.full_s.tolist(), self.full_xy[:, 0].tolist(),
                      self.full_xy[:, 1].tolist(), self.full_heading.tolist())
        self.traj = traj
        self.u = 0.0
        # the trajectory starts at the ego's centre: keep u where the ego is
        d = np.hypot(*(self.path_xy - self.pose[:2]).T)
        self.u = float(u[int(np.argmin(d[: max(1, int(5.0 / _PATH_SPACING))]))])
        self.window_end = window_end

    def _reroute(self, err: RoadBlockedError) -> tuple[bool, Any]:
        """Level 1 again with the blocked edge avoided. Returns (done, detail or error)."""
        from splineplan.network import route_corridor
        from splineplan.route import route_length, shortest_route

        ego = self.sc.ego
        assert self.corridor is not None
        blocked = err.closed_edge
        here = self.corridor.edge_at(self.station)
        if blocked is None or blocked == here or blocked in self.avoid:
            return False, err
        self.avoid.add(blocked)
        assert here is not None
        start = float(self.corridor.edge_starts[self.corridor.edges.index(here)])
        pos = min(max(self.station - start + ego.length / 2.0, 0.0), self.net.length_of(here))
        try:
            route = shortest_route(self.net, here, ego.goal_edge, vclass=ego.vclass,
                                   avoid=self.avoid, start_pos=pos)
            corridor = route_corridor(self.net, route, vclass=ego.vclass)
        except (NoRouteError, GeometryError) as e:
            return False, RoadBlockedError(f"{err}; no other route: {e}", station=err.station,
                                           edge=blocked)
        try:
            self.sumo.vehicle.setRoute(self.ego, list(route.edges))
        except Exception as e:
            return False, SimulationError(f"SUMO refused the new route: {_sumo_message(e)}")
        old = self.route_edges
        self.driven_before += old[:old.index(here)]
        self._set_route(corridor, route.edges)
        self.station = float(corridor.to_sl(self.pose[:2])[0, 0])
        # the route as driven from the start: what was driven before, then the new route
        self.route_length = route_length(self.net, self.driven_before + route.edges,
                                         vclass=ego.vclass, start_pos=ego.start_pos)
        log.info("t=%.1f re-routed around %s", self.time, blocked)
        return True, (f"edge '{blocked}' blocked; route {' '.join(old)} -> "
                      f"{' '.join(route.edges)}")

    def _brake_before_blockage(self, err: Any) -> None:
        """No new plan: keep the old trajectory but stop before the blockage."""
        if self.traj is None:
            return
        st = getattr(err, "station_on_route", None)
        if st is None:
            self.stop_at = self.u + 0.5 * self.v * self.v / self.sc.trajectory.b_max
            return
        # station on the route -> on the trajectory: offset by where the ego is on both
        margin = self.sc.ego.length + 2.0 * self.sc.roadmap.d + 2.0
        self.stop_at = max(self.u + (st - self.station) - margin, self.u)

    # -- driving ------------------------------------------------------------------------------
    def _drive(self) -> None:
        """Advance along the trajectory and move the ego in SUMO."""
        if self.traj is None:
            self._move()
            return
        sc, ego = self.sc, self.sc.ego
        tp = sc.trajectory
        dt = self.dt
        # speed squared is linear in station under constant acceleration: interpolate it
        u_next = self.u + self.v * dt + 0.5 * tp.a_max * dt * dt
        ps, px, py, ph, pv2 = self._pl
        v_plan = math.sqrt(max(_interp(u_next, ps, pv2), 0.0))
        v_cap, limited = self._gap_speed()
        if self.stop_at is not None:
            v_cap = min(v_cap, math.sqrt(max(2.0 * tp.b_max * (self.stop_at - self.u), 0.0)))
            limited = 1
        end = float(self.path_s[-1])
        # stop at the trajectory's end unless a new plan comes first
        v_cap = min(v_cap, math.sqrt(max(2.0 * tp.b_max * (end - self.u), 0.0)))
        v_target = min(v_plan, v_cap)
        emergency = EMERGENCY_FACTOR * tp.b_max
        v_new = min(max(v_target, self.v - emergency * dt), self.v + tp.a_max * dt)
        v_new = max(v_new, 0.0)
        u = min(self.u + 0.5 * (self.v + v_new) * dt, end)
        if u >= end:
            v_new = 0.0
        self.u, self.v = u, v_new
        self.limited = limited
        j, f = _locate(u, ps)
        x = px[j] + f * (px[j + 1] - px[j])
        y = py[j] + f * (py[j + 1] - py[j])
        h = ph[j] + f * (ph[j + 1] - ph[j])
        self.pose = np.array([x, y, h])
        del ego
        self._move(x, y, h)

    def _move(self, x: float | None = None, y: float | None = None, h: float | None = None
              ) -> None:
        """Put the ego at centre ``x``, ``y`` [m], heading ``h`` [rad] (default: its pose)."""
        s, ego = self.sumo, self.sc.ego
        if x is None or y is None or h is None:
            x, y, h = (float(v) for v in self.pose)
        fx = x + ego.length / 2.0 * math.cos(h)
        fy = y + ego.length / 2.0 * math.sin(h)
        angle = sumo_angle_from_heading(h)
        assert self.corridor is not None
        edge = self._edge_at(self.station)
        if self._lane_of[0] != self.last_lane:
            self._lane_of = (self.last_lane, _lane_index(self.last_lane))
        lane = self._lane_of[1]
        t0 = time.perf_counter()
        s.vehicle.moveToXY(self.ego, edge, lane, fx, fy, angle, KEEP_ROUTE)
        # without it SUMO infers the speed from the move, measured along its lanes' lengths
        # and capped by the lanes' speed limits: at each lane change and junction it
        # saw jumps of the speed (and "emergency braking" of 10 to 37 m/s^2) that the plan
        # never had
        s.vehicle.setSpeed(self.ego, self.v)
        self.sumo_seconds += time.perf_counter() - t0

    def _gap_speed(self) -> tuple[float, int]:
        """Speed cap [m/s] to keep the time gap to whatever is in the path, and red lights.

        A vehicle is in the path where a corner, the centre or an edge's midpoint of its
        footprint comes within the ego's half width plus :data:`PATH_MARGIN` of a path sample
        ahead of the ego (the trajectory and its straight extension); the gap is to the first
        such sample. Only the samples within the vehicle's bounding circle plus that reach
        can be in reach: a vehicle whose circle misses the bounding box of the samples
        ahead is skipped, and the samples in the circle are found by a walk along the path
        that skips those the distance bound rules out (:func:`~splineplan.traffic.next_in_circle`).
        """
        sc, ego, tp = self.sc, self.sc.ego, self.sc.trajectory
        sim = sc.sim
        cap = math.inf
        o = self.others
        reach = ego.width / 2.0 + min(PATH_MARGIN, 0.5 * sc.roadmap.safety_margin)
        if o.n:
            full_s, full_x, full_y, full_h = self._full
            i0 = bisect.bisect_left(self._pl[0], self.u)  # first sample ahead
            cand = []  # (first sample in the circle, vehicle, centre x, y, circle's radius)
            if i0 < len(full_s):
                x0, x1, y0, y1 = (b[i0] for b in self._ahead_box)
                step = self._sample_step
                for j, (cx, cy, r) in enumerate(zip(o.cx.tolist(), o.cy.tolist(),
                                                    o.radius.tolist(), strict=True)):
                    r += reach
                    if cx + r < x0 or cx - r > x1 or cy + r < y0 or cy - r > y1:
                        continue
                    lo = next_in_circle(full_x, full_y, i0, cx, cy, r, step)
                    if lo >= 0:
                        cand.append((lo, j, cx, cy, r))
            cand.sort()
            reach2 = reach * reach
            base = self.u + ego.length / 2.0 + sim.min_gap
            for lo, j, cx, cy, r in cand:
                # the gap is at least up to the first sample in reach of the bounding
                # circle, and a leader's speed is at least 0: nothing after can go lower
                if safe_speed(full_s[lo] - base, 0.0, tp.b_max, sim.time_gap) >= cap:
                    break
                pts = probe_points(cx, cy, float(o.cos[j]), float(o.sin[j]),
                                    0.5 * float(o.length[j]), 0.5 * float(o.width[j]))
                first = first_in_reach(pts, lo, (cx, cy, r, self._sample_step),
                                        full_x, full_y, reach2)
                if first < 0:
                    continue
                gap = full_s[first] - base
                rel = math.cos(float(o.head[j]) - full_h[first])
                v_l = max(float(o.speed[j]) * rel, 0.0)
                cap = min(cap, safe_speed(gap, v_l, tp.b_max, sim.time_gap))
        cap = min(cap, self._red_light_speed(), self._yield_speed())
        return cap, int(math.isfinite(cap))

    def _red_light_speed(self) -> float:
        tp = self.sc.trajectory
        try:
            tls = self.sumo.vehicle.getNextTLS(self.ego)
        except Exception:
            return math.inf
        for _, _, dist, state in tls:
            if dist > self.sc.sim.lookahead:
                break
            if state in "rRyYu":
                need = self.v * self.v / (2.0 * tp.b_max)
                if state in "yY" and dist < need:
                    return math.inf  # cannot stop comfortably: go
                return math.sqrt(max(2.0 * tp.b_max * (dist - 1.0), 0.0))
            break
        return math.inf

    def _yield_speed(self) -> float:
        """Speed cap [m/s] that gives way at junctions, as SUMO's right of way says.

        For each vehicle that the ego must yield to on its way through the next junctions
        (``getJunctionFoes``: ``egoResponse``) and that has not cleared the conflict area,
        the times it occupies that area (at its speed) and the times the ego would (along
        its plan, accelerating from its speed) are compared; where they come within
        :data:`YIELD_GAP` of each other, the ego stops :data:`YIELD_STOP` before the area,
        if it still can at its braking limit. Once it cannot, it goes on: a car that stops
        inside a crossing blocks it. A foe standing still outside the area is waiting
        (for a light or another vehicle) and is no conflict.
        """
        tp, ego = self.sc.trajectory, self.sc.ego
        try:
            foes = self.sumo.vehicle.getJunctionFoes(self.ego, self.sc.sim.lookahead)
        except Exception:  # an older SUMO, or the ego not on its route: SUMO's view only
            return math.inf
        cap = math.inf
        for foe in foes:
            fid, ego_in, foe_in, ego_out, foe_out, must_yield = (
                foe[0], foe[1], foe[2], foe[3], foe[4], foe[7])
            if not must_yield or ego_in <= YIELD_STOP:
                continue  # the ego has the way, or is at (or in) the area already
            try:
                v_f = self.sumo.vehicle.getSpeed(fid)
                foe_out += self.sumo.vehicle.getLength(fid)
            except Exception:
                continue
            if foe_out <= 0.0 or (foe_in > 0.0 and v_f < STOPPED_FOE_SPEED):
                continue  # cleared, or waiting outside the area
            t_foe_in = max(foe_in, 0.0) / max(v_f, 1e-3)
            t_foe_out = foe_out / max(v_f, 1e-3)
            t_in = self._time_along_plan(ego_in)
            t_out = self._time_along_plan(ego_out + ego.length)
            if t_in - YIELD_GAP >= t_foe_out or t_foe_in >= t_out + YIELD_GAP:
                continue
            room = ego_in - YIELD_STOP
            if self.v * self.v > 2.0 * EMERGENCY_FACTOR * tp.b_max * room:
                continue  # cannot stop before the area, even braking hard: clear it
            # a comfortable stop, one step early
            cap = min(cap, math.sqrt(max(2.0 * tp.b_max * (room - self.v * self.dt), 0.0)))
        return cap

    def _time_along_plan(self, dist: float) -> float:
        """Time [s] the ego takes to drive ``dist`` [m] along its plan from where it is,
        at the plan's speeds but no faster than accelerating from its speed at ``a_max``."""
        ps, _, _, _, pv2 = self._pl
        a2 = 2.0 * self.sc.trajectory.a_max
        u0, end = self.u, min(self.u + dist, ps[-1])
        t, u, v = 0.0, u0, self.v
        i = bisect.bisect_right(ps, u0)
        while u < end - 1e-9:
            nxt = min(ps[i], end) if i < len(ps) else end
            v_next = max(min(math.sqrt(max(_interp(nxt, ps, pv2), 0.0)),
                             math.sqrt(self.v * self.v + a2 * (nxt - u0))), 0.5)
            t += 2.0 * (nxt - u) / (max(v, 0.5) + v_next)
            u, v, i = nxt, v_next, i + 1
        # beyond the plan's end: at the last speed
        return t + max(dist - (end - u0), 0.0) / max(v, 0.5)

    # -- end ----------------------------------------------------------------------------------
    def fail(self, err: BaseException) -> None:
        self.status = "failed"
        self.reason = f"{type(err).__name__}: {_sumo_message(err)}"

    def interrupt(self) -> None:
        """The user stopped the run (Ctrl-C)."""
        self.status = "interrupted"
        where = "" if self.depart_time is None else f" at station {self.station:.1f} m"
        self.reason = (f"interrupted by the user (Ctrl-C) {self.when()}{where}"
                       + (f" (before: {self.reason})" if self.reason else ""))

    def when(self) -> str:
        """The simulation time reached, in words."""
        if self.sumo_started or self.time > 0.0:
            return f"at t={self.time:.1f} s"
        return "before the simulation started"


    def finish(self, *, plot: bool) -> SimResult:
        # SUMO may be running without sumo_started set, when Ctrl-C came as it started
        if self.sumo is not None and (self.sumo_started or self.status == "interrupted"):
            t0 = time.perf_counter()
            _safe_close(self.sumo)
            self.sumo_seconds += time.perf_counter() - t0
            self.sumo_started = False
        self.wall_time = time.perf_counter() - self.wall_start
        driven = self._driven()
        metrics = self._metrics(driven)
        _write_csv(self.out / "trajectory.csv",
                   {k: v for k, v in driven.items() if k != "lane"})
        with (self.out / "metrics.json").open("w") as fh:
            json.dump(_jsonable(metrics), fh, indent=2, allow_nan=False)
        result = SimResult(self.status, self.reason, self.out, metrics, tuple(self.replans),
                           self.driven_before + self.route_edges, driven, tuple(self.plans))
        if plot:
            try:
                _plot(self, result)
            except Exception as err:
                log.warning("plots failed: %s", err)
        return result

    def _driven(self) -> dict[str, np.ndarray]:
        names = ("t", "x", "y", "heading", "speed", "station", "lateral", "lane", "sumo_x",
                 "sumo_y", "position_error", "clearance_obstacles", "clearance_vehicles",
                 "off_road", "speed_limited")
        cols: dict[str, np.ndarray] = {}
        for i, name in enumerate(names):
            vals = [r[i] for r in self.rows]
            cols[name] = np.array(vals, dtype=object if name == "lane" else float)
        dyn = dynamics(cols["t"], cols["x"], cols["y"], cols["speed"])
        cols.update(dyn)
        return cols

    def _metrics(self, d: dict[str, np.ndarray]) -> dict[str, Any]:
        sc = self.sc
        t = d["t"]
        xy = np.column_stack((d["x"], d["y"])) if len(t) else np.zeros((0, 2))
        dist = float(np.hypot(*np.diff(xy, axis=0).T).sum()) if len(t) > 1 else 0.0
        ego_coll = [c for c in self.sumo_collisions
                    if self.ego in (c["collider"], c["victim"])]
        plan_times = [r.planning_time for r in self.replans]
        off = d["off_road"].astype(bool) if len(t) else np.zeros(0, dtype=bool)
        travel = (t[-1] - self.depart_time) if (len(t) and self.depart_time is not None) else None
        return {
            "scenario": sc.name,
            "scenario_file": str(sc.path) if sc.path else None,
            "driver": self.driver,
            "status": self.status,
            "arrived": self.status == "arrived",
            "reason": self.reason,
            "seed": sc.sim.seed,
            "step_length": self.dt,
            "sim_time_end": self.time,
            "depart_time": self.depart_time,
            "travel_time": travel,
            "distance": dist,
            # the route from the ego's start: after a re-route, the edges driven before it
            # and the new route
            "route": list(self.driven_before + self.route_edges),
            "route_length": finite_or_none(self.route_length),
            "avoided_edges": sorted(self.avoid),
            "safety_margin": sc.roadmap.safety_margin,
            "min_clearance_obstacles": finite_or_none(
                float(d["clearance_obstacles"].min()) if len(t) else math.inf),
            "min_clearance_vehicles": finite_or_none(
                float(d["clearance_vehicles"].min()) if len(t) else math.inf),
            # our own check: the ego's rectangle overlaps another vehicle's rectangle
            "collisions": len(self.collisions),
            "collision_events": self.collisions[:100],
            # SUMO's reports: lane-based, so a remote-controlled ego passing a vehicle on the
            # same lane with a lateral offset is reported too; recorded, not counted
            "sumo_collision_reports": len(ego_coll),
            "sumo_collision_reports_list": ego_coll[:100],
            "sumo_collisions_others": len(self.sumo_collisions) - len(ego_coll),
            "time_off_road": float(off.sum() * self.dt),
            "off_road_tolerance": OFF_ROAD_TOLERANCE,
            "max_speed": float(d["speed"].max()) if len(t) else None,
            "max_lateral_acceleration": float(np.abs(d["a_lat"]).max()) if len(t) else None,
            "max_curvature": float(np.abs(d["curvature"]).max()) if len(t) else None,
            "lateral_acceleration_method": (
                "v^2 * kappa; kappa of the circle through the driven centre positions at "
                f"each sample and {CURVATURE_SPAN:g} m of path before and after it"),
            "max_longitudinal_acceleration": float(np.abs(d["a_lon"]).max()) if len(t) else None,
            "max_jerk": float(d["jerk"].max()) if len(t) else None,
            "replans": [r.__dict__ for r in self.replans],
            "replan_count": len(self.replans),
            "planning_time": summary_stats(plan_times),
            "position_error_max": (float(max(self.position_errors))
                                   if self.position_errors else None),
            # --time-to-teleport -1: SUMO teleports nobody, so these stay 0 unless the
            # option is changed; a stuck SUMO driver shows as status "timeout" instead
            "teleports": self.teleports,
            "ego_teleports": len(self.ego_teleports),
            # wall time [s] of the run: inside SUMO (start, steps, moveToXY, subscription
            # reads, close), in the planner (levels 1 to 3 at each replan) and in the loop
            # itself (the rest: reading the network, observation, safety checks, speed
            # control)
            "wall_time": self.wall_time,
            "wall_time_sumo": self.sumo_seconds,
            "wall_time_planner": self.plan_seconds,
            "wall_time_loop": max(self.wall_time - self.sumo_seconds - self.plan_seconds, 0.0),
            "safety_check_time": self.check_seconds,
        }


# ---- helpers ------------------------------------------------------------------------------

@dataclass(frozen=True)
class _Cut:
    """The drivable start of a trajectory whose end came too near an obstacle."""

    s: FloatArray
    x: FloatArray
    y: FloatArray
    heading: FloatArray
    speed: FloatArray


def _jsonable(value: Any) -> Any:
    """Plain JSON values: non-finite floats become ``None``, numpy scalars Python ones."""
    if isinstance(value, dict):
        return {str(k): _jsonable(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_jsonable(v) for v in value]
    if isinstance(value, np.generic):
        value = value.item()
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


def _locate(u: float, s: list[float]) -> tuple[int, float]:
    """Segment ``j`` and fraction ``f`` of ``u`` on increasing stations ``s`` (clamped to the
    ends, as :func:`numpy.interp`)."""
    n = len(s)
    if n < 2 or u <= s[0]:
        return 0, 0.0
    if u >= s[-1]:
        return max(n - 2, 0), 1.0 if n >= 2 else 0.0
    j = min(bisect.bisect_right(s, u) - 1, n - 2)
    span = s[j + 1] - s[j]
    return j, (u - s[j]) / span if span > 0 else 0.0


def _interp(u: float, s: list[float], v: list[float]) -> float:
    """``numpy.interp(u, s, v)`` for one value on plain lists."""
    j, f = _locate(u, s)
    if len(s) < 2:
        return v[0]
    return v[j] + f * (v[j + 1] - v[j])


def _lane_index(lane_id: str) -> int:
    try:
        return int(lane_id.rsplit("_", 1)[1])
    except (IndexError, ValueError):
        return 0


def _check_xml(path: Path) -> None:
    try:
        ET.parse(path)
    except ET.ParseError as err:
        raise SimulationError(f"SUMO input file {path} is not well-formed XML: {err}") from err


def _sumo_message(err: BaseException) -> str:
    msg = getattr(err, "message", None)
    if isinstance(msg, str) and msg:
        return msg
    text = str(err)
    if text.startswith("<libsumo"):
        return type(err).__name__
    return text


def _check_display() -> None:
    """Fail at once where ``sumo-gui`` has no display to open (Linux and other X11/Wayland
    systems without ``DISPLAY`` or ``WAYLAND_DISPLAY``): traci would otherwise retry its
    connection for a minute while sumo-gui fails to open its window."""
    if sys.platform.startswith(("win", "darwin")):
        return
    if not (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")):
        raise SimulationError("gui=True (--gui) needs a display to show sumo-gui on, and "
                              "neither DISPLAY nor WAYLAND_DISPLAY is set; run without the "
                              "GUI (the outputs are the same) or on a desktop session")


def _safe_close(sumo_mod: Any) -> None:
    with contextlib.suppress(Exception):
        sumo_mod.close()


def _safe_remove(sumo_mod: Any, vid: str) -> None:
    with contextlib.suppress(Exception):
        sumo_mod.vehicle.remove(vid)


def _tail(path: Path, n: int = 3) -> str:
    try:
        lines = [ln.strip() for ln in path.read_text().splitlines() if ln.strip()]
    except OSError:
        return ""
    return " | ".join(lines[-n:])


@contextlib.contextmanager
def _run_log(path: Path) -> Any:
    """Send the package's log records (warnings and up) to ``path`` while a run lasts.

    With a handler on the package's logger, Python's last-resort handler no longer prints
    them on the console; records still propagate to any handlers the application set up.
    """
    handler = logging.FileHandler(path, mode="w", delay=True)
    handler.setLevel(logging.WARNING)
    handler.setFormatter(logging.Formatter("%(levelname)s %(name)s: %(message)s"))
    pkg = logging.getLogger("splineplan")
    pkg.addHandler(handler)
    try:
        yield
    finally:
        pkg.removeHandler(handler)
        handler.close()


def _want_progress(progress: bool | None) -> bool:
    if progress is not None:
        return progress
    return bool(getattr(sys.stderr, "isatty", lambda: False)())


def _progress_bar(total: float, name: str) -> Any:
    from tqdm import tqdm

    return tqdm(total=total, unit="s", desc=name, file=sys.stderr, leave=False,
                bar_format="{desc}: {percentage:3.0f}%|{bar}| {n:.0f}/{total:.0f} s sim "
                           "[{elapsed}<{remaining}]")


def _write_csv(path: Path, cols: dict[str, np.ndarray]) -> None:
    names = list(cols)
    n = len(cols[names[0]]) if names else 0
    with path.open("w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(names)
        for i in range(n):
            row = []
            for name in names:
                v = cols[name][i]
                row.append(v if isinstance(v, str) else f"{float(v):.10g}")
            w.writerow(row)


#: At most this many plans are drawn with ``plot=True``.
MAX_PLAN_PICTURES = 40


def _plot(run: _Run, result: SimResult) -> None:
    from splineplan import plot as splot

    splot.plot_run_folder(run.out)
    folder = run.out / "plans"
    folder.mkdir(exist_ok=True)
    ego = run.sc.ego
    for i, (t, roadmaps, traj, window, obstacles) in enumerate(
            result.plans[:MAX_PLAN_PICTURES]):
        splot.plot_trajectory(traj, window, obstacles, roadmaps,
                              path=folder / f"plan_{i:03d}_t{t:07.1f}.png",
                              footprint_every=10.0, vehicle_size=(ego.length, ego.width),
                              s_max=run.sc.trajectory.s_max,
                              title=f"{run.sc.name}: plan {i} at t = {t:.1f} s")
