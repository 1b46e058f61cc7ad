"""Control of one planned vehicle: the speed along its trajectory, capped to keep a time
gap to whatever is in its path, to stop at red lights and to give way at junctions as SUMO's
right of way says, and where SUMO is to put it next. No SUMO calls: the traffic lights and
junction foes come in as :class:`~splineplan.sumo.world.Signals`.
"""

from __future__ import annotations

import bisect
import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from splineplan import kernels
from splineplan.closedloop.bodies import (
    HORIZON,
    JUNCTION_ACCEL,
    JUNCTION_TOP,
    LONG_VEHICLE,
    MOVING,
    SLOW_HORIZON,
    BodyPath,
    bodies_along,
    body_path,
    meetings,
)
from splineplan.closedloop.cooperate import CROSSING
from splineplan.closedloop.lanes import LaneChange
from splineplan.closedloop.perception import Perception, _interp, _locate
from splineplan.errors import SplineplanError
from splineplan.geometry import FloatArray, wrap_angle
from splineplan.spacetime import box_gap
from splineplan.sumo.world import JunctionFoe, LanePlace, Signals
from splineplan.traffic import first_in_box_reach, safe_speed

#: A planned vehicle within this distance [m] of where its published plan puts it keeps to
#: its plan.
ON_PLAN = 1.5
#: Lateral slack [m] beyond the ego's half width within which a vehicle counts as in its path.
PATH_MARGIN = 0.15
#: Time [s] the ego keeps between its passage of a junction's conflict area and that of a
#: vehicle it must yield to; it stops this far [m] before the area to let that one pass.
YIELD_GAP = 1.5
YIELD_STOP = 1.0
#: The ego counts as in a conflict area from this far [m] before it (SUMO's distances are
#: to the area's first point, along the lanes).
YIELD_EDGE = 0.2
#: A vehicle in the path slower than this [m/s] stands in a queue: the ego keeps a junction
#: clear rather than stand inside it behind that vehicle (``keep_clear``).
QUEUE_SPEED = 1.0
#: A vehicle slower than this [m/s] stands: outside a conflict area it is waiting there,
#: not coming; in the lane a plan reaches into, the gap test asks whether the footprint
#: passes it (:data:`SIDE_CLEAR`), not for a time gap.
STOPPED_FOE_SPEED = 0.1
#: A lane change waits for a gap of this time [s] at the speed of the one behind (the
#: ego's ahead), at least :data:`CHANGE_MIN_GAP` [m], to the vehicles within
#: :data:`CHANGE_LOOK` [m] in the lane it changes into.
CHANGE_GAP_TIME = 1.0
CHANGE_MIN_GAP = 1.0
CHANGE_LOOK = 60.0
#: Room [m] the footprint keeps from a vehicle standing in the lane a plan reaches into,
#: over the lane change and at most :data:`SIDE_LOOK` [m] past its start, for the change
#: to need no gap (:meth:`Control._clears_standing`).
SIDE_CLEAR = 0.15
SIDE_LOOK = 10.0
#: A standing vehicle beside the body (in the path's reach before the front) is in the
#: way only ahead of the front where the footprint, moved on along the path to there,
#: keeps :data:`PATH_MARGIN` from it or comes no more than this [m] nearer to it than it
#: stands (a rear corner sweeps a little towards a vehicle turned towards it as it
#: passes), and never touches it (:meth:`Control._first_in_way`).
BESIDE_GIVE = 0.05
#: At a stop sign or an all-way stop the vehicle comes to a full stop with its front
#: :data:`STOP_LINE` [m] before the line (at most :data:`STOP_REACH` more) and stands this
#: long [s] (SUMO's ``jmStopSignWait`` at stop signs) before it goes, giving way as SUMO's
#: right of way says.
STOP_WAIT = 1.0
STOP_LINE = 1.0
STOP_REACH = 2.0
#: Acceleration [m/s²] at which a foe at an all-way stop may speed up (SUMO's default for
#: passenger cars).
FOE_ACCEL = 2.6
#: How hard [m/s²] SUMO's drivers brake for a vehicle in a junction (SUMO's default of a
#: bus; a car's is 4.5).
FOE_DECEL = 4.0
#: How far [m] beyond a junction's bounding circle a vehicle coming towards an all-way
#: stop counts as coming.
ALLWAY_REACH = 3.0
#: The closed loop's emergency deceleration, a multiple of the planner's ``b_max``: the
#: speed control brakes up to this hard when something comes into the ego's path (and SUMO's
#: vehicle type of the ego has it as its ``emergencyDecel``).
EMERGENCY_FACTOR = 2.0
#: A multiple of ``b_max`` at which a vehicle that gives way brakes, where it must, to
#: stand before a junction that its connection crosses on one junction lane rather than
#: inside it (:meth:`Control._before_junction`); below the emergency rate, at which SUMO
#: reports emergency braking.
HARD_BRAKING = 1.5
#: How far [m/s] a plan's speed may lie below what braking at ``b_max`` reaches for the
#: speed control to follow it at ``b_max`` (a new plan starts that little below where its
#: curve turns the wheels sooner than the last plan's did); a plan that drops further
#: slows for something, and is followed at the emergency rate.
PLAN_DROP = 0.25


@dataclass(frozen=True)
class Move:
    """Where SUMO is to put a planned vehicle: the route edge and lane index to map it
    onto, its centre ``(x, y)`` [m], heading [rad] and speed [m/s]."""

    edge: str
    lane: int
    centre: tuple[float, float]
    heading: float
    speed: float


