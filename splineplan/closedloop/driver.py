"""One planned vehicle of the closed loop: its route, plan, motion state and record.

A :class:`Driver` never calls SUMO. Each step the run gives it what SUMO says about it
(:class:`~splineplan.sumo.world.VehicleState`) and the vehicles around it
(:meth:`Driver.perceive`), lets it replan (:meth:`Driver.maybe_replan`), and asks where SUMO
is to put it next (:meth:`Driver.command`, with the traffic lights and junction foes ahead).
Its perception, replanning and control are the mixins of :mod:`.perception`,
:mod:`.replan` and :mod:`.control`.
"""

from __future__ import annotations

import copy
import logging
import math
from collections.abc import Mapping
from pathlib import Path
from typing import Any, Literal, get_args

import numpy as np

from splineplan.closedloop.bodies import BodyPath
from splineplan.closedloop.control import Control
from splineplan.closedloop.lanes import LaneChange
from splineplan.closedloop.perception import STANDING_SPEED
from splineplan.closedloop.replan import Replan, Replanning
from splineplan.corridor import Corridor
from splineplan.errors import ScenarioError, VehicleClassError
from splineplan.geometry import FloatArray, heading_from_sumo_angle
from splineplan.obstacles import Obstacles
from splineplan.scenario import Scenario
from splineplan.sumo.world import LanePlace, VehicleState
from splineplan.traffic import NO_OTHERS, Others, RoadCheck

#: Who drives the ego: ``planner`` (splineplan, through ``moveToXY``), ``sumo`` (SUMO's
#: default car-following and lane-change models, lane-based: SUMO started without
#: ``--lateral-resolution``) or ``sublane`` (SUMO's sublane model, which can shift within a
#: lane to pass an obstacle: ``--lateral-resolution`` :data:`LATERAL_RESOLUTION`).
DriverKind = Literal["planner", "sumo", "sublane"]
DRIVERS: tuple[str, ...] = get_args(DriverKind)
#: A vehicle standing (slower than :data:`STANDING_SPEED` [m/s]) this long [s] is stuck:
#: its metrics and the log say why (what its speed control waits for).
STUCK_AFTER = 30.0

log = logging.getLogger(__name__)


