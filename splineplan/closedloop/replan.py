"""Replanning of one planned vehicle: when to plan again, levels 2 and 3 on the window
ahead (among stopped obstacles and the traffic beside), and level 1 again with a blocked
edge avoided. No SUMO calls: a new route is left in ``route_request`` for the run.
"""

from __future__ import annotations

import itertools
import logging
import math
import time
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from splineplan.closedloop.cooperate import WAIT_REPLAN, keeps_clear_of, plans_before
from splineplan.closedloop.lanes import (
    LaneChange,
    lane_band,
    lane_entry,
    onto_road,
    side_reach,
)
from splineplan.closedloop.perception import Perception
from splineplan.corridor import Corridor
from splineplan.errors import (
    GeometryError,
    NoRouteError,
    RoadBlockedError,
    SplineplanError,
    TrajectoryError,
)
from splineplan.geometry import FloatArray
from splineplan.network import Lane
from splineplan.obstacles import Obstacles
from splineplan.spacetime import MovingObstacle, published
from splineplan.traffic import probe_points
from splineplan.trajectory import TrajectoryParams

log = logging.getLogger(__name__)

#: Seconds between retries when no plan could be made.
_RETRY_AFTER = 1.0
#: Re-routes tried in one replan before giving up.
_MAX_REROUTES = 5
#: Spacing [m] of the path samples used to find vehicles in the ego's path.
_PATH_SPACING = 0.5
#: Straight extension [m] of the path beyond the trajectory's end, to see what is in the way.
_PATH_EXTENSION = 60.0
#: At most one ``traffic`` replan per this many seconds.
_TRAFFIC_REPLAN_EVERY = 0.5
#: While waiting for others' plans, a vehicle plans again (every ``WAIT_REPLAN``) from this
#: long [s] before its plan has it move on, not before: the plan's speed profile holds it
#: until then, and plans in between come out the same.
GO_EARLY = 0.5
#: A plan has the vehicle move on once it has gone this far [m].
_GO_MOVED = 0.5
#: A plan stands where its speed is at most this [m/s].
_STANDS = 0.05
#: A routine replan (the plan runs short) whose speed profile falls more than this [m/s]
#: below what braking at ``b_max`` from the vehicle's speed allows is put off while the
#: current plan reaches at least :data:`DEFER_REACH` of the replan distance ahead: a new
#: curve leaves the vehicle straight along its heading, so one made inside a bend must
#: turn harder soon after, and the vehicle would brake at its emergency rate along a kink.
#: It drives on along its plan instead and plans again every :data:`TRIGGER_PERIOD`. So is
#: one whose curve bends beyond the turning limit and beyond what is left of the current
#: plan. Not for a vehicle that keeps to its lane among SUMO's traffic: there the plans
#: put off cost arrivals (city, 25 % planned, seeds 1 and 3: 30 and 20 arrived in 300 s
#: against 46 and 28).
BRAKE_SLACK = 0.05
#: Least distance [m] from the vehicle, and from the current plan's end, of the point where
#: the last try of a routine replan that is still worse goes on from the current plan.
JOIN_AHEAD = 5.0
#: Share of ``sim.replan_distance`` that the current plan must still reach for a routine
#: replan to be put off (and never less than the distance to stop in).
DEFER_REACH = 0.5
#: Period [s] of the checks for new obstacles ahead and for traffic beside the ego coming
#: near the plan (a reaction time well below a driver's; the deviation and horizon checks,
#: and the ego's own safety checks, run every step).
TRIGGER_PERIOD = 0.3


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
        road closed), ``cooperation`` (again while waiting for another planned vehicle's
        published plan), ``retry`` (after a failed plan) or ``put off`` (a ``horizon``
        replan not taken, whose curve would make the vehicle brake harder than
        ``b_max`` (:data:`BRAKE_SLACK`) or bend beyond the turning limit and beyond
        what is left of the current plan).
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


class _PutOff(SplineplanError):
    """A routine replan worse than the current plan (:meth:`Replanning._worse`): not
    taken."""