class Control(Perception):
    """The control half of a :class:`~splineplan.closedloop.driver.Driver` (a mixin)."""

    def command(self, signals: Signals) -> Move:
        """Advance along the trajectory by one step: where SUMO is to put the vehicle.

        ``signals``: the traffic lights and junction foes ahead, read from SUMO just before.
        """
        self.signals = signals
        if self.traj is None:
            self._hold(f"no plan ({self.reason})" if self.reason else "no plan yet")
            self.held_by = self.why_slow
            return self._move()
        sc, ego = self.sc, self.sc.ego
        tp = sc.trajectory
        dt = self.dt
        # speed squared is linear in station under constant acceleration: interpolate it
        u_next = self.u + self.v * dt + 0.5 * tp.a_max * dt * dt
        ps, px, py, ph, pv2 = self._pl
        v_plan = math.sqrt(max(_interp(u_next, ps, pv2), 0.0))
        self._hold("")
        v_cap, limited = self._gap_speed()
        if self.stop_at is not None:
            v_cap = min(v_cap, math.sqrt(max(2.0 * tp.b_max * (self.stop_at - self.u), 0.0)))
            limited = 1
        end = float(self.path_s[-1])
        # stop at the trajectory's end unless a new plan comes first
        v_cap = min(v_cap, math.sqrt(max(2.0 * tp.b_max * (end - self.u), 0.0)))
        if self.stop_at is not None and not self.why_slow:
            self._hold(f"stopping before a blockage ({self.reason})")
        if v_plan < v_cap and self.waiting_for:
            self._hold(f"waiting for the published plan of {self._waited_for()}",
                       *self.waiting_for)
        # a plan a little below what braking at b_max reaches (a new plan whose curve asks
        # the steering to turn sooner) is followed braking at b_max while that keeps the
        # cornering speed of its curve ahead; a plan that slows for something, and what
        # comes into its way, at the emergency rate
        emergency = EMERGENCY_FACTOR * tp.b_max
        gentle = max(v_plan, self.v - tp.b_max * dt)
        if (gentle - v_plan > PLAN_DROP
                or gentle * gentle > _interp(u_next, ps, self._corner_reach)):
            gentle = max(v_plan, self.v - emergency * dt)
        v_new = min(gentle, max(v_cap, self.v - emergency * dt), self.v + tp.a_max * dt)
        v_new = max(v_new, 0.0)
        u = min(self.u + 0.5 * (self.v + v_new) * dt, end)
        if u >= end:
            v_new = 0.0
        self.u, self.v = u, v_new
        self.limited = limited
        self.held_by = ((self.why_slow or "coming to the end of its plan")
                        if v_cap < v_plan or self.waiting_for else "")
        j, f = _locate(u, ps)
        x, y = _on_curve(j, f, ps, px, py, ph)
        h = ph[j] + f * (ph[j + 1] - ph[j])
        self.pose = np.array([x, y, h])
        del ego
        return self._move(x, y, h)

    def _hold(self, why: str, *by: str) -> None:
        """Say what holds the vehicle back (``why_slow``) and which vehicles
        (``slowed_by``)."""
        self.why_slow, self.slowed_by = why, by

    def _waited_for(self) -> str:
        """The vehicles whose published plans this one waits for, quoted, for ``why_slow``."""
        return ", ".join(f"'{v}'" for v in self.waiting_for)

    def _cannot_stop(self, dist: float) -> bool:
        """Whether the vehicle can no longer stop within ``dist`` [m] even at its emergency
        braking."""
        return self.v * self.v > 2.0 * EMERGENCY_FACTOR * self.sc.trajectory.b_max * dist

    def _stand_within(self, dist: float, braking: float | None = None) -> float:
        """Speed cap [m/s] that stands within ``dist`` [m] ahead at the comfortable braking
        (or at ``braking`` [m/s^2]), one step early (at once where it is that near
        already)."""
        b = self.sc.trajectory.b_max if braking is None else braking
        return math.sqrt(max(2.0 * b * (dist - self.v * self.dt), 0.0))

    def _move(self, x: float | None = None, y: float | None = None, h: float | None = None
              ) -> Move:
        """Put the ego at centre ``x``, ``y`` [m], heading ``h`` [rad] (default: its pose)."""
        if x is None or y is None or h is None:
            x, y, h = (float(v) for v in self.pose)
        assert self.corridor is not None
        edge = self._edge_at(self.station)
        if self._lane_of[0] != self.last_lane:
            self._lane_of = (self.last_lane, _lane_index(self.last_lane))
        return Move(edge, self._lane_of[1], (x, y), h, self.v)

    def _gap_speed(self) -> tuple[float, int]:
        """Speed cap [m/s] to keep the time gap to whatever is in the path, and red lights.

        A vehicle is in the path where its footprint comes within the ego's half width
        plus :data:`PATH_MARGIN` of a path sample ahead of the ego (the trajectory and its
        straight extension), or beside the body where moving on brings it nearer
        (:meth:`_first_in_way`); the gap is to the first such sample. Only the samples
        within the vehicle's bounding circle plus that reach can be in reach: a vehicle whose
        circle misses the bounding box of the samples ahead is skipped, and the first
        sample in each other one's circle is found for all of them at once
        (:func:`~splineplan.kernels.first_in_circles`); the samples after it, by
        :func:`~splineplan.traffic.first_in_box_reach`.
        """
        sc, ego, tp = self.sc, self.sc.ego, self.sc.trajectory
        sim = sc.sim
        cap = math.inf
        gap_to = -1  # the vehicle (in self.others) whose gap caps the speed
        stop_front: float | None = None  # station on the path [m] the front stops at
        o = self.others
        reach = ego.width / 2.0 + min(PATH_MARGIN, 0.5 * sc.roadmap.safety_margin)
        if o.n:
            full_s, _, _, full_h = self._full
            i0 = bisect.bisect_left(self._pl[0], self.u)  # first sample ahead
            cand = []  # (first sample in the circle, vehicle, centre x, y, circle's radius)
            if i0 < len(full_s):
                box = np.array([b[i0] for b in self._ahead_box])
                orad = o.radius + reach
                # the first sample ahead in each one's circle, all at once
                first = kernels.first_in_circles(self.full_xy, i0, box, o.cx, o.cy, orad)
                for j in np.flatnonzero(first >= 0).tolist():
                    cand.append((int(first[j]), j, float(o.cx[j]), float(o.cy[j]),
                                 float(orad[j])))
            cand.sort()
            front = self.u + ego.length / 2.0
            i_front = bisect.bisect_left(full_s, front)  # the first sample at its front
            base = front + sim.min_gap
            for lo, j, cx, cy, r in cand:
                # the gap is at least up to the first sample in reach of the bounding
                # circle, and a leader's speed is at least 0: nothing after can go lower
                if safe_speed(full_s[lo] - base, 0.0, tp.b_max, sim.time_gap) >= cap:
                    break
                if self.trusted and o.ids[j] in self.trusted and self._keeps_to_plan(
                        j, full_h[lo]):
                    continue  # crossing as it published: the plan yields to it
                first = self._first_in_way(j, lo, (cx, cy, r), reach, i0, i_front)
                if first < 0:
                    continue
                gap = full_s[first] - base
                rel = math.cos(float(o.head[j]) - full_h[first])
                v_l = max(float(o.speed[j]) * rel, 0.0)
                c = safe_speed(gap, v_l, tp.b_max, sim.time_gap)
                if c < cap:
                    cap, gap_to = c, j
                    # where its front will stand behind a vehicle that (nearly) stands
                    stop_front = (full_s[first] - sim.min_gap if v_l < QUEUE_SPEED
                                  else None)
        if gap_to >= 0:
            self._hold(f"keeping its gap to vehicle '{o.ids[gap_to]}' ahead", o.ids[gap_to])
            if self.keep_clear and stop_front is not None:
                clear = self._keep_clear_speed(stop_front)
                if clear < cap:
                    cap = clear
                    self._hold(f"keeping the junction clear: vehicle '{o.ids[gap_to]}' "
                               "stands beyond it", o.ids[gap_to])
            if stop_front is not None:
                # not across a lane line behind a queue: before the lane change instead
                stand = stop_front - ego.length / 2.0 - self.u
                before = self._before_change(stand)
                if before < stand and self._stand_within(before) < cap:
                    cap = self._stand_within(before)
                    self._hold(f"waiting before its lane change: vehicle "
                               f"'{o.ids[gap_to]}' stands beyond it", o.ids[gap_to])
        if self.keep_clear and self.waiting_for and self.plan_wait is not None:
            # its plan waits for another's inside a junction: wait before it instead
            clear = self._keep_clear_speed(self.plan_wait + ego.length / 2.0)
            if clear < cap:
                cap = clear
                self._hold("keeping the junction clear while it waits for the published "
                           f"plan of {self._waited_for()}", *self.waiting_for)
        red = self._red_light_speed()
        if red < cap:
            cap = red
            self._hold("stopping at a red light")
        stop = self._stop_sign_speed()
        if stop < cap:
            cap = stop
            self._hold("stopping at a stop sign")
        # (why_slow set by each of these where it caps the speed)
        cap = min(cap, self._allway_speed(cap))
        cap = min(cap, self._only_below(self._yield_speed, cap))
        cap = min(cap, self._body_speed(cap))
        cap = min(cap, self._only_below(self._change_speed, cap))
        return cap, int(math.isfinite(cap))

    def _first_in_way(self, j: int, lo: int, circle: tuple[float, float, float],
                      reach: float, i0: int, i_front: int) -> int:
        """The first path sample from ``lo`` on within ``reach`` [m] of the body of
        vehicle ``j`` of ``others`` (-1 if none), whose bounding circle (centre x, y and
        radius plus ``reach`` [m]) it is in. One found before the ego's front (sample
        ``i_front``; the first ahead of its centre is ``i0``) is beside its body: where it
        stands (slower than :data:`STOPPED_FOE_SPEED`; one that moves may move in) and the
        footprint moved on to its front keeps :data:`PATH_MARGIN` from it or comes at most
        :data:`BESIDE_GIVE` nearer to it than it stands (:meth:`_keeps_off`), only ahead
        of the front is it in the way. Two planned cars side by side, each in the other's
        reach, waited for each other for good where the one ahead could drive on past."""
        _, full_x, full_y, _ = self._full
        o = self.others
        around = (*circle, self._sample_step)
        body = (float(o.cos[j]), float(o.sin[j]), 0.5 * float(o.length[j]),
                0.5 * float(o.width[j]))
        first = first_in_box_reach(lo, around, body, full_x, full_y, reach)
        if 0 <= first < i_front and o.speed[j] < STOPPED_FOE_SPEED and self._keeps_off(
                j, self.full_xy[i0:i_front + 1], self.full_heading[i0:i_front + 1],
                PATH_MARGIN, BESIDE_GIVE):
            first = first_in_box_reach(i_front, around, body, full_x, full_y, reach)
        return first

    def _only_below(self, rule: Callable[[], float], cap: float) -> float:
        """The speed cap [m/s] of ``rule``; what it says holds the vehicle back is kept
        only where that cap is below ``cap`` (the other rules')."""
        held = (self.why_slow, self.slowed_by)
        c = rule()
        if c >= cap:
            self.why_slow, self.slowed_by = held
        return c

    def _keep_clear_speed(self, stop_front: float) -> float:
        """Speed cap [m/s] that keeps a junction clear, as SUMO's drivers do: where the
        vehicle would come to stand inside the next junction on its route (its front at
        ``stop_front``, a station on its path, behind a vehicle that stands beyond, or
        where its plan waits for another's), it stops :data:`YIELD_STOP` before the
        junction instead, if it still can at its emergency braking; once inside (by the
        route's stations or on SUMO's junction lanes), it goes on."""
        ego = self.sc.ego
        if self.last_lane.startswith(":"):
            return math.inf  # SUMO has it in a junction already
        front = self.station + ego.length / 2.0
        stop = self.station + (stop_front - self.u)  # on the route
        for j_in, j_out in self._junction_spans:
            if j_in < front:
                continue  # passed, or in it
            if stop <= j_in or stop - ego.length >= j_out:
                break  # stands before the junction, or behind it
            if self._cannot_stop(j_in - front):
                break  # cannot stop before it
            return self._stand_within(j_in - front - YIELD_STOP)
        return math.inf

    def _keeps_to_plan(self, j: int, path_heading: float) -> bool:
        """Whether vehicle ``j`` (of ``self.others``), whose published plan the current
        plan was timed among (:mod:`.cooperate`), crosses the path and is where that plan
        says (within :data:`ON_PLAN`): then the plan's timing keeps the margin from it,
        and the time gap, which would take a crossing vehicle for one standing in the
        path, does not apply. One slower than :data:`QUEUE_SPEED` is not trusted: its
        control may hold it (giving way, in a queue) where its plan has it move on."""
        o = self.others
        turn = abs(math.remainder(float(o.head[j]) - path_heading, 2.0 * math.pi))
        if turn <= CROSSING or float(o.speed[j]) < QUEUE_SPEED:
            return False
        xy, _, there = self.trusted[o.ids[j]].at([self.time])
        return bool(there[0]) and math.hypot(float(xy[0, 0]) - float(o.cx[j]),
                                             float(xy[0, 1]) - float(o.cy[j])) <= ON_PLAN

    def _red_light_speed(self) -> float:
        tp = self.sc.trajectory
        tls = self.signals.lights
        if tls is None:
            return math.inf
        for _, _, dist, state in tls:
            if dist > self.sc.sim.lookahead:
                break
            if state in "rRyYu":
                need = self.v * self.v / (2.0 * tp.b_max)
                if state in "yY" and dist < need:
                    return math.inf  # cannot stop comfortably: go
                stand = self._before_change(dist - 1.0)
                return math.sqrt(max(2.0 * tp.b_max * stand, 0.0))
            break
        return math.inf

    def _stop_sign_speed(self) -> float:
        """Speed cap [m/s] that stops at the next stop sign or all-way stop on the route
        (:meth:`~splineplan.network.RoadNetwork.stop_kind`), as SUMO's drivers do: the
        front :data:`STOP_LINE` before the line, standing there :data:`STOP_WAIT`; then
        that stop is done. A vehicle that cannot stop before the line at its emergency
        braking goes on."""
        if not self._stop_lines or self.last_lane.startswith(":"):
            return math.inf
        front = self.station + self.sc.ego.length / 2.0
        for line, edge, _ in self._stop_lines:
            if edge in self.stops_done or line < front:
                continue  # done, or passed
            room = line - front - STOP_LINE
            if room > self.sc.sim.lookahead:
                break
            if self.v < STOPPED_FOE_SPEED and room <= STOP_REACH:
                if self.stop_since is None:
                    self.stop_since = self.time
                if self.time - self.stop_since >= STOP_WAIT - 1e-9:
                    self.stops_done.add(edge)
                    self.stop_since = None
                    continue
                return 0.0
            self.stop_since = None
            if self._cannot_stop(line - front):
                return math.inf  # cannot stop before it
            return self._stand_within(room)
        return math.inf

    def _yield_speed(self) -> float:
        """Speed cap [m/s] that gives way at junctions, as SUMO's right of way says.

        For each vehicle that the ego must yield to on its way through the next junctions
        (``getJunctionFoes``: ``egoResponse``) and that has not cleared the conflict area,
        the times it occupies that area (at its speed) and the times the ego would (along
        its plan, accelerating from its speed) are compared; where they come within
        :data:`YIELD_GAP` of each other, the ego stops :data:`YIELD_STOP` before the area,
        if it still can at its braking limit (:meth:`_stop_short`): before SUMO's conflict
        area, and before its footprint reaches the foe's body driving along its lane
        (:meth:`_lane_reach`; SUMO measures along the lanes' centre lines, and a turning
        car's front corner is in the foe's way earlier). Once it cannot stop before them,
        or its footprint is in the foe's way already (:meth:`_in_lane_way`), it goes on: a
        car that stops inside a crossing blocks it. Where the foe is SUMO's and may wait
        inside the junction, at an internal junction (:meth:`_waits_inside`), the ego
        stands before the junction instead, where it still can (:meth:`_before_junction`;
        not at an all-way stop, where the stop's own rule holds). One that has crept within
        :data:`YIELD_STOP` of the area stays there while it must give way: it is in the
        area only within :data:`YIELD_EDGE` of it. A foe standing still outside the area
        is waiting (for a light or another vehicle) and is no conflict, except at an
        all-way stop that the ego has not yet entered, where it goes once it has stopped
        (SUMO's drivers do not see a vehicle that SUMO does not drive approach), and
        another planned vehicle that goes first (:meth:`_goes_first`): such a foe may speed
        up from its speed at :data:`FOE_ACCEL` to reach the area.
        """
        ego = self.sc.ego
        foes = self.signals.foes
        if foes is None:  # an older SUMO, or the ego not on its route: SUMO's view only
            return math.inf
        kind, junction = self._next_stop()
        inside = self.last_lane.startswith(":")
        cap = math.inf
        for foe in foes:
            ego_in, foe_in, ego_out, foe_out, must_yield = (
                foe.ego_in, foe.foe_in, foe.ego_out, foe.foe_out, foe.must_yield)
            if not must_yield or ego_in <= YIELD_EDGE:
                continue  # the ego has the way, or is in the area already
            # the all-way stop's rule holds for its own foes, and only until the ego is in
            # the junction (SUMO's drivers wait for a vehicle on the junction's lanes)
            going = ((kind == "w" and not inside and _junction_of(foe.foe_lane) == junction)
                     or self._goes_first(foe))
            v_f = foe.foe_speed
            foe_out += foe.foe_length
            if foe_out <= 0.0 or (foe_in > 0.0 and v_f < STOPPED_FOE_SPEED and not going):
                continue  # cleared, or waiting outside the area
            t_foe_in = (_reach_time(max(foe_in, 0.0), v_f, FOE_ACCEL) if going
                        else max(foe_in, 0.0) / max(v_f, 1e-3))
            t_foe_out = foe_out / max(v_f, 1e-3)
            t_in = self._time_along_plan(ego_in)
            t_out = self._time_along_plan(ego_out + ego.length)
            if t_in - YIELD_GAP >= t_foe_out or t_foe_in >= t_out + YIELD_GAP:
                continue
            if self._in_lane_way(foe.foe_lane, foe.foe_width):
                continue  # in the foe's way where it stands already: clear it
            if inside and self._foe_waits(foe):
                continue  # SUMO's driver waits for a vehicle in the junction
            ahead = min(ego_in, self._lane_reach(foe.foe_lane, foe.foe_width))
            c = self._stop_short(*(self._before_junction(ahead)
                                   if kind != "w" and self._waits_inside(foe)
                                   else (ahead, None)))
            if c < cap:
                cap = c
                self._hold(f"giving way at a junction to vehicle '{foe.id}', as SUMO's "
                           "right of way says", foe.id)
        return cap

    def _waits_inside(self, foe: JunctionFoe) -> bool:
        """Whether SUMO's driver of ``foe`` has an internal junction on its way through the
        junction (its connection runs on more than one junction lane): it may wait there,
        inside the junction, for a vehicle in the ego's way."""
        if foe.id in self.board or not foe.foe_lane.startswith(":"):
            return False
        c = self.net.connection_via(foe.foe_lane)
        return c is not None and c.internal_junction

    def _before_junction(self, ahead: float) -> tuple[float, float | None]:
        """Where [m ahead along the plan] the vehicle is to stand to give way instead of
        ``ahead``, and the braking [m/s^2] to stand there (``None``: ``b_max``): before the
        junction ahead that holds that place, where its connection runs on one junction
        lane, if the vehicle can still stand :data:`YIELD_STOP` before it (or, crept
        nearer, before it at all) braking at :data:`HARD_BRAKING` times ``b_max`` or less.
        SUMO's drivers never stand inside such a junction, and one that turns across it
        waits at its own internal junction for a vehicle standing there, maybe with its
        front in that vehicle's way: both waited for good (a planned car going straight on
        at the city's bridge junction and SUMO's car turning left into the same lane)."""
        if self.last_lane.startswith(":"):
            return ahead, None
        front = self.station + self.sc.ego.length / 2.0
        b = self.sc.trajectory.b_max
        for j_in, j_out in self._junction_spans:
            if j_in < front or front + ahead >= j_out:
                continue  # passed or in it, or the place lies beyond it
            if front + ahead <= j_in or j_in not in self._one_lane_junctions:
                return ahead, None
            # to stand YIELD_STOP before it; one that has crept nearer stands at once,
            # before the junction
            stand = j_in - front - YIELD_STOP
            need = self.v * self.v / (2.0 * (stand if stand > 0.0 else max(j_in - front, 1e-6)))
            if need > HARD_BRAKING * b:
                return ahead, None
            return j_in - front, max(need, b)
        return ahead, None

    def _foe_waits(self, foe: JunctionFoe) -> bool:
        """Whether SUMO's driver of ``foe`` waits for the ego, which is in the junction
        already: the foe is not yet on the junction's lane where they meet, and can stop
        before the conflict area braking at :data:`FOE_DECEL`. SUMO's drivers give way to
        the vehicles in a junction; an ego that stopped there to give way to them would
        stand in their way for good. Not so before an internal junction (a lane of the
        connection that another follows), where SUMO's drivers wait for the foes, and SUMO's
        foes drive on."""
        if foe.id in self.board:
            return False  # another planned vehicle: its published plan times the meeting
        c = self.net.connection_via(self.last_lane)
        if c is None or c.via.index(self.last_lane) < len(c.via) - 1:
            return False
        try:
            length = self.net.lane(foe.foe_lane).length
        except SplineplanError:
            return False
        return (foe.foe_in > length
                and foe.foe_speed * foe.foe_speed < 2.0 * FOE_DECEL * foe.foe_in)

    def _goes_first(self, foe: JunctionFoe) -> bool:
        """Whether ``foe``, another planned vehicle that the ego must give way to, standing
        as near the conflict area as the ego or nearer (by id where equally near), goes
        first: the ego then waits for it as for one that may move off. Where each must
        give way to the other (both inside a junction), the nearer goes and the other
        waits, where both waited before."""
        if foe.id not in self.board or foe.foe_speed >= STOPPED_FOE_SPEED:
            return False
        return (foe.foe_in, foe.id) < (foe.ego_in, self.ego)

    def _allway_speed(self, cap: float) -> float:
        """Speed cap [m/s] that gives way at an all-way stop once the vehicle has stopped
        there: SUMO reports no junction foes at all-way stops, and its drivers, who go in
        the order they stopped, do not see a vehicle SUMO does not drive approach. So the
        vehicle waits before the line while any vehicle SUMO drives is in the junction or
        comes towards it within :data:`ALLWAY_REACH` [m] of its outline's bounding circle,
        heading more than :data:`~.cooperate.CROSSING` away from the vehicle's heading
        (other planned vehicles: by their published plans). Only caps below ``cap``."""
        if not self._stop_lines or self.last_lane.startswith(":") or cap <= 0.0:
            return math.inf
        front = self.station + self.sc.ego.length / 2.0
        line, edge, kind = next(((a, e, k) for a, e, k in self._stop_lines if a >= front),
                                (math.inf, "", ""))
        if kind != "w" or edge not in self.stops_done:
            return math.inf  # no all-way stop next, or not stopped at it yet
        o = self.others
        if not o.n:
            return math.inf
        centre, radius = self._junction_circle(edge)
        d = centre - o.front
        dist = np.hypot(d[:, 0], d[:, 1])
        toward = d[:, 0] * o.cos + d[:, 1] * o.sin > 0.0
        turn = np.abs(wrap_angle(o.head - float(self.pose[2])))
        near = np.flatnonzero(((dist <= radius) | (toward & (dist <= radius + ALLWAY_REACH)))
                              & (turn > CROSSING))
        foes = [j for j in near.tolist() if o.ids[j] not in self.board]
        if not foes:
            return math.inf
        c = self._stop_short(line - front)
        if c < cap:
            self._hold(f"giving way at an all-way stop to vehicle '{o.ids[foes[0]]}'",
                       o.ids[foes[0]])
        return c

    def _junction_circle(self, edge: str) -> tuple[FloatArray, float]:
        """Centre [m] and radius [m] of the bounding circle of the outline of the junction
        that ``edge`` ends at."""
        net = self.net
        shape = np.asarray(net.junction_shapes.get(net.to_node(edge), np.zeros((1, 2))),
                           dtype=float)
        centre = shape.mean(axis=0)
        return centre, float(np.max(np.hypot(*(shape - centre).T)))

    def _next_stop(self) -> tuple[str, str]:
        """The kind of stop (:meth:`~splineplan.network.RoadNetwork.stop_kind`) at the
        next junction on the route and that junction's id, ``("", "")`` where it has no
        stop; the one the vehicle stands at, or has just left, counts while it is not yet
        in the junction, and the one it is in, until it has left it."""
        if not self._stop_lines:
            return "", ""
        front = self.station + self.sc.ego.length / 2.0
        for a, b in self._junction_spans:
            if a >= front - STOP_REACH or front < b:
                edge, kind = next(((e, k) for line, e, k in self._stop_lines if line == a),
                                  ("", ""))
                return kind, (self.net.to_node(edge) or "") if edge else ""
        return "", ""

    def _lane_reach(self, lane_id: str, width: float) -> float:
        """How far [m] the ego can go along its path before its footprint comes within
        :data:`PATH_MARGIN` of a vehicle ``width`` [m] wide anywhere on the centre line of
        SUMO's lane ``lane_id`` (a foe's lane through a junction), ``inf`` where it does
        not on its path ahead (or the width is unknown). Found once per plan, lane and
        width, for every path sample (:func:`~splineplan.spacetime.box_gap` of the
        footprint and each piece of that band)."""
        if not lane_id or width <= 0.0:
            return math.inf
        stations = self._reach.get((lane_id, width))
        if stations is None:
            stations = self._touching(lane_id, width)
            self._reach[(lane_id, width)] = stations
        k = bisect.bisect_left(stations, self.u)
        return stations[k] - self.u if k < len(stations) else math.inf

    def _touching(self, lane_id: str, width: float) -> list[float]:
        """Stations [m] of the path samples whose footprint comes within
        :data:`PATH_MARGIN` of the band ``width`` [m] wide along lane ``lane_id`` (none
        for a lane the network lacks)."""
        band = self._lane_band(lane_id, width)
        if band is None:
            return []
        pts, mid, head, size = band
        ego = self.sc.ego
        # only the samples near the lane's bounding box can come near it
        reach = 0.5 * math.hypot(ego.length, ego.width) + 0.6 * width + PATH_MARGIN
        xy = self.full_xy
        close = np.flatnonzero(np.all(xy >= pts.min(axis=0) - reach, axis=1)
                               & np.all(xy <= pts.max(axis=0) + reach, axis=1))
        n, m = len(close), len(head)
        if not n:
            return []
        i = np.repeat(close, m)
        j = np.tile(np.arange(m), n)
        gap = box_gap(xy[i], self.full_heading[i], (ego.length, ego.width),
                      mid[j], head[j], (size[0][j], size[1][j]))
        near = (gap.reshape(n, m) <= PATH_MARGIN).any(axis=1)
        return self.full_s[close[near]].tolist()

    def _in_lane_way(self, lane_id: str, width: float) -> bool:
        """Whether the footprint where the vehicle is overlaps the band ``width`` [m] wide
        along lane ``lane_id``: a vehicle of that width driving along the lane would run
        into it there."""
        band = self._lane_band(lane_id, width)
        if band is None:
            return False
        _, mid, head, size = band
        ego = self.sc.ego
        m = len(head)
        gap = box_gap(np.repeat(self.pose[None, :2], m, axis=0), np.full(m, self.pose[2]),
                      (ego.length, ego.width), mid, head, size)
        return bool((gap <= 0.0).any())

    def _lane_band(self, lane_id: str, width: float
                   ) -> tuple[FloatArray, FloatArray, FloatArray,
                              tuple[FloatArray, FloatArray]] | None:
        """The band ``width`` [m] wide along lane ``lane_id`` as rectangles, one per piece of
        its centre line: the lane's points, the pieces' centres, headings and (length,
        width); ``None`` for a lane the network lacks, or unknown width. Kept per lane and
        width."""
        key = (lane_id, width)
        if key in self._bands:
            return self._bands[key]  # type: ignore[no-any-return]
        band = None
        if lane_id and width > 0.0:
            try:
                pts = np.asarray(self.net.lane(lane_id).shape, dtype=float)
            except SplineplanError:
                pts = np.zeros((0, 2))
            d = np.diff(pts, axis=0)
            seg = np.hypot(d[:, 0], d[:, 1])
            keep = seg > 1e-6
            if keep.any():
                mid, d, seg = ((pts[:-1] + pts[1:]) / 2.0)[keep], d[keep], seg[keep]
                band = (pts, mid, np.arctan2(d[:, 1], d[:, 0]),
                        (seg + 0.1 * width, np.full(len(seg), width)))
        self._bands[key] = band
        return band

    def _body_speed(self, cap: float) -> float:
        """Speed cap [m/s] that keeps the ego's footprint, swinging round its path's
        curves, off the bodies of others (:mod:`.bodies`): of long vehicles sweeping
        through a junction (driving on along their lanes for :data:`~.bodies.HORIZON`)
        by the safety margin, of standing vehicles by :data:`PATH_MARGIN`. Where a body
        comes that near the ego's footprint on its path ahead, and the ego would be there
        within :data:`YIELD_GAP` of the time the body is, the ego stops before that place,
        if it still can at its emergency braking (else it goes on, to clear it). Within
        the margin of a moving body's sweep already, it waits where it is unless the body
        overlaps it there; and where ``cap`` (the other rules) would stand it inside a
        sweep before the body has passed, it stands before the sweep. Only caps below
        ``cap`` are looked for."""
        if self.traj is None or cap <= 0.0:
            return math.inf
        out = math.inf
        # where the other caps stand the vehicle if they brake it [m ahead]: there it
        # waits, and a body that comes by later must find it before its sweep
        b = self.sc.trajectory.b_max
        stand = cap * cap / (2.0 * b) + self.v * self.dt if cap < self.v else math.inf
        for s_in, s_out, t_in_b, t_out_b, (why, by), touch in self._bodies_meeting():
            if s_in <= self.u and touch is not None:
                # within the margin of the sweep already: wait where the footprint is
                # rather than drive on into the body, unless it overlaps it here
                s_in, s_out, t_in_b, t_out_b = touch
            c = self._give_way(s_in, s_out, t_in_b, t_out_b)
            if math.isinf(c) and s_in > self.u and stand >= s_in - self.u and t_out_b > 0.0:
                c = self._stop_short(s_in - self.u)  # it would wait inside the sweep
            if c < min(out, cap):
                out = c
                self._hold(why, *by)
        return out

    def _bodies_meeting(self) -> list[tuple[float, float, float, float,
                                            tuple[str, tuple[str, ...]],
                                            tuple[float, float, float, float] | None]]:
        """Where (first and last station on the plan [m]) and when (first and last time
        [s] from now) bodies meet the ego's footprint on its path ahead, and what to say
        of each, with the vehicle where it is one (:meth:`_body_speed`): each moving long
        vehicle's, and the standing vehicles' of each size together; all in one pass
        (:func:`~.bodies.meetings`).
        For a moving long vehicle, also where and when its body overlaps the footprint
        (no margin; ``None`` where it does not, and for the standing ones)."""
        o = self.others
        if not o.n:
            return []
        sc, ego = self.sc, self.sc.ego
        s = self.full_s
        lo = max(int(np.searchsorted(s, self.u, side="right")) - 1, 0)
        hi = int(np.searchsorted(s, self.u + max(self.v * HORIZON, 0.0) + ego.length + 10.0))
        if hi - lo < 1:
            return []
        path = (s[lo:hi], self.full_xy[lo:hi], self.full_heading[lo:hi])
        rows: list[tuple[FloatArray, FloatArray, FloatArray, float, float, float]] = []
        whys: list[tuple[str, tuple[str, ...]]] = []
        last: list[float] = []  # a body still meeting at this time stays
        touching: list[bool] = []  # a row without the margin (follows its margin's row)
        where = {o.ids[i]: i for i in np.flatnonzero(o.length >= LONG_VEHICLE).tolist()}
        for place in self.signals.long:
            i = where.get(place.id)
            if i is None or place.speed < MOVING:
                continue
            length, width = float(o.length[i]), float(o.width[i])
            body = self._body_of(place, length)
            if body is None:
                continue
            times, centres, heads = body
            why = (f"giving way to the body of vehicle '{place.id}' sweeping through the "
                   "junction")
            for margin in (sc.roadmap.safety_margin, 0.0):  # the margin, then touching
                rows.append((times, centres, heads, length, width, margin))
                whys.append((why, (place.id,)))
                last.append(float(times[-1]))
                touching.append(margin == 0.0)
        # standing vehicles near the path ahead, by size (few sizes)
        xy = path[1]
        x0, y0 = xy.min(axis=0) - ego.length
        x1, y1 = xy.max(axis=0) + ego.length
        standing = np.flatnonzero((o.speed < MOVING) & (o.cx + o.radius >= x0)
                                  & (o.cx - o.radius <= x1) & (o.cy + o.radius >= y0)
                                  & (o.cy - o.radius <= y1))
        margin = min(PATH_MARGIN, 0.5 * sc.roadmap.safety_margin)
        for dims in {(float(o.length[i]), float(o.width[i])) for i in standing.tolist()}:
            group = standing[(o.length[standing] == dims[0]) & (o.width[standing] == dims[1])]
            rows.append((np.zeros(len(group)), o.centre[group], o.head[group], dims[0],
                         dims[1], margin))
            whys.append(("keeping its body off a standing vehicle beside its path", ()))
            last.append(0.0)
            touching.append(False)
        if not rows:
            return []
        counts = [len(r[0]) for r in rows]
        met = meetings(np.repeat(np.arange(len(rows)), counts), len(rows),
                       np.concatenate([r[0] for r in rows]),
                       np.concatenate([r[1] for r in rows]),
                       np.concatenate([r[2] for r in rows]),
                       np.repeat([r[3] for r in rows], counts),
                       np.repeat([r[4] for r in rows], counts),
                       np.repeat([r[5] for r in rows], counts), *path, (ego.length, ego.width))
        spans: list[tuple[float, float, float, float] | None] = []
        for (s_in, s_out, t_in, t_out), end in zip(met.tolist(), last, strict=True):
            if t_out >= end - 1e-9:
                t_out = math.inf  # still there at the horizon
            spans.append(None if math.isnan(s_in) else (s_in, s_out, t_in, t_out))
        found = []
        for k, (span, said, touch) in enumerate(zip(spans, whys, touching, strict=True)):
            if span is None or touch:
                continue
            bare = spans[k + 1] if k + 1 < len(spans) and touching[k + 1] else None
            found.append((*span, said, bare))
        return found

    def _give_way(self, s_in: float, s_out: float, t_in_b: float, t_out_b: float) -> float:
        """Speed cap [m/s] for a body that meets the path from station ``s_in`` to
        ``s_out`` [m] of the plan, from ``t_in_b`` to ``t_out_b`` [s] from now, or
        ``inf``."""
        ahead = s_in - self.u
        if ahead <= 0.0:
            return math.inf  # in its way already: clear it
        t_in = self._time_along_plan(ahead)
        t_out = self._time_along_plan(s_out - self.u)
        if t_in - YIELD_GAP >= t_out_b or t_in_b >= t_out + YIELD_GAP:
            return math.inf
        return self._stop_short(ahead)

    def _stop_short(self, ahead: float, braking: float | None = None) -> float:
        """Speed cap [m/s] that stops :data:`YIELD_STOP` short of a place ``ahead`` [m]
        along the plan (comfortably, or at ``braking`` [m/s^2]; one step early; at once
        where it is that near already), or ``inf`` where the ego cannot stop before it even
        at its emergency braking: it goes on, to clear it."""
        if self._cannot_stop(max(ahead, 0.0)):
            return math.inf
        return self._stand_within(self._before_change(ahead - YIELD_STOP), braking)

    def _before_change(self, stand: float) -> float:
        """Where [m ahead along the plan] the vehicle is to stand instead of ``stand``:
        :data:`YIELD_STOP` before the lane change ahead (``lane_change``) where it would
        otherwise stand with its footprint over the lane line (SUMO's drivers in the next
        lane see a car by its lane and lateral offset, not its corner), if it still can
        stop there at its emergency braking; else ``stand``."""
        ch = self.lane_change
        if ch is None:
            return stand
        at = ch.at - self.u
        if at <= 0.0 or not at <= stand < ch.end - self.u:
            return stand  # changing already, or standing before or after the change
        before = max(at - YIELD_STOP, 0.0)
        if self._cannot_stop(before):
            return stand
        return before

    def _change_speed(self) -> float:
        """Speed cap [m/s] that waits for a gap before changing lanes: where the plan
        reaches into the next lane ahead (``lane_change``), a vehicle in that lane which,
        at its speed, will be less than the gap behind or ahead of where the ego then is
        (:data:`CHANGE_GAP_TIME` at the follower's speed, and the room the follower needs
        to brake to the ego's speed) holds the ego back before that place, if it can
        still stop there at its emergency braking; before the junction, where that place
        would leave it standing inside one (``keep_clear``). Inside a junction the ego goes
        on: the lanes it reaches into there are other connections, and a car standing in a
        junction blocks it."""
        ch = self.lane_change
        o = self.others
        if (ch is None or self.traj is None or not o.n or self.corridor is None
                or self.last_lane.startswith(":")):
            return math.inf  # (in a junction there are no lanes to change between)
        tp, ego = self.sc.trajectory, self.sc.ego
        ahead = ch.at - self.u
        stop = self._stop_short(ahead)
        if math.isinf(stop) or (ahead <= 0.0 and self.last_lane == ch.lane_id):
            return math.inf  # cannot stop before, or SUMO has it in that lane already
        x, y = float(self.pose[0]), float(self.pose[1])
        near = np.flatnonzero((~o.stopped) & (np.hypot(o.cx - x, o.cy - y) < CHANGE_LOOK))
        if not len(near):
            return math.inf
        c = self.corridor
        sl = np.atleast_2d(self._project(np.column_stack((o.cx[near], o.cy[near])),
                                         back=CHANGE_LOOK + 10.0, ahead=CHANGE_LOOK + 10.0))
        right, _ = c.bounds_at(np.clip(sl[:, 0], 0.0, c.length))
        there = np.floor((sl[:, 1] - right) / ch.width) == ch.lane
        if not there.any():
            return math.inf
        t_e = self._time_along_plan(max(ahead, 0.0))
        ps, _, _, _, pv2 = self._pl
        v_e = min(math.sqrt(max(_interp(ch.at, ps, pv2), 0.0)),
                  math.sqrt(self.v * self.v + 2.0 * tp.a_max * max(ahead, 0.0)))
        s_e = self.station + ahead
        for j, (s_o, _) in zip(near[there].tolist(), sl[there].tolist(), strict=True):
            v_o = max(float(o.speed[j]), 0.0)
            if v_o < STOPPED_FOE_SPEED and self._clears_standing(j, ch):
                continue  # it stands beside: the footprint passes it, wherever it reaches
            d = s_o + v_o * t_e - s_e
            half = 0.5 * (float(o.length[j]) + ego.length)
            if d >= 0.0:  # ahead of the ego then
                short = d - half < max(CHANGE_MIN_GAP, v_e * CHANGE_GAP_TIME)
            else:  # behind: it must keep its gap, braking to the ego's speed
                need = v_o * CHANGE_GAP_TIME + max(v_o - v_e, 0.0) ** 2 / (2.0 * tp.b_max)
                short = -d - half < max(CHANGE_MIN_GAP, need)
            if short:
                self._hold(f"waiting for a gap to change lanes (vehicle '{o.ids[j]}' in "
                           "the lane)", o.ids[j])
                if self.keep_clear:  # not inside the junction the change reaches into
                    stop = min(stop, self._keep_clear_speed(ch.at - YIELD_STOP
                                                            + ego.length / 2.0))
                return stop  # one that reaches over the line already stands
        return math.inf

    def _clears_standing(self, j: int, ch: LaneChange) -> bool:
        """Whether the plan's footprint, from the vehicle to the end of the lane change
        ``ch`` (at most :data:`SIDE_LOOK` past its start), keeps :data:`SIDE_CLEAR` from
        vehicle ``j`` of ``others`` where it stands, or where the two stand nearer already
        (side by side, each waiting for the other's lane), never comes nearer to it than
        it is."""
        ps = np.asarray(self.path_s, dtype=float)
        stop = min(ch.end, ch.at + SIDE_LOOK)
        k = np.flatnonzero((ps >= self.u) & (ps <= stop))
        return self._keeps_off(j, np.asarray(self.path_xy, dtype=float)[k],
                               np.asarray(self.path_heading, dtype=float)[k], SIDE_CLEAR)

    def _keeps_off(self, j: int, xy: FloatArray, heading: FloatArray, room: float,
                   give: float = 1e-3) -> bool:
        """Whether the footprint at the path's points ``xy`` ``(n, 2)`` [m], headings
        ``heading`` [rad], keeps ``room`` [m] from vehicle ``j`` of ``others`` where it
        stands, or where the two are nearer already at the first of them (side by side),
        never comes more than ``give`` [m] nearer to it than that (nor touches it)."""
        n = len(heading)
        if not n:
            return False
        o, ego = self.others, self.sc.ego
        gap = box_gap(xy, heading, (ego.length, ego.width),
                      np.repeat(o.centre[j:j + 1], n, axis=0), np.full(n, float(o.head[j])),
                      (float(o.length[j]), float(o.width[j])))
        return bool(np.min(gap) >= min(room, float(gap[0]) - give) and np.min(gap) > 0.0)

    def _body_of(self, place: LanePlace, length: float
                 ) -> tuple[FloatArray, FloatArray, FloatArray] | None:
        """The predicted body (:func:`~.bodies.bodies_along`) of a moving long vehicle of
        ``length`` [m] at ``place``, ``None`` where it approaches no junction or does not
        reach it within :data:`~.bodies.HORIZON`, and where its front has left the last
        junction and its body has too. Predicted for that horizon, or until the body has
        left the junction where that takes longer (at most :data:`~.bodies.SLOW_HORIZON`).
        Kept for the step (planned vehicles of one run share it: the run clears it each
        step)."""
        key = (place, length)
        if key in self._bodies_now:
            return self._bodies_now[key]
        found = None
        known = self._body_path(place)
        after = self._bodies_after.get(place.id) if place.pos < length else None
        if after is not None and after[2] == place.lane:
            # its front has left the junction, its body still sweeps through it
            known = after[:2]
        elif known is not None and place.lane.startswith(":"):
            c = self.net.connection_via(place.lane)
            if c is not None:  # the lane after the junction, the last of the path
                self._bodies_after[place.id] = (known[0], len(known[0].starts) - 1,
                                                f"{c.to_edge}_{c.to_lane}")
        if known is not None:
            lanes, index = known
            at = lanes.station(index, place.pos)
            if index > 0 or at + place.speed * HORIZON >= float(lanes.starts[1]):
                # a slow one is followed until its body has left the junction: a car that
                # stands just beyond a shorter prediction stands in its way
                clear = float(lanes.starts[-1]) + length - at
                inside = place.lane.startswith(":")
                found = bodies_along(lanes, at, place.speed, length,
                                     accel=JUNCTION_ACCEL if inside else 0.0,
                                     top=JUNCTION_TOP, horizon=min(
                                         max(HORIZON, clear / max(place.speed, MOVING)),
                                         SLOW_HORIZON))
        self._bodies_now[key] = found
        return found

    def _body_path(self, place: LanePlace) -> tuple[BodyPath, int] | None:
        """The lanes a long vehicle's front follows through the next junction (the lane
        before it, its internal lanes and the lane after), and which of them it is on;
        ``None`` where it approaches none. Kept per lane and internal lane (planned
        vehicles of one run share them)."""
        key = (place.lane, place.via)
        if key in self._body_paths:
            return self._body_paths[key]
        net, found = self.net, None
        try:
            c = net.connection_via(place.lane if place.lane.startswith(":") else place.via)
            if c is not None:
                chain = [f"{c.from_edge}_{c.from_lane}", *c.via, f"{c.to_edge}_{c.to_lane}"]
                if place.lane in chain:
                    lanes = [net.lane(lane) for lane in chain]
                    found = (body_path([(ln.shape, ln.length) for ln in lanes]),
                             chain.index(place.lane))
        except (LookupError, SplineplanError):
            found = None
        self._body_paths[key] = found
        return found

    def _time_along_plan(self, dist: float) -> float:
        """Time [s] the ego takes to drive ``dist`` [m] along its plan from where it is,
        at the plan's speeds but no faster than accelerating from its speed at ``a_max``.

        The times to the plan's samples ahead are summed once per step
        (:meth:`_plan_times`), the same sums in the same order as a walk along them."""
        ps, _, _, _, pv2 = self._pl
        u0 = self.u
        end = min(u0 + dist, ps[-1])
        t, v = 0.0, self.v
        if u0 < end - 1e-9:
            i0, vn, tcum = self._plan_times()
            m = bisect.bisect_left(ps, end) - i0  # samples passed on the way
            u = u0
            if m > 0:
                t, u, v = tcum[m - 1], ps[i0 + m - 1], vn[m - 1]
            if u < end - 1e-9:
                a2 = 2.0 * self.sc.trajectory.a_max
                v_next = max(min(math.sqrt(max(_interp(end, ps, pv2), 0.0)),
                                 math.sqrt(self.v * self.v + a2 * (end - u0))), 0.5)
                t += 2.0 * (end - u) / (max(v, 0.5) + v_next)
                v = v_next
        # beyond the plan's end: at the last speed
        return t + max(dist - (end - u0), 0.0) / max(v, 0.5)

    def _plan_times(self) -> tuple[int, list[float], list[float]]:
        """From the ego's station on: the first sample ahead, and at each sample from it
        the speed [m/s] (the plan's, capped by accelerating from the ego's speed, at least
        0.5) and the time [s] to reach it; kept for the step."""
        key = (self.u, self.v)
        if self._times_key == key:
            return self._times
        ps, _, _, _, pv2 = self._pl
        s_np, pv2_np = self._pl_np
        u0 = self.u
        i0 = bisect.bisect_right(ps, u0)
        s = s_np[i0:]
        vp = np.sqrt(np.maximum(pv2_np[i0:], 0.0))
        if len(vp) and i0 <= len(ps) - 1:  # the last sample as _interp has it
            vp[-1] = math.sqrt(max(_interp(ps[-1], ps, pv2), 0.0))
        a2 = 2.0 * self.sc.trajectory.a_max
        vn = np.maximum(np.minimum(vp, np.sqrt(self.v * self.v + a2 * (s - u0))), 0.5)
        prev_v = np.concatenate(([max(self.v, 0.5)], vn[:-1]))
        prev_s = np.concatenate(([u0], s[:-1]))
        tcum = np.cumsum(2.0 * (s - prev_s) / (prev_v + vn))
        self._times_key = key
        self._times = (i0, vn.tolist(), tcum.tolist())
        return self._times