class Driver(Replanning, Control):
    """One planned vehicle (or one driven by SUMO's models, as a baseline).

    ``sc`` is the scenario with this vehicle as its ``ego``; ``net`` the road network.
    """

    def __init__(self, scenario: Scenario, net: Any, *, kind: DriverKind = "planner",
                 out: Path | None = None) -> None:
        self.sc = scenario
        self.net = net
        self.kind = kind
        self.out = out
        self.ego = scenario.ego.id
        self.dt = scenario.sim.step_length
        self.time = 0.0
        self.status = "pending"
        self.reason = ""
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
        self.route_request: list[str] | None = None  # a new route for SUMO
        self.corridor: Corridor | None = None
        self.in_sim = False
        self.depart_time: float | None = None
        self.polygons = Obstacles.empty()
        self.road: Any = None
        # motion state
        self.traj: Any = None
        self.path_s: FloatArray = np.zeros(0)
        self.u = 0.0  # station [m] along the current trajectory
        self.v = 0.0  # speed [m/s]
        self.pose = np.zeros(3)  # centre x, y, heading
        self.sumo_front = np.zeros(2)  # where SUMO has the front bumper [m]
        self.sumo_heading = 0.0
        self.planned_ids: frozenset[str] = frozenset()
        self.window_end = 0.0
        self.truncated = False
        self.stop_at: float | None = None  # station on the trajectory to stop before
        self.retry_at: float | None = None
        self.goal_station = math.nan
        self.last_lane = ""
        self.teleports: list[float] = []
        self.check_seconds = 0.0  # wall time [s] of the safety checks
        self.plan_seconds = 0.0  # wall time [s] of the planning calls
        self._obs_cache: dict[tuple[str, float, float], tuple[float, float, bool]] = {}
        self._body_paths: dict[tuple[str, str], tuple[BodyPath, int] | None] = {}
        # (place, length) -> predicted body or None, this step's (see Control._body_of)
        self._bodies_now: dict[tuple[LanePlace, float],
                               tuple[FloatArray, FloatArray, FloatArray] | None] = {}
        # long vehicle -> the path through its last junction, to the lane after it
        self._bodies_after: dict[str, tuple[BodyPath, int, str]] = {}
        self.lateral = 0.0  # the ego's lateral offset [m] on the route
        self.station = 0.0
        self.deviation = 0.0
        self.limited = 0
        self.traffic_after = 0.0  # no traffic replan before this time [s]
        self.trigger_after = 0.0  # no obstacle or traffic check before this time [s]
        self.horizon_after = 0.0  # no routine replan before this time [s]
        self.joined_at = None  # where the last plan went on from the one before [m]
        self.others = NO_OTHERS
        self.board: Mapping[str, Any] = {}  # the plans others published (the run's board)
        self.priority = 0  # lower plans first (the order of entering)
        self.publish = False  # whether it publishes its plans (several planned vehicles)
        self.keep_plans = True  # keep every plan for pictures (a single ego's run)
        self.keep_lane = False  # plan within its lane first (among SUMO's traffic)
        self.lane_change: LaneChange | None = None  # see Replanning._take
        self.keep_clear = False  # stop before a junction it could not leave
        self.published_plan: Any = None
        self.own_plan: Any = None  # its latest published plan (kept)
        self.waiting_for: tuple[str, ...] = ()
        self.plan_wait: float | None = None  # see Replanning._take
        self._stop_lines: list[tuple[float, str, str]] = []  # see Replanning._set_route
        self.stops_done: set[str] = set()
        self.stop_since: float | None = None
        self.trusted: dict[str, Any] = {}
        self.board_seen = 0
        self.wait_replan_at = 0.0
        self.go_at = 0.0  # when its plan has it move on, while it waits [s]
        self.conflicts: list[dict[str, Any]] = []
        self.why_slow = ""  # what holds the vehicle back (speed control), in words
        self.slowed_by: tuple[str, ...] = ()  # the vehicles that do (named in why_slow)
        # vehicle id -> until when [s] this one does not wait for its published plans
        # (released from a deadlock, see .cooperate.waits_in_cycle)
        self.released: dict[str, float] = {}
        self.held_by = ""  # the same where it held the last step's speed below the plan's
        self.stand_since: float | None = None
        self.stuck: list[dict[str, Any]] = []  # stands longer than STUCK_AFTER
        self._beside_at: tuple[float, float] | None = None
        self._cand_at: tuple[float, float] | None = None
        self._lane_of: tuple[str, int] = ("", 0)  # the last lane's id and index
        self._times_key: tuple[float, float] | None = None  # see Control._plan_times
        self._times: tuple[int, list[float], list[float]] = (0, [], [])
        self._ahead_box: tuple[list[float], ...] = ([], [], [], [])
        self._sample_step = 0.0
        self._cand_was: list[int] = []
        self._reach: dict[tuple[str, float], list[float]] = {}  # see Control._lane_reach
        self._bands: dict[tuple[str, float], Any] = {}  # see Control._lane_band
        self._turn_key: tuple[Corridor, float] | None = None
        self._turn_window: FloatArray = np.zeros(0)
        self._beside_was: tuple[np.ndarray, FloatArray] = (np.zeros(0, dtype=np.int64),
                                                           np.zeros((0, 2)))

    # -- setup ----------------------------------------------------------------------------
    def route_from_scenario(self) -> None:
        """Check the ego's start and goal against the network and plan its route (level 1)."""
        from splineplan.network import route_corridor
        from splineplan.route import forward_route

        sc, ego = self.sc, self.sc.ego
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
        route = forward_route(self.net, ego.start_edge, ego.goal_edge, vclass=ego.vclass,
                              start_pos=ego.start_pos, car=self.car,
                              avoid_limit_turns=True)
        goal_len = self.net.length_of(ego.goal_edge)
        if ego.goal_pos is not None and ego.goal_pos > goal_len:
            raise ScenarioError(f"{sc.name}: ego.goal_pos {ego.goal_pos} m is beyond the end of "
                                f"goal edge '{ego.goal_edge}' ({goal_len:.1f} m)")
        self._set_route(route_corridor(self.net, route, vclass=ego.vclass), route.edges)
        self.route_length = route.length

    def route_from_sumo(self) -> None:
        """Plan the route (level 1) from where SUMO inserted the vehicle to its goal."""
        from splineplan.network import route_corridor
        from splineplan.route import forward_route

        ego = self.sc.ego
        route = forward_route(self.net, ego.start_edge, ego.goal_edge, vclass=ego.vclass,
                              start_pos=ego.start_pos, car=self.car,
                              avoid_limit_turns=True)
        self._set_route(route_corridor(self.net, route, vclass=ego.vclass), route.edges)
        self.route_length = route.length

    def set_road(self, road: RoadCheck, polygons: Obstacles) -> None:
        """The road check (lanes and junction areas) and the obstacle polygons.

        The vehicle gets its own copy of the check, sharing the lanes: the check keeps the
        lane segments around where it last looked, and one check for vehicles all over the
        network would gather them again for each."""
        self.road = copy.copy(road)
        self.polygons = polygons

    def goal_arrival_pos(self) -> float:
        """Where [m] on the goal edge SUMO's own drivers end the trip."""
        ego = self.sc.ego
        goal_len = self.net.length_of(ego.goal_edge)
        return ego.goal_pos if ego.goal_pos is not None else max(
            goal_len - self.sc.sim.goal_margin, 0.0)

    # -- the loop's calls -------------------------------------------------------------------
    def enter(self, now: float, front: FloatArray, heading: float, speed: float = 0.0
              ) -> None:
        """SUMO has just inserted the vehicle, its front bumper at ``front`` [m], at
        ``speed`` [m/s] (at most the planner's ``s_max``)."""
        self.in_sim = True
        self.status = "running"
        self.depart_time = now
        self.time = now
        if self.kind != "planner":
            return
        self.sumo_front, self.sumo_heading = front, heading
        self._set_pose_from_sumo()
        self.v = min(speed, float(self.sc.trajectory.s_max)) if speed > 0.0 else 0.0

    def perceive(self, now: float, st: VehicleState, others: Others) -> None:
        """What SUMO says after a step: check where it put the vehicle, the safety checks,
        the record's row, arrival."""
        import time as _time

        ego = self.sc.ego
        self.time = now
        fx, fy = st.front
        lane = st.lane
        half = ego.length / 2.0
        if self.kind == "planner":
            x, y, h = (float(v) for v in self.pose)
            pos_err = math.hypot(fx - (x + half * math.cos(h)), fy - (y + half * math.sin(h)))
            self.position_errors.append(pos_err)
            self.deviation = pos_err
            self.sumo_front = np.array([fx, fy], dtype=float)
            self.sumo_heading = float(heading_from_sumo_angle(st.angle))
        else:
            h = float(heading_from_sumo_angle(st.angle))
            x, y = fx - half * math.cos(h), fy - half * math.sin(h)
            self.pose = np.array([x, y, h])
            self.v = float(st.speed)
            pos_err = math.nan
        self.last_lane = lane
        self.others = others
        t0 = _time.perf_counter()
        clear_obs, clear_veh, off_road = self._safety(x, y, h)
        self.check_seconds += _time.perf_counter() - t0
        sl = self._project(np.array([x, y]))
        self.station = float(sl[0])
        self.lateral = float(sl[1])
        self.rows.append((self.time, x, y, h, self.v, self.station, float(sl[1]), lane,
                          float(fx), float(fy), pos_err, clear_obs, clear_veh, int(off_road),
                          self.limited, self.held_by))
        self._watch_standing(now)
        if self.station >= self.goal_station:
            self.status = "arrived"
            self.reason = (f"front bumper reached the goal on edge '{ego.goal_edge}' at "
                           f"t={self.time:.1f} s")
            self.in_sim = False

    def _watch_standing(self, now: float) -> None:
        """Deadlock watch: a vehicle standing for :data:`STUCK_AFTER` seconds says why
        (its ``stuck`` record and the log), once per stand."""
        if self.v >= STANDING_SPEED:
            if self.stuck and self.stuck[-1]["until"] is None:
                self.stuck[-1]["until"] = now
            self.stand_since = None
            return
        if self.stand_since is None:
            self.stand_since = now
            return
        if now - self.stand_since < STUCK_AFTER or (
                self.stuck and self.stuck[-1]["until"] is None):
            return
        why = self.why_slow or ("at the end of its plan, waiting for a new one"
                                if self.kind == "planner" else "SUMO's driver stands")
        self.stuck.append({"since": self.stand_since, "until": None, "lane": self.last_lane,
                           "station": self.station, "why": why})
        log.warning("t=%.1f vehicle '%s' has not moved for %.0f s on lane '%s': %s", now,
                    self.ego, now - self.stand_since, self.last_lane, why)

    def release(self, vid: str, until: float, cycle: list[str]) -> None:
        """Stop waiting for the published plans of vehicle ``vid`` until ``until`` [s],
        and plan again: this one and ``vid`` stand in a ``cycle`` of waits (its ids in
        order, each held by the next)."""
        self.released[vid] = until
        chain = " -> ".join(f"'{v}'" for v in [*cycle, cycle[0]])
        log.info("t=%.1f vehicle '%s' stops waiting for the plan of '%s': they stand in a "
                 "cycle of waits (%s)", self.time, self.ego, vid, chain)
        self._replan("deadlock", f"stops waiting for the plan of '{vid}' (waits: {chain})")

    def maybe_replan(self) -> None:
        """Plan at the start, then whenever needed (:meth:`_maybe_replan`)."""
        if not self.replans:
            self._replan("start", "")
        else:
            self._maybe_replan()

    def arrived_by_sumo(self, now: float) -> None:
        """SUMO's own driver ended the trip at its route's end."""
        self.status = "arrived"
        self.reason = f"SUMO's driver reached the end of its route at t={now:.1f} s"
        self.in_sim = False

    # -- end ----------------------------------------------------------------------------------
    def timeout_reason(self, now: float, duration: float) -> str:
        """Why the vehicle did not arrive within ``duration`` [s]."""
        text = f"duration {duration:g} s reached before the ego arrived"
        if self.depart_time is None:
            return text + " (the ego was never inserted)"
        # how long the ego has been standing: SUMO's drivers wait behind a blockage forever
        # (--time-to-teleport -1)
        moving = [r[0] for r in self.rows if r[4] > 0.1]
        since = moving[-1] if moving else self.depart_time
        if now - since >= 5.0:
            text += (f" (standing still for the last {now - since:.0f} s on lane "
                     f"'{self.last_lane}')")
        if self.reason:
            text += f" ({self.reason})"
        return text

    def fail(self, reason: str) -> None:
        """The run could not carry on; ``reason`` says why."""
        self.status = "failed"
        self.reason = reason

    def interrupt(self, when: str) -> None:
        """The user stopped the run (Ctrl-C) ``when`` (in words)."""
        self.status = "interrupted"
        where = "" if self.depart_time is None else f" at station {self.station:.1f} m"
        self.reason = (f"interrupted by the user (Ctrl-C) {when}{where}"
                       + (f" (before: {self.reason})" if self.reason else ""))
