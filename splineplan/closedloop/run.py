"""The closed loop over the active drivers: SUMO steps, every planned vehicle perceives,
replans and is moved.

Each step::

    for d in active: world.move(d.id, d.command(world.signals(d.id)))
    events = world.step()
    for d in departed planned vehicles: world.take_control(d.id); d.enter(...)
    for d in active:
        d.perceive(world.state(d.id), world.around(d.id)); d.maybe_replan()

The planned vehicles are the scenario's ``[[ego]]`` tables (inserted by the run), or those
of a SUMO scenario's own vehicles chosen by a :class:`~splineplan.closedloop.select.Selection`
(taken over where SUMO inserts them). Vehicles planned earlier publish their trajectories;
see :mod:`splineplan.closedloop.cooperate`.
"""

from __future__ import annotations

import contextlib
import logging
import os
import sys
import time
import xml.etree.ElementTree as ET
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import Any

import numpy as np

from splineplan._signals import sigint_deferred, sigint_ignored
from splineplan.closedloop.bodies import LONG_VEHICLE
from splineplan.closedloop.control import EMERGENCY_FACTOR, YIELD_EDGE
from splineplan.closedloop.cooperate import Published, waits_in_cycle
from splineplan.closedloop.driver import DRIVERS, Driver, DriverKind
from splineplan.closedloop.record import (
    RunTotals,
    SimResult,
    driven_columns,
    vehicle_metrics,
    write_vehicle,
)
from splineplan.closedloop.select import Picker, Selection
from splineplan.errors import (
    Interrupted,
    ParameterError,
    ScenarioError,
    SimulationError,
    SplineplanError,
)
from splineplan.scenario import Scenario
from splineplan.sumo import ssm
from splineplan.sumo.world import SumoError, World, sumo_message
from splineplan.traffic import RoadCheck

log = logging.getLogger(__name__)

#: Width [m] of SUMO's sublanes for the ``planner`` and ``sublane`` drivers. The planner's
#: runs need the sublane model: the ego leans into a neighbouring lane to pass an obstacle,
#: and only with sublanes do SUMO's vehicles on that lane see the part of the ego that is in
#: it (lane-based, SUMO puts the ego on one lane and a car on the next lane drives past it
#: with centimetres to spare; see :mod:`splineplan.sim`).
LATERAL_RESOLUTION = 0.4
#: At most this many plans are drawn with ``plot=True``.
MAX_PLAN_PICTURES = 40
#: Warnings of one kind that a run with several planned vehicles writes to ``sumo.log`` in
#: full; SUMO counts the rest (``--aggregate-warnings``).
AGGREGATE_WARNINGS = 50
#: Seconds planned vehicles stand in a cycle of waits before one stops waiting for the
#: next one's plan, and for how long [s] it does not wait for that vehicle's plans.
DEADLOCK_WAIT = 5.0
RELEASE_FOR = 10.0


def simulate(
    scenario: Scenario,
    *,
    out_dir: str | Path,
    plot: bool = False,
    gui: bool = False,
    seed: int | None = None,
    progress: bool | None = None,
    on_step: Callable[[float], None] | None = None,
    driver: DriverKind = "planner",
    share: float | None = None,
    vehicles: tuple[str, ...] = (),
    vtype: str | None = None,
) -> SimResult:
    """Run a scenario in SUMO with the planner driving the ego vehicle(s).

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
    share, vehicles, vtype
        Also plan these of SUMO's own vehicles (:class:`~.select.Selection`): a share
        [0, 1] of the departing passenger vehicles (drawn with ``seed``, default 0), the
        vehicles of these ids, those of this type. Each is taken over where SUMO inserts
        it, drives to its route's last edge and leaves there. With more than one planned
        vehicle (or any of these), each has its own folder ``out_dir/<id>/`` and the run
        writes ``summary.json``; the result's ``vehicles`` holds each one's result.

    Raises
    ------
    ScenarioError, UnknownEdgeError, VehicleClassError, NoRouteError
        Bad input (missing file, unknown edge, an edge the ego's class may not use).
    SimulationError
        SUMO failed to start or to step, or the ego left the simulation unplanned; with
        ``gui=True``, no display to show ``sumo-gui`` on (checked before anything starts).
    Interrupted
        Ctrl-C (``KeyboardInterrupt``) during the run: SUMO is closed (``fcd.xml`` and
        ``ssm.xml`` complete), ``trajectory.csv`` and ``metrics.json`` (status
        ``interrupted``, the time reached) are written, no pictures; the exception's
        ``result`` is the :class:`SimResult`.
    """
    if seed is not None:
        scenario = scenario.with_seed(seed)
    if driver not in DRIVERS:
        raise ParameterError(f"driver must be one of {', '.join(map(repr, DRIVERS))}, "
                             f"not {driver!r}")
    selection = None
    if share is not None or vehicles or vtype is not None or scenario.from_sumo:
        selection = Selection(tuple(vehicles), vtype, 0.0 if share is None else share,
                              0 if seed is None else seed)
    if gui:
        _check_display()
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    run = _Run(scenario, out, kind=driver, gui=gui, on_step=on_step,
               progress=_want_progress(progress), selection=selection,
               sumo_seed=seed is not None or not scenario.from_sumo)
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
        if run.world.started:
            raise SimulationError(f"{scenario.name}: {err}") from err
        raise
    except Exception as err:  # anything unforeseen: keep what we have
        run.fail(err)
        run.finish(plot=plot)
        raise SimulationError(f"{scenario.name}: simulation stopped at "
                              f"t={run.time:.1f} s: {sumo_message(err)}") from err
    return run.finish(plot=plot)