def _on_curve(j: int, f: float, s: list[float], x: list[float], y: list[float],
              h: list[float]) -> tuple[float, float]:
    """The point at fraction ``f`` of the step from path sample ``j`` to the next (stations
    ``s``, positions ``x``, ``y`` [m], headings ``h`` [rad]) on the cubic that leaves and
    reaches them along their headings (Hermite): on the plan's curve to within a fraction
    of a millimetre, where the chord between the samples would put the vehicle up to the
    step's sagitta inside a bend and kink its path at every sample."""
    span = s[j + 1] - s[j]
    f2, f3 = f * f, f * f * f
    a, b = 2.0 * f3 - 3.0 * f2 + 1.0, span * (f3 - 2.0 * f2 + f)
    c, d = 1.0 - a, span * (f3 - f2)
    c0, s0, c1, s1 = math.cos(h[j]), math.sin(h[j]), math.cos(h[j + 1]), math.sin(h[j + 1])
    return (a * x[j] + b * c0 + c * x[j + 1] + d * c1,
            a * y[j] + b * s0 + c * y[j + 1] + d * s1)


def _reach_time(dist: float, speed: float, accel: float) -> float:
    """Time [s] to cover ``dist`` [m] from ``speed`` [m/s] speeding up at ``accel``
    [m/s²]."""
    return (math.sqrt(speed * speed + 2.0 * accel * dist) - speed) / accel


def _junction_of(lane_id: str) -> str:
    """The junction of SUMO's internal lane ``lane_id`` (``:<junction>_<link>_<lane>``),
    ``""`` for a lane that is not internal."""
    return lane_id[1:].rsplit("_", 2)[0] if lane_id.startswith(":") else ""


def _lane_index(lane_id: str) -> int:
    try:
        return int(lane_id.rsplit("_", 1)[1])
    except (IndexError, ValueError):
        return 0