def _sharper_bend(new: Any, current: Any, u: float, limit: float) -> str | None:
    """Why ``new`` is worse than the rest of ``current`` (a whole trajectory, never a
    truncated one: routine replans are not judged after one) from its station ``u`` [m] in
    curvature: it bends beyond ``limit`` [1/m] and beyond every bend left of ``current``;
    ``None`` if it does not."""
    k = np.abs(np.asarray(new.curvature, dtype=float))
    i = int(np.argmax(k))
    if k[i] <= limit * (1.0 + 1e-6):
        return None
    s = np.asarray(current.s, dtype=float)
    left = np.abs(np.asarray(current.curvature, dtype=float))[s >= u - 1e-9]
    if len(left) and k[i] <= float(left.max()) + 1e-6:
        return None
    return (f"put off: its curve bends at {k[i]:.3f} 1/m {float(new.s[i]):.1f} m ahead, "
            f"beyond the turning limit")


@dataclass(frozen=True)
class _Cut:
    """The drivable start of a trajectory whose end came too near an obstacle."""

    s: FloatArray
    x: FloatArray
    y: FloatArray
    heading: FloatArray
    speed: FloatArray
    curvature: FloatArray


class Replanning(Perception):
    """The replanning half of a :class:`~splineplan.closedloop.driver.Driver` (a mixin)."""

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
        # the junctions on the route: from an edge's end to the next edge's start [m]
        ends = np.asarray(corridor.edge_ends, dtype=float).tolist()
        self._junction_spans = ([(a, b) for a, b in zip(ends[:-1], self._edge_starts[1:],
                                                         strict=True) if b > a]
                                if len(ends) == len(self._edge_starts) else [])
        # those whose connections run on one junction lane each (no internal junction)
        self._one_lane_junctions = (
            {a for a, b, e, f in zip(ends[:-1], self._edge_starts[1:], edges[:-1], edges[1:],
                                      strict=True)
             if b > a and not any(c.internal_junction
                                  for c in self.net.connections_between(e, f))}
            if len(ends) == len(self._edge_starts) == len(edges) else set())
        # the stop lines on the route (stop signs, all-way stops): the edge's end, the edge
        # (a stop is done once per edge) and the kind (network.stop_kind)
        kinds = ([self.net.stop_kind(e, f, ego.vclass) for e, f in itertools.pairwise(edges)]
                 if len(ends) == len(edges) else [])
        self._stop_lines = [(a, e, k) for a, e, k in zip(ends[:-1], edges[:-1], kinds,
                                                         strict=False) if k]
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
            if self.board and self.time >= self.wait_replan_at:
                news = self._new_plans_near()
                if news:
                    self.wait_replan_at = self.time + WAIT_REPLAN
                    if self.waiting_for or not self._clear_of(news):
                        self._replan("cooperation", "new plan of " + ", ".join(
                            f"'{v.id}'" for v in news) + " near the path",
                                     obstacles=self._obstacles_ahead(ahead))
                        return
                    # its plan keeps clear of theirs: seen, nothing to plan again
                    self.board_seen = max(p.seq for p in self.board.values())
            if self.time >= self.traffic_after:
                near = self._traffic_conflict()
                if near is not None:
                    self.traffic_after = self.time + _TRAFFIC_REPLAN_EVERY
                    self._replan("traffic", f"vehicle '{near}' beside the ego comes near the "
                                            "planned path", obstacles=self._obstacles_ahead(ahead))
                    return
        if (self.waiting_for and self.time >= self.wait_replan_at
                and self.time >= self.go_at - GO_EARLY):
            self.wait_replan_at = self.time + WAIT_REPLAN
            self._replan("cooperation", "waiting for the plan of "
                         + ", ".join(f"'{v}'" for v in self.waiting_for),
                         obstacles=self._obstacles_ahead(ahead))
            return
        assert self.corridor is not None
        left = float(self.path_s[-1]) - self.u
        if (self.window_end < self.corridor.length - 1e-6 or self.truncated) and (
                left < sim.replan_distance) and self.time >= self.horizon_after:
            stop = 0.5 * self.v**2 / self.sc.trajectory.b_max
            routine = not (self.truncated or self.keep_lane)
            early = left > max(DEFER_REACH * sim.replan_distance, stop)
            self._replan("horizon", f"{left:.1f} m of the plan left",
                         obstacles=self._obstacles_ahead(ahead), put_off=routine and early,
                         join=routine and not early)

    def _set_pose_from_sumo(self) -> None:
        """The pose where SUMO has the vehicle (as last perceived)."""
        front, h = self.sumo_front, self.sumo_heading
        c = front - self.sc.ego.length / 2.0 * np.array([math.cos(h), math.sin(h)])
        self.pose = np.array([c[0], c[1], h])

    def _replan(self, reason: str, detail: str, *, obstacles: Obstacles | None = None,
                put_off: bool = False, join: bool = False) -> None:
        """Plan again (levels 2 and 3, level 1 where the road is found closed). With
        ``put_off``, a plan worse than the current one (:meth:`_worse`) is not taken: the
        vehicle keeps its plan and tries again after :data:`TRIGGER_PERIOD`. With
        ``join``, such a plan gives way to one that goes on from the current plan where
        that is not worse (:meth:`_continued`)."""
        t0 = time.perf_counter()
        obstacles = self._obstacles_ahead() if obstacles is None else obstacles
        ok, msg = self._plan(obstacles, put_off=put_off, join=join)
        if isinstance(msg, _PutOff):
            elapsed = time.perf_counter() - t0
            self.plan_seconds += elapsed
            self.horizon_after = self.time + TRIGGER_PERIOD - 0.5 * self.dt
            self.replans.append(Replan(self.time, "put off", elapsed, self.station, False,
                                       f"{detail}; {msg}"))
            return
        reroutes = 0
        while not ok and isinstance(msg, RoadBlockedError) and reroutes < _MAX_REROUTES:
            reroutes += 1
            done, why = self._reroute(msg)
            if not done:
                msg = why
                break
            obstacles = self._obstacles_ahead()
            ok, msg = self._plan(obstacles)  # on the new route: taken as it comes
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
            if self.joined_at is not None:
                detail += f"; on from the plan {self.joined_at:.1f} m ahead"
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

    def _level3(self) -> TrajectoryParams:
        """Level 3's parameters in the loop: the scenario's; for a vehicle that keeps to
        its lane among SUMO's traffic, without the easing of the bends that equation (3)
        leaves too sharp (``bend_rounds=0``): there eased plans measured worse (city,
        25 % planned, seeds 1-5: 25 overlapping pairs against 17) and took twice the
        planning time."""
        if self.keep_lane:
            return replace(self.sc.trajectory, bend_rounds=0)
        return self.sc.trajectory

    def _plan(self, obstacles: Obstacles, *, put_off: bool = False, join: bool = False
              ) -> tuple[bool, Any]:
        """Levels 2 and 3 on the window ahead. Returns (ok, error).

        Moving vehicles beside the ego (:meth:`_moving_obstacles`) are planned around too
        where that gives a trajectory that keeps the safety margin; otherwise the plan is
        made among the stopped obstacles alone and the moving vehicles are left to the
        time-gap speed control. A vehicle that keeps to its lane (``keep_lane``, among
        SUMO's traffic: :mod:`.lanes`) plans within its lane first, where the moving
        vehicles beside it are in other lanes and left to SUMO's drivers and the time gap.
        With ``put_off``, the first plan made that is worse than the current one
        (:meth:`_worse`) ends the search (a :class:`_PutOff` error); with ``join``, such a
        plan may go on from the current one instead.
        """
        if self.keep_lane:
            ok, err = self._plan_among(obstacles, None, in_lane=True, put_off=put_off,
                                       join=join)
            if ok or isinstance(err, _PutOff):
                return ok, err
            log.debug("t=%.1f no plan within the lane (%s): planning on the whole road",
                      self.time, err)
        moving = self._moving_obstacles()
        if len(moving):
            ok, err = self._plan_among(obstacles, moving, put_off=put_off, join=join)
            if ok or isinstance(err, _PutOff):
                return ok, err
            log.debug("t=%.1f no plan around the traffic beside the ego (%s): planning "
                      "among the stopped obstacles only", self.time, err)
        return self._plan_among(obstacles, None, put_off=put_off, join=join)

    def _plan_among(self, obstacles: Obstacles, moving: Obstacles | None, *,
                    in_lane: bool = False, put_off: bool = False, join: bool = False
                    ) -> tuple[bool, Any]:
        """Levels 2 and 3 among ``obstacles`` (and ``moving``, or ``in_lane``: within the
        vehicle's lane, :func:`.lanes.lane_band`; both strictly: any failure or a
        trajectory short of the margin is a refusal, never a truncated plan)."""
        sc, ego = self.sc, self.sc.ego
        assert self.corridor is not None
        self.joined_at = None
        everything = obstacles if moving is None else obstacles + moving
        try:
            roadmaps, traj, window, s1 = self._levels_2_3(obstacles, everything,
                                                          in_lane=in_lane)
        except RoadBlockedError as err:
            if moving is not None or in_lane:
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
        if len(bad) and (moving is not None or in_lane):
            return False, TrajectoryError("trajectory comes too near the traffic beside"
                                          if moving is not None else
                                          "trajectory within the lane comes too near an "
                                          "obstacle")
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
        why = self._worse(traj) if put_off or join else None
        if why is not None and put_off:
            return False, _PutOff(why)
        if why is not None and usable is None:
            # the last chance for a routine replan: go on along the current plan to where it
            # runs straightest, and on from there (as the corridor's segments join), where
            # that is no worse: no sharper bend, no harder braking
            joined = self._continued(obstacles, everything)
            if joined is not None and _rank(self._shortfall(joined[1])) <= _rank(
                    self._shortfall(traj)):
                roadmaps, traj, window, s1, self.joined_at = joined
        final = s1 >= self.corridor.length - 1e-6
        if self.board:
            traj, roadmaps, everything = self._among_plans(traj, roadmaps, window, everything,
                                                           final)
        self._take(traj, s1, usable=usable)
        if self.keep_plans:  # for the pictures of a single ego's run
            self.plans.append((self.time, roadmaps, traj, window, everything))
        if self.publish and hasattr(traj, "t"):
            self.published_plan = published(traj, id=self.ego, t0=self.time,
                                            length=ego.length, width=ego.width)
            self.own_plan = self.published_plan
        else:
            self.own_plan = None
        return True, None

    def _levels_2_3(self, obstacles: Obstacles, everything: Obstacles, *,
                    in_lane: bool = False,
                    start: tuple[FloatArray, float, float] | None = None
                    ) -> tuple[Any, Any, Corridor, float]:
        """Roadmaps, trajectory, window and the window's end station [m] of a plan among
        ``everything`` (the stopped ``obstacles`` and any moving ones) from the vehicle's
        pose, or from ``start`` (a pose ``(3,)`` on the current plan, its station [m] on
        the route and its speed [m/s])."""
        from splineplan.planner import plan_corridor

        sc, ego = self.sc, self.sc.ego
        assert self.corridor is not None
        station, pose, speed = ((self.station, self.pose, float(self.v)) if start is None
                                else (start[1], start[0], start[2]))
        # a vehicle whose centre lies behind its route's start (SUMO inserts it with its
        # front on a first edge shorter than itself; its station is then 0) plans on the
        # route extended back, from a car length behind it
        behind = 0.0
        if station <= 0.0:
            behind = max(-float(self.corridor.to_sl(pose[None, :2])[0, 0]), 0.0)
        back = behind + ego.length if behind > 0.0 else 0.0
        route = self.corridor.extend_back(back)
        s0 = max(station - ego.length, 0.0) - back
        s1 = station + sc.sim.lookahead
        if len(obstacles):  # reach past every obstacle seen, so a closed road shows at once
            far = float(self.corridor.to_sl(obstacles.vertices)[:, 0].max())
            s1 = max(s1, far + ego.length + 2.0 * sc.roadmap.d)
        s1 = min(s1, self.corridor.length)
        if s1 - s0 < 2.0 * sc.roadmap.d + ego.length:
            s0 = max(s1 - 2.0 * sc.roadmap.d - ego.length, -back)
        final = s1 >= self.corridor.length - 1e-6
        window = route.slice(s0 + back, s1 + back)
        if in_lane:
            width = self._lane_width()
            if width is None:
                raise TrajectoryError(f"no lanes known for edge '{self._edge_at(station)}'")
            window = lane_band(window, station - s0, self.lateral, lane_width=width,
                               half_width=ego.width / 2.0, **self._lane_links(window))
        if start is None:
            on = onto_road(window, (float(pose[0]), float(pose[1])))
            if on is not None:
                log.info("t=%.1f '%s' is off its corridor: planning from %.2f m away, on "
                         "it", self.time, self.ego, math.hypot(on[0] - pose[0], on[1] - pose[1]))
                self.pose = pose = np.array([on[0], on[1], pose[2]])
        # a vehicle that keeps to its lane among SUMO's traffic plans on its lanes,
        # not on the junctions' paving beside them: SUMO's drivers see a vehicle by
        # its lane (taking the paving, more planned vehicles ran into others in the
        # city's 25 % runs: 38 pairs on ten seeds against 29)
        roadmaps, traj = plan_corridor(
            window, everything, pose[:2], float(pose[2]), roadmap_params=sc.roadmap,
            params=self._level3(), start_speed=speed, end_speed=0.0 if final else None,
            paving=not self.keep_lane)
        return roadmaps, traj, window, s1

    def _worse(self, traj: Any) -> str | None:
        """Why a routine replan's ``traj`` is not taken, or ``None``: it would make the
        vehicle brake harder than ``b_max`` (:data:`BRAKE_SLACK`), or it bends beyond the
        turning limit and beyond what is left of the current plan."""
        bend, short, i = self._shortfall(traj)
        if short > BRAKE_SLACK:
            return (f"put off: its curve asks for {float(traj.speed[i]):.1f} m/s "
                    f"{float(traj.s[i]):.1f} m ahead, the vehicle drives at {self.v:.1f} m/s")
        return bend

    def _shortfall(self, traj: Any) -> tuple[str | None, float, int]:
        """How a replan's ``traj`` falls short of the current plan: why it bends beyond the
        turning limit and beyond what is left of the current plan (``None`` where it does
        not), the most [m/s] by which its speed falls below what braking at ``b_max`` from
        the vehicle's speed allows, and the sample where it does."""
        tp = self.sc.trajectory
        sv = np.asarray(traj.speed, dtype=float)
        brake = np.sqrt(np.maximum(self.v**2 - 2.0 * tp.b_max * np.asarray(traj.s, dtype=float),
                                   0.0))
        i = int(np.argmax(brake - sv))
        return (_sharper_bend(traj, self.traj, self.u, tp.kappa_max),
                float(brake[i] - sv[i]), i)

    def _continued(self, obstacles: Obstacles, everything: Obstacles
                   ) -> tuple[Any, Any, Corridor, float, float] | None:
        """A plan that drives the current one on to where it runs straightest ahead
        (:func:`~splineplan.planner.join_indices`, between :data:`JOIN_AHEAD` from the
        vehicle and as far before its end) and a new plan from there, and the join's
        distance [m] ahead; ``None`` where the current plan leaves no such stretch or no
        plan comes out."""
        from splineplan.planner import continued, join_indices

        tr, corridor = self.traj, self.corridor  # not truncated: a whole Trajectory
        assert corridor is not None
        s = np.asarray(tr.s, dtype=float)
        lo, hi = self.station + JOIN_AHEAD, self.station + (float(s[-1]) - self.u) - JOIN_AHEAD
        if hi <= lo:
            return None
        overlap = 2.0 * (hi - lo)
        try:
            j = int(join_indices(tr, corridor, lo - overlap / 4.0, overlap)[0])
        except TrajectoryError:
            return None
        first = max(int(np.searchsorted(s, self.u, side="right")) - 1, 0)
        if j <= first:
            return None
        start = (np.array([tr.x[j], tr.y[j], tr.heading[j]], dtype=float),
                 self.station + float(s[j]) - self.u, float(tr.speed[j]))
        try:
            roadmaps, after, window, s1 = self._levels_2_3(obstacles, everything, start=start)
        except SplineplanError:
            return None
        if np.any(np.asarray(after.clearance_obstacles) < self.sc.roadmap.safety_margin - 1e-6):
            return None
        final = s1 >= corridor.length - 1e-6
        return (roadmaps, continued(tr, first, j, after, self._level3(), float(self.v),
                                    0.0 if final else None), window, s1, float(s[j]) - self.u)

    def _lane_links(self, window: Corridor) -> dict[str, Any]:
        """:func:`.lanes.lane_band`'s ``leads_to`` over ``window``'s edges, by SUMO's
        connections, and in a junction its ``arrive``: the lane that SUMO's internal lane
        under the vehicle leads to."""
        net, cls, edges = self.net, self.sc.ego.vclass, window.edges

        def leads_to(k: int, lane: int) -> int | None:
            a, b = edges[k], edges[k + 1]
            if not a or not b:
                return None
            try:
                return net.lane_after(a, lane, b, cls)
            except (LookupError, SplineplanError):
                return None

        arrive = None
        if self.last_lane.startswith(":"):
            junction = self.corridor.junction_at(self.station) if self.corridor else None
            if junction is not None:
                try:
                    arrive = net.lane_after(junction[0], 0, junction[1], cls,
                                            via=self.last_lane)
                except (LookupError, SplineplanError):
                    arrive = None
        return {"leads_to": leads_to, "arrive": arrive}

    def _edge_lanes(self) -> tuple[Lane, ...]:
        """The lanes the vehicle may use of the route's edge where it is (none known:
        empty)."""
        try:
            return self.net.allowed_lanes(self._edge_at(self.station), self.sc.ego.vclass)
        except (LookupError, SplineplanError):
            return ()

    def _lane_width(self) -> float | None:
        """Width [m] of the lanes of the route's edge where the vehicle is (``None``: none
        known)."""
        lanes = self._edge_lanes()
        return float(min(ln.width for ln in lanes)) if lanes else None

    def _new_plans_near(self) -> list[MovingObstacle]:
        """The plans, published since this vehicle planned, of the vehicles before it that
        come near its current path (grown where they cross it, as it plans among them), by
        vehicle id."""
        if not len(self.path_xy):
            return []
        plans = plans_before(self.board, self.ego, self.priority, self.path_xy,
                             self.path_heading, self.time, pad=self.sc.sim.min_gap,
                             after=self.board_seen, released=self.released)
        return sorted(plans, key=lambda p: p.id)

    def _clear_of(self, plans: list[MovingObstacle]) -> bool:
        """Whether this vehicle's own latest plan keeps the safety margin from ``plans``
        (:func:`.cooperate.keeps_clear_of`); ``False`` where it has none."""
        mine = self.own_plan
        if mine is None:
            return False
        return keeps_clear_of(mine, plans, self.time, margin=self.sc.roadmap.safety_margin)

    def _among_plans(self, traj: Any, roadmaps: Any, window: Any, everything: Obstacles,
                     final: bool) -> tuple[Any, Any, Obstacles]:
        """The trajectory retimed among the published plans of the vehicles before this
        one (:mod:`.cooperate`); its path planned again around the first whose margin speed
        alone cannot keep."""
        from splineplan.planner import plan_corridor
        from splineplan.spacetime import retime

        sc, ego = self.sc, self.sc.ego
        self.board_seen = max((p.seq for p in self.board.values()), default=0)
        plans = plans_before(self.board, self.ego, self.priority, np.asarray(traj.xy),
                             np.asarray(traj.heading), self.time, pad=sc.sim.min_gap,
                             released=self.released)
        self.waiting_for = ()
        self.trusted = {}
        if not plans:
            return traj, roadmaps, everything
        end_speed = 0.0 if final else None
        kw = {"t0": self.time, "length": ego.length, "width": ego.width,
              "margin": sc.roadmap.safety_margin, "end_speed": end_speed}
        timed, sp = retime(traj, plans, sc.trajectory, **kw)
        if sp.conflict is not None:
            static = sp.conflict.as_static()
            # not where the vehicle is now: level 2 cannot start inside an obstacle
            x, y, h = (float(v) for v in self.pose)
            here = probe_points(x, y, math.cos(h), math.sin(h), ego.length / 2.0,
                                ego.width / 2.0)
            static = static.subset(~static.near_mask(np.asarray(here),
                                                     sc.roadmap.safety_margin + ego.width))
            try:
                roadmaps2, path2 = plan_corridor(
                    window, everything + static, self.pose[:2], float(self.pose[2]),
                    roadmap_params=sc.roadmap, params=self._level3(),
                    start_speed=float(self.v), end_speed=end_speed, paving=False)
            except SplineplanError as err:
                log.info("t=%.1f '%s': no path around the plan of '%s' (%s); yielding "
                         "by speed", self.time, self.ego, sp.conflict.obstacle.id, err)
            else:
                timed2, sp2 = retime(path2, plans, sc.trajectory, **kw)
                # keeps the margin, and keeps to the road no worse than the first path
                ok = bool(np.all(np.asarray(path2.clearance_obstacles)
                                 >= sc.roadmap.safety_margin - 1e-6)
                          and np.min(path2.clearance_road)
                          >= min(float(np.min(traj.clearance_road)), 0.0) - 1e-6)
                if ok and (sp2.conflict is None or sp2.conflict.t > sp.conflict.t):
                    log.info("t=%.1f '%s': path planned around the plan of '%s'",
                             self.time, self.ego, sp.conflict.obstacle.id)
                    timed, sp, roadmaps = timed2, sp2, roadmaps2
                    everything = everything + static
        self.waiting_for = sp.yielded
        self.go_at = _go_time(timed, self.time) if sp.yielded else self.time
        # the plans grown by the standstill distance where they cross (cooperate.py): the
        # control trusts them for vehicles that keep to them
        self.trusted = {p.id: p for p in plans}
        if sp.conflict is not None:
            self.conflicts.append({"time": self.time, "other": sp.conflict.obstacle.id,
                                   "at": sp.conflict.t, "station": sp.conflict.station})
        return timed, roadmaps, everything

    def _take(self, traj: Any, window_end: float, *, usable: float | None = None) -> None:
        s = np.asarray(traj.s, dtype=float)
        self.truncated = usable is not None
        if usable is not None:  # cut the trajectory: the ego stops at its new end
            cut = max(int(np.searchsorted(s, usable)), 2)
            traj = _Cut(s[:cut], np.asarray(traj.x)[:cut], np.asarray(traj.y)[:cut],
                        np.asarray(traj.heading)[:cut], np.asarray(traj.speed)[:cut],
                        np.asarray(traj.curvature)[:cut])
            s = traj.s
        n = max(math.ceil(s[-1] / _PATH_SPACING), 1) + 1
        u = np.linspace(0.0, s[-1], n)
        self.path_s = u
        self.path_xy = np.column_stack((np.interp(u, s, traj.x), np.interp(u, s, traj.y)))
        self.path_heading = np.interp(u, s, np.unwrap(traj.heading))
        self.path_speed = np.interp(u, s, traj.speed)
        # where the plan first stands, past its start and before its end (a wait for
        # another's plan)
        sp = np.asarray(traj.speed, dtype=float)
        stand = np.flatnonzero((sp <= _STANDS) & (s > s[0] + _GO_MOVED)
                               & (s < s[-1] - _GO_MOVED))
        self.plan_wait = float(s[stand[0]]) if len(stand) else None
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
        self._pl_np = (u, self.path_speed**2)
        self._times_key = None
        self._reach = {}  # the lane reaches of the new path (Control._lane_reach)
        self._pl = (u.tolist(), self.path_xy[:, 0].tolist(), self.path_xy[:, 1].tolist(),
                    self.path_heading.tolist(), (self.path_speed**2).tolist())
        self._corner_reach = _corner_reach(u, np.interp(u, s, traj.curvature),
                                           self.sc.trajectory).tolist()
        self._full = (self.full_s.tolist(), self.full_xy[:, 0].tolist(),
                      self.full_xy[:, 1].tolist(), self.full_heading.tolist())
        self.traj = traj
        self.u = 0.0
        # the trajectory starts at the ego's centre: keep u where the ego is
        d = np.hypot(*(self.path_xy - self.pose[:2]).T)
        self.u = float(u[int(np.argmin(d[: max(1, int(5.0 / _PATH_SPACING))]))])
        self.window_end = window_end
        self.lane_change = self._lane_change_ahead() if self.keep_lane else None

    def _lane_change_ahead(self) -> LaneChange | None:
        """Where the plan first reaches into another lane of the edge the vehicle is on
        (before the next junction; :func:`.lanes.lane_entry`); ``None`` if it keeps its
        lane (or reaches off the road) or is in a junction."""
        c = self.corridor
        lanes = self._edge_lanes()
        if c is None or not lanes:
            return None
        width = float(min(ln.width for ln in lanes))
        nxt = c.length
        for a, b in self._junction_spans:
            if b > self.station:
                if a <= self.station:
                    return None  # in a junction
                nxt = a
                break
        ahead = self.path_s >= self.u
        if not ahead.any():
            return None
        sl = np.asarray(c.to_sl(self.path_xy[ahead]))
        beyond = sl[:, 0] > nxt  # the samples up to the next junction
        sl = sl[:int(np.argmax(beyond))] if beyond.any() else sl
        st = np.clip(sl[:, 0], 0.0, c.length)
        right, _ = c.bounds_at(st)
        turn = self.path_heading[ahead][:len(sl)] - c.heading_at(st)
        ego = self.sc.ego
        found = lane_entry(sl[:, 1], right, side_reach(turn, ego.length / 2.0, ego.width / 2.0),
                           lane_width=width)
        if found is None or not 0 <= found[1] < len(lanes):
            return None
        k, lane, k_end = found
        s = self.path_s[ahead]
        return LaneChange(float(s[k]), lane, width,
                          f"{self._edge_at(self.station)}_{lanes[lane].index}",
                          float(s[k_end]) if k_end < len(sl) else math.inf)

    def _reroute(self, err: RoadBlockedError) -> tuple[bool, Any]:
        """Level 1 again with the blocked edge avoided. Returns (done, detail or error)."""
        from splineplan.network import route_corridor
        from splineplan.route import forward_route, route_length

        ego = self.sc.ego
        assert self.corridor is not None
        blocked = err.closed_edge
        here = self.corridor.edge_at(self.station)
        if blocked is None or blocked == here or blocked in self.avoid:
            return False, err
        assert here is not None
        start = float(self.corridor.edge_starts[self.corridor.edges.index(here)])
        ahead = self.corridor.edges[self.corridor.edges.index(here) + 1:]
        if (ahead and ahead[0] == blocked
                and self.station + ego.length / 2.0 > start + self.net.length_of(here)):
            # the front is in the junction towards the closed edge: SUMO has the vehicle on
            # the internal lane there and keeps it on its way (it refuses a route that
            # leaves it); drive on, to stop before the closure, and re-route from that edge
            stay = RoadBlockedError(f"{err}; the vehicle is already in the junction towards "
                                    f"edge '{blocked}'", station=err.station, edge=blocked)
            if hasattr(err, "station_on_route"):
                stay.station_on_route = err.station_on_route  # type: ignore[attr-defined]
            return False, stay
        self.avoid.add(blocked)
        pos = min(max(self.station - start + ego.length / 2.0, 0.0), self.net.length_of(here))
        try:
            route = forward_route(self.net, here, ego.goal_edge, vclass=ego.vclass,
                                  avoid=self.avoid, start_pos=pos, car=self.car,
                                  avoid_limit_turns=True)
            corridor = route_corridor(self.net, route, vclass=ego.vclass)
        except (NoRouteError, GeometryError) as e:
            return False, RoadBlockedError(f"{err}; no other route: {e}", station=err.station,
                                           edge=blocked)
        self.route_request = list(route.edges)  # the run gives it to SUMO
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