class _Run:
    """State of one closed-loop run (internal): the world and the drivers."""

    def __init__(self, scenario: Scenario, out: Path, *, kind: DriverKind, gui: bool,
                 on_step: Callable[[float], None] | None, progress: bool,
                 selection: Selection | None = None, sumo_seed: bool = True) -> None:
        self.sc = scenario
        self.out = out
        self.kind = kind
        self.on_step = on_step
        self.progress = progress
        self.selection = selection
        self.picker = Picker(selection) if selection is not None else None
        self.sumo_seed = sumo_seed
        self.world = World(gui=gui)
        self.dt = scenario.sim.step_length
        self.status = "running"
        self.reason = ""
        self.net: Any = None
        #: one folder per vehicle and a summary, or the single ego's files in ``out``
        self.multi = selection is not None or len(scenario.egos) > 1
        self.drivers: list[Driver] = [
            Driver(scenario.for_vehicle(e) if self.multi else scenario, None, kind=kind,
                   out=_vehicle_dir(out, e.id) if self.multi else out)
            for e in scenario.egos]
        self.unplanned: dict[str, str] = {}  # SUMO vehicles chosen but not planned: why
        self.sumo_collisions: list[dict[str, Any]] = []
        self.teleports = 0  # of any vehicle
        self.wall_start = time.perf_counter()
        self.wall_time = 0.0
        self._roads: dict[str, RoadCheck] = {}
        self.board: dict[str, Published] = {}  # the planned vehicles' latest plans
        # what the drivers share of long vehicles' bodies: paths through junctions, the
        # last one each went through, and this step's predicted bodies (Control._body_of)
        self._body_paths: dict[Any, Any] = {}
        self._bodies_now: dict[Any, Any] = {}
        self._bodies_after: dict[Any, Any] = {}
        self._entered = 0
        self._published = 0  # plans published so far
        # cycles of planned vehicles standing, each held by the next (_release_deadlocks)
        self.deadlocks: list[dict[str, Any]] = []
        self._cycles_seen: set[frozenset[str]] = set()
        self.sizes: dict[str, tuple[float, float]] = {}  # vehicle types' length, width
        self._junctions: list[Any] = []
        self._polygons: Any = None

    @property
    def time(self) -> float:
        """Simulation time reached [s]."""
        return self.world.time

    # -- setup ----------------------------------------------------------------------------
    def setup(self) -> None:
        from splineplan.network import load_network

        sc = self.sc
        for p in (sc.network, *sc.routes, *sc.additional):
            if not Path(p).is_file():
                raise ScenarioError(f"{sc.name}: file not found: {p}")
        if self.selection is not None:
            self.selection.check(sc.routes)
        self.net = load_network(sc.network)
        for d in self.drivers:
            d.net = self.net
            d.route_from_scenario()
        if self.kind == "planner":
            from splineplan.planner import warm_up

            warm_up()  # the compiled loops, loaded before the loop rather than in a replan
        roads = {d.sc.ego.vclass: RoadCheck(self.net, d.sc.ego.vclass) for d in self.drivers}
        for p in (*sc.routes, *sc.additional):
            _check_xml(Path(p))
        self._start_sumo()
        self._junctions = self.world.junction_shapes()
        for road in roads.values():
            road.add_junctions(self._junctions)
        self._roads = roads
        self._polygons = self.world.obstacle_polygons()
        for d in self.drivers:
            d.set_road(roads[d.sc.ego.vclass], self._polygons)
            self._add_vehicle(d)

    def _road(self, vclass: str) -> RoadCheck:
        if vclass not in self._roads:
            road = RoadCheck(self.net, vclass)
            road.add_junctions(self._junctions)
            self._roads[vclass] = road
        return self._roads[vclass]

    def _start_sumo(self) -> None:
        sc = self.sc
        planned = bool(self.drivers) or (self.selection is not None
                                         and not self.selection.empty)
        if sc.from_sumo:
            # SUMO's own scenario with its own options (teleports too); ours only add
            # outputs and, where vehicles are planned, what they need
            if sc.sumo_config is not None:
                args = ["-c", str(sc.sumo_config)]
                if not sc.sim_step_given:  # SUMO's default, 1 s, is too coarse to plan
                    args += ["--step-length", f"{self.dt:g}"]
            else:
                args = ["-n", str(sc.network), "--step-length", f"{self.dt:g}"]
            if self.sumo_seed:
                args += ["--seed", str(sc.sim.seed)]
            if planned:
                args += ["--collision.action", "warn", "--collision.check-junctions", "true",
                         *self._lateral_options()]
        else:
            args = ["-n", str(sc.network),
                    "--step-length", f"{self.dt:g}", "--seed", str(sc.sim.seed),
                    "--collision.action", "warn", "--collision.check-junctions", "true",
                    "--time-to-teleport", "-1", *self._lateral_options()]
        args += ["--fcd-output", str(self.out / "fcd.xml"),
                 # everything SUMO says goes to sumo.log, nothing to the console: with
                 # --no-warnings, warnings reach only the error log (the same file)
                 "--log", str(self.out / "sumo.log"), "--error-log", str(self.out / "sumo.log"),
                 "--no-warnings", "true",
                 "--no-step-log", "true", "--duration-log.disable", "true"]
        # SUMO's surrogate safety measures: with several planned vehicles for every vehicle
        # (the run's pairs), for a single ego for the ego only (every vehicle would double
        # SUMO's time among the city's traffic; the ego's alone costs nothing measurable)
        args += ssm.ssm_options(self.out / ssm.FILE,
                                None if self.multi else [d.ego for d in self.drivers])
        if self.multi:
            args += ["--tripinfo-output", str(self.out / "tripinfo.xml"),
                     # a warning SUMO repeats every step (the SSM devices at a junction
                     # whose internal lanes it finds no crossing for: 60,000 lines in five
                     # minutes of the city's traffic) is written AGGREGATE_WARNINGS times,
                     # then counted at the end
                     "--aggregate-warnings", str(AGGREGATE_WARNINGS)]
        if sc.sumo_config is None:  # (a configuration names its own files)
            if sc.routes:
                args += ["-r", ",".join(str(p) for p in sc.routes)]
            if sc.additional:
                args += ["-a", ",".join(str(p) for p in sc.additional)]
        try:
            self.world.start(args, log_file=self.out / "sumo.log")
        except SumoError as err:
            raise SumoError(f"SUMO failed to start for scenario '{sc.name}': {err}") from err

    def _lateral_options(self) -> list[str]:
        if self.kind == "sumo":
            return []
        return ["--lateral-resolution", f"{LATERAL_RESOLUTION:g}"]

    def _add_vehicle(self, d: Driver) -> None:
        ego = d.sc.ego
        vtype = f"{ego.id}_type"
        tp = d.sc.trajectory
        planner = d.kind == "planner"
        # SUMO's view of the ego's limits: the planner's, with the closed loop's emergency
        # braking (twice b_max, see Control.command) as the physical limit; SUMO's other
        # drivers read these for the ego as a leader
        self.world.add_type(vtype, length=ego.length, width=ego.width, vclass=ego.vclass,
                            max_speed=ego.max_speed,
                            accel=tp.a_max if planner else None,
                            decel=tp.b_max if planner else None,
                            emergency_decel=EMERGENCY_FACTOR * tp.b_max if planner else None)
        self.world.add_vehicle(ego.id, list(d.route_edges), type_id=vtype, depart=ego.depart,
                               depart_pos=ego.start_pos, depart_lane=ego.start_lane,
                               arrival_pos=None if d.kind == "planner"
                               else d.goal_arrival_pos())

    # -- main loop --------------------------------------------------------------------------
    def loop(self) -> None:
        sc = self.sc
        bar = _progress_bar(sc.sim.duration, sc.name) if self.progress else None
        steps = round(sc.sim.duration / self.dt)
        open_ended = self.selection is not None
        try:
            with sigint_deferred() as ctrl_c:  # Ctrl-C stops between steps
                for k in range(steps):
                    ctrl_c.check()
                    self._move_all()
                    events = self._step()
                    if self.on_step is not None:
                        self.on_step(self.time)
                    if bar is not None and k % 10 == 0:
                        bar.update(10 * self.dt)
                    self._enter(events.departed)
                    self._observe_all(events.arrived)
                    if all(d.status not in ("pending", "running") for d in self.drivers) and (
                            not open_ended or self.world.expected() == 0):
                        break
                else:
                    for d in self.drivers:
                        if d.status in ("pending", "running"):
                            d.status = "timeout"
                            d.reason = d.timeout_reason(self.time, sc.sim.duration)
        finally:
            if bar is not None:
                bar.close()

    def _move_all(self) -> None:
        self._bodies_now.clear()
        for d in self.drivers:
            if not (d.in_sim and d.kind == "planner"):
                continue
            o = d.others
            long = (tuple(o.ids[i] for i in np.flatnonzero(o.length >= LONG_VEHICLE).tolist())
                    if o.n else ())
            mv = d.command(self.world.signals(d.ego, d.sc.sim.lookahead, near=YIELD_EDGE,
                                              long=long, planned=self.board,
                                              lane=d.last_lane))
            try:
                self.world.move(d.ego, mv.edge, mv.lane, mv.centre, mv.heading,
                                d.sc.ego.length, mv.speed)
            except SumoError as err:
                if not self.world.present(d.ego):
                    self._lost(d, err)
                    continue
                raise

    def _lost(self, d: Driver, err: BaseException | None = None) -> None:
        """A planned vehicle SUMO removed: an error for the single ego; with several, that
        vehicle fails (saying so) and the others drive on."""
        text = (f"ego vehicle '{d.ego}' left the simulation at t={self.time:.1f} s "
                "(removed by someone else)")
        if not self.multi:
            raise SimulationError(text) from err
        log.warning("%s", text)
        d.fail(f"SimulationError: {text}")
        d.in_sim = False
        self.world.release(d.ego)
        self.board.pop(d.ego, None)

    def _step(self) -> Any:
        try:
            events = self.world.step()
        except SumoError as err:
            for d in self.drivers:
                if d.in_sim and not self.world.present(d.ego):
                    raise SimulationError(
                        f"ego vehicle '{d.ego}' left the simulation at t={self.time:.1f} s "
                        "(removed by someone else)") from err
            raise
        self.sumo_collisions.extend(events.collisions)
        if events.teleported:
            self.teleports += len(events.teleported)
            for d in self.drivers:
                if d.ego in events.teleported:
                    d.teleports.append(self.time)
                    if self.multi and d.in_sim:
                        # SUMO moved it elsewhere: the plan no longer holds; SUMO drives it on
                        text = (f"teleported by SUMO at t={self.time:.1f} s on lane "
                                f"'{d.last_lane}' (its jam or collision rules)")
                        log.warning("vehicle '%s' %s", d.ego, text)
                        d.fail(text)
                        d.in_sim = False
                        self.world.release(d.ego)
                        self.board.pop(d.ego, None)
        return events

    def _enter(self, departed: tuple[str, ...]) -> None:
        if not departed:
            return
        for d in self.drivers:
            if d.in_sim or d.depart_time is not None or d.ego not in departed:
                continue
            ego = d.sc.ego
            self.world.take_control(d.ego,
                                    subscribe_range=d.sc.sim.lookahead + ego.length + 20.0,
                                    remote=d.kind == "planner")
            front, heading = self.world.pose(d.ego)
            d.enter(self.time, front, heading)
            self._join(d)
        if self.picker is None:
            return
        known = {d.ego for d in self.drivers}
        for vid in departed:
            if vid in known:
                continue
            edges, edge, pos, lane, type_id = self.world.route_of(vid)
            vt = self.world.type_of(type_id)
            if self.picker.picks(vid, type_id, vt["vclass"]):
                self._adopt(vid, edges, edge, pos, lane, vt)

    def _adopt(self, vid: str, edges: tuple[str, ...], edge: str, pos: float, lane: int,
               vt: dict[str, Any]) -> None:
        """Take over a vehicle SUMO has just inserted: its route's last edge is the goal."""
        from splineplan.scenario import EgoSpec

        sc = self.sc
        try:
            spec = EgoSpec(start_edge=edge, goal_edge=edges[-1], start_pos=pos,
                           start_lane=lane, vclass=vt["vclass"], length=vt["length"],
                           width=vt["width"], max_speed=vt["max_speed"], id=vid,
                           depart=self.time)
            d = Driver(sc.for_vehicle(spec), self.net, kind=self.kind,
                       out=_vehicle_dir(self.out, vid))
            d.route_from_sumo()
        except SplineplanError as err:
            self.unplanned[vid] = str(err)
            log.warning("t=%.1f vehicle '%s' is left to SUMO: %s", self.time, vid, err)
            return
        self.world.set_route(vid, list(d.route_edges))
        tp = d.sc.trajectory
        self.world.take_control(vid, subscribe_range=sc.sim.lookahead + spec.length + 20.0,
                                remote=d.kind == "planner",
                                limits=(tp.a_max, tp.b_max, EMERGENCY_FACTOR * tp.b_max))
        d.set_road(self._road(spec.vclass), self._polygons)
        front, heading = self.world.pose(vid)
        d.enter(self.time, front, heading, speed=self.world.speed(vid))
        self.drivers.append(d)
        self._join(d)

    def _join(self, d: Driver) -> None:
        """A planned vehicle entered: its priority is the order of entering; it shares the
        run's record of long vehicles' bodies."""
        d.priority = self._entered
        self._entered += 1
        d._body_paths, d._bodies_now = self._body_paths, self._bodies_now
        d._bodies_after = self._bodies_after
        if self.multi:
            d.board = self.board
            d.publish = True
            d.keep_plans = False  # no pictures; hundreds of vehicles' plans would pile up
            # SUMO's drivers see it on one lane only: keep to it where it can
            d.keep_lane = True
            d.keep_clear = True

    def _observe_all(self, arrived: tuple[str, ...]) -> None:
        for d in self.drivers:
            if not d.in_sim:
                continue
            if d.kind != "planner" and d.ego in arrived:
                d.arrived_by_sumo(self.time)
                continue
            st = self.world.state(d.ego)
            if st is None:
                self._lost(d)
                continue
            d.perceive(self.time, st, self.world.around(d.ego, d.sc.sim.stopped_speed))
            if d.status == "arrived":
                self.world.remove(d.ego)
                self.board.pop(d.ego, None)
                continue
            if d.kind == "planner":
                d.maybe_replan()
                if d.route_request is not None:
                    edges, d.route_request = d.route_request, None
                    self.world.set_route(d.ego, edges)
                self._publish(d)
        self._release_deadlocks()

    def _publish(self, d: Driver) -> None:
        """Put a driver's new plan on the board."""
        if d.published_plan is not None:
            self._published += 1
            self.board[d.ego] = Published(d.priority, d.published_plan, self._published)
            d.published_plan = None

    def _release_deadlocks(self) -> None:
        """Planned vehicles standing for :data:`DEADLOCK_WAIT` in a cycle, each held by
        the next (:func:`~.cooperate.waits_in_cycle`): the cycle is recorded once
        (``deadlocks``, with when it was found) and logged. Where one of them waits for the
        next one's published plan, that one stops waiting for it for :data:`RELEASE_FOR`
        and plans again: the plan it waits for cannot be driven while it stands in its
        way (its vehicle waits for a gap where it stands, or behind it); its speed control
        still sees that vehicle as SUMO's drivers see each other."""
        holds = {d.ego: d.slowed_by for d in self.drivers
                 if d.in_sim and d.kind == "planner" and d.slowed_by
                 and d.stand_since is not None
                 and self.time - d.stand_since >= DEADLOCK_WAIT - 1e-9}
        if len(holds) < 2:
            return
        for d in self.drivers:
            if d.ego not in holds:
                continue
            cycle = waits_in_cycle(holds, d.ego)
            if cycle is None or len(cycle) < 2:
                continue
            members = frozenset(cycle)
            if members not in self._cycles_seen:
                self._cycles_seen.add(members)
                chain = " -> ".join(f"'{v}'" for v in [*cycle, cycle[0]])
                why = {x.ego: x.why_slow for x in self.drivers if x.ego in members}
                self.deadlocks.append({"time": self.time, "vehicles": cycle,
                                       "why": [why[v] for v in cycle]})
                log.warning("t=%.1f planned vehicles stand in a cycle of waits: %s",
                            self.time, chain)
            if cycle[1] in d.waiting_for:
                d.release(cycle[1], self.time + RELEASE_FOR, cycle)
                self._publish(d)
                holds.pop(d.ego)

    # -- end ----------------------------------------------------------------------------------
    def fail(self, err: BaseException) -> None:
        reason = f"{type(err).__name__}: {sumo_message(err)}"
        self.status, self.reason = "failed", reason
        for d in self.drivers:
            if d.status in ("pending", "running"):
                d.fail(reason)

    def interrupt(self) -> None:
        """The user stopped the run (Ctrl-C)."""
        self.status = "interrupted"
        for d in self.drivers:
            if d.status in ("pending", "running"):
                d.interrupt(self.when())

    def when(self) -> str:
        """The simulation time reached, in words."""
        if self.world.started or self.time > 0.0:
            return f"at t={self.time:.1f} s"
        return "before the simulation started"

    def finish(self, *, plot: bool) -> SimResult:
        # SUMO may be running without `started` set, when Ctrl-C came as it started
        if self.multi and self.world.started:
            with contextlib.suppress(Exception):
                self.sizes = self.world.type_sizes()
        if self.world.sumo is not None and (self.world.started or self.status == "interrupted"):
            self.world.close()
        self.wall_time = time.perf_counter() - self.wall_start
        results = {d.ego: self._finish_driver(d) for d in self.drivers}
        result = next(iter(results.values())) if not self.multi else self._summary(results)
        if plot and not self.multi:
            try:
                _plot(self, result)
            except Exception as err:
                log.warning("plots failed: %s", err)
        return result

    def _finish_driver(self, d: Driver) -> SimResult:
        totals = RunTotals(self.time, self.sumo_collisions, self.teleports, self.wall_time,
                           self.world.seconds, d.plan_seconds)
        driven = driven_columns(d.rows)
        metrics = vehicle_metrics(d, driven, totals)
        if not self.multi:  # (with several, they are the run's: summary.json)
            metrics.update(self._sumo_ssm({d.ego}))
        out = d.out if d.out is not None else self.out
        write_vehicle(out, driven, metrics)
        return SimResult(d.status, d.reason, out, metrics, tuple(d.replans),
                         d.driven_before + d.route_edges, driven, tuple(d.plans))

    def _summary(self, results: dict[str, SimResult]) -> SimResult:
        from splineplan.closedloop.pairs import pair_safety
        from splineplan.closedloop.record import run_summary, write_json

        summary = run_summary(self, results)
        fcd = self.out / "fcd.xml"
        if fcd.is_file() and self.status != "interrupted":
            pairs: dict[str, Any] = {}
            try:
                pairs.update(pair_safety(fcd, self.sizes, results))
            except Exception as err:  # an FCD cut short (SUMO failed): no pair figures
                log.warning("no pairwise gaps from %s: %s", fcd, err)
            pairs.update(self._sumo_ssm(results))  # SUMO's own, beside ours
            if pairs:
                summary["pairs"] = pairs
        write_json(self.out / "summary.json", summary)
        return SimResult(summary["status"], summary["reason"], self.out, summary, (), (),
                         {}, (), vehicles=results)


    def _sumo_ssm(self, planned: Iterable[str]) -> dict[str, Any]:
        """SUMO's surrogate safety measures from the run's ``ssm.xml`` (none where SUMO did
        not write it, or not completely)."""
        path = self.out / ssm.FILE
        if not path.is_file():
            return {}
        try:
            return ssm.read_ssm(path, planned)
        except (OSError, ValueError, ET.ParseError) as err:
            log.warning("no surrogate safety measures from %s: %s", path, err)
            return {}


def _vehicle_dir(out: Path, vid: str) -> Path:
    """A planned vehicle's folder in the run's (its id, made safe as a file name)."""
    safe = "".join(c if c.isalnum() or c in "-_.#" else "_" for c in vid)
    return out / (safe or "_")


# ---- helpers ------------------------------------------------------------------------------

def _check_xml(path: Path) -> None:
    try:
        ET.parse(path)
    except ET.ParseError as err:
        raise SimulationError(f"SUMO input file {path} is not well-formed XML: {err}") from err


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