def _rank(shortfall: tuple[str | None, float, int]) -> tuple[bool, float]:
    """A replan's :meth:`Replanning._shortfall` to compare with another's: a bend beyond
    the limit first, then the braking beyond ``b_max`` (within :data:`BRAKE_SLACK`, none)."""
    bend, short, _ = shortfall
    return bend is not None, max(short - BRAKE_SLACK, 0.0)


def _corner_reach(s: FloatArray, curvature: FloatArray, tp: TrajectoryParams) -> FloatArray:
    """Per station of ``s`` [m] on a curve of ``curvature`` [1/m], the highest speed
    squared [m^2/s^2] from which braking at ``b_max`` keeps the cornering speed of
    equation (1) everywhere ahead (a huge number on a straight to the end)."""
    k = np.abs(np.asarray(curvature, dtype=float))
    corner2 = tp.mu * tp.g / np.maximum(k, 1e-12)
    ramp = 2.0 * tp.b_max * np.asarray(s, dtype=float)
    return np.asarray(np.minimum.accumulate((corner2 + ramp)[::-1])[::-1] - ramp)


def _go_time(traj: Any, now: float) -> float:
    """When [s] a plan made at ``now`` [s] has the vehicle move on: the time of its first
    sample :data:`_GO_MOVED` beyond its start (``now`` where it has none)."""
    tt = np.asarray(getattr(traj, "t", ()), dtype=float)
    if not len(tt):
        return now
    s = np.asarray(traj.s, dtype=float)
    moved = np.flatnonzero((s > s[0] + _GO_MOVED) & np.isfinite(tt))
    return now + float(tt[moved[0]]) if len(moved) else now
