"""The running SUMO simulation: the only module that imports ``libsumo`` (and ``traci``,
for ``sumo-gui``).

:class:`World` starts SUMO, steps it, reads each planned vehicle and the vehicles around it
once a step (one subscription per vehicle, all read in one call; no per-vehicle
getters), moves planned vehicles (``moveToXY`` at the front bumper, ``keepRoute=3``, and
``setSpeed``), sets routes, reads traffic lights and junction foes, and closes. Every error
SUMO raises reaches the caller as :class:`SumoError`.
"""

from __future__ import annotations

import contextlib
import math
import time
from collections.abc import Container
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from splineplan.errors import SimulationError
from splineplan.geometry import FloatArray, heading_from_sumo_angle, sumo_angle_from_heading
from splineplan.obstacles import Obstacles
from splineplan.traffic import NO_OTHERS, Others

#: ``moveToXY`` keepRoute: bit 1 maps onto the vehicle's route only, bit 2 keeps the exact x, y.
KEEP_ROUTE = 3
#: SUMO's link states without a traffic light at which a vehicle gives way to others
#: (minor, equal, stop sign): :meth:`World.signals` finds their foes itself too.
YIELD_STATES = "m=s"
#: How far [m] before such a link :meth:`World.signals` looks for those foes (the comfortable
#: stop from the city's speeds, and a few seconds more).
YIELD_LOOK = 50.0


class SumoError(SimulationError):
    """SUMO refused a command or failed (the one SUMO error type of the package)."""


@dataclass(frozen=True)
class StepEvents:
    """What happened in one SUMO step.

    Attributes
    ----------
    time
        Simulation time [s] after the step.
    collisions
        SUMO's collision reports (dicts: time, collider, victim, type, lane, pos).
    teleported
        Vehicles whose teleport started.
    departed, arrived
        Vehicles inserted in this step, and those that left the simulation at their
        route's end.
    """

    time: float
    collisions: tuple[dict[str, Any], ...]
    teleported: tuple[str, ...]
    departed: tuple[str, ...]
    arrived: tuple[str, ...]


@dataclass(frozen=True)
class VehicleState:
    """A planned vehicle as SUMO has it after a step (its subscription).

    Attributes
    ----------
    front
        Middle of the front bumper ``(2,)`` [m].
    angle
        SUMO's angle [deg], 0 = north, clockwise.
    speed
        [m/s].
    lane
        SUMO lane id.
    """

    front: tuple[float, float]
    angle: float
    speed: float
    lane: str


@dataclass(frozen=True)
class JunctionFoe:
    """A vehicle with which a planned vehicle shares a conflict area ahead
    (``vehicle.getJunctionFoes``), distances [m] along each one's way."""

    id: str
    ego_in: float
    foe_in: float
    ego_out: float
    foe_out: float
    must_yield: bool
    foe_speed: float
    foe_length: float
    foe_lane: str = ""  #: the foe's lane where the two meet (SUMO's ``foeLane``)
    foe_width: float = 0.0


@dataclass(frozen=True)
class LanePlace:
    """Where SUMO has a vehicle: its lane, its front's position on it [m] (SUMO's lane
    position), its speed [m/s], and the internal lane it approaches next (``""`` if none,
    or if it is on an internal lane)."""

    id: str
    lane: str
    pos: float
    speed: float
    via: str


@dataclass(frozen=True)
class Signals:
    """What lies ahead of a planned vehicle at junctions: traffic lights
    ``(id, link index, distance [m], state)`` in order, junction foes (``None``: SUMO
    cannot say, e.g. the vehicle is off its route), and where the long vehicles around
    it are on their lanes."""

    lights: tuple[tuple[Any, ...], ...] | None
    foes: tuple[JunctionFoe, ...] | None
    long: tuple[LanePlace, ...] = ()


def sumo_message(err: BaseException) -> str:
    """SUMO's message of an exception (libsumo's ``str()`` may be its repr only)."""
    msg = getattr(err, "message", None)
    if isinstance(msg, str) and msg:
        return msg
    text = str(err)
    if text.startswith("<libsumo"):
        return type(err).__name__
    return text


class World:
    """One running SUMO simulation (one per process with libsumo).

    ``seconds`` is the wall time [s] spent inside SUMO (start, steps, moves, reads, close).
    """

    def __init__(self, *, gui: bool = False) -> None:
        self.gui = gui
        self.sumo: Any = None
        self.started = False
        self.time = 0.0
        self.seconds = 0.0
        self.c: Any = None
        #: length and width [m] of each vehicle seen around a planned one (they do not
        #: change: read once, not with every step's results)
        self._sizes: dict[str, tuple[float, float]] = {}
        #: the search radius [m] round each planned vehicle (:meth:`around`)
        self._ranges: dict[str, float] = {}
        #: every vehicle's subscribed position, angle, speed and stop state, read once a
        #: step (:meth:`_snapshot`)
        self._snap_at = math.nan
        self._snap: tuple[dict[str, int], list[str], FloatArray] = ({}, [], np.zeros((0, 5)))
        #: the places read this step (:meth:`places`)
        self._places_at = math.nan
        self._places: dict[str, LanePlace] = {}
        #: per link (lane, lane it leads to): the incoming lanes with the right of way over
        #: it and the junction lanes that cross it (:meth:`_unreported_foes`)
        self._link_foes: dict[tuple[str, str], tuple[tuple[str, ...], frozenset[str]]] = {}
        #: lane lengths [m], and the length of a junction's lanes from each internal lane
        #: on [m]
        self._lengths: dict[str, float] = {}
        self._through: dict[str, float] = {}
        #: per planned vehicle and lane: the link at the lane's end where it gives way
        #: (the lane it leads to, its internal lane; empty where it need not)
        self._next_link: dict[tuple[str, str], tuple[str, str]] = {}
        #: the internal lane each vehicle on a lane takes next (:meth:`_via_of`)
        self._next_via: dict[tuple[str, str], str] = {}
        #: the vehicles on each lane asked for this step (:meth:`_unreported_foes`)
        self._on_lanes_at = math.nan
        self._on_lanes: dict[str, tuple[str, ...]] = {}

    # -- start and stop ------------------------------------------------------------------------
    def start(self, args: list[str], *, log_file: Path | None = None) -> None:
        """Start SUMO with command-line ``args`` (without the binary)."""
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
        cmd = [binary, *args]
        if self.gui:
            cmd += ["--start", "--quit-on-end"]
        self.sumo = sumo_mod
        t0 = time.perf_counter()
        try:
            sumo_mod.start(cmd)
        except Exception as err:
            _safe_close(sumo_mod)
            log_text = _tail(log_file) if log_file is not None else ""
            raise SumoError(sumo_message(err)
                            + (f"; SUMO says: {log_text}" if log_text else "")) from err
        self.started = True
        self.c = sumo_mod.constants
        self.seconds += time.perf_counter() - t0

    def close(self) -> None:
        """Close SUMO (its output files are complete afterwards); never raises."""
        if self.sumo is None:
            return
        t0 = time.perf_counter()
        _safe_close(self.sumo)
        self.seconds += time.perf_counter() - t0
        self.started = False

    # -- the static world ----------------------------------------------------------------------
    def junction_shapes(self) -> list[FloatArray]:
        """Outlines ``(n, 2)`` of the network's (non-internal) junctions."""
        s = self.sumo
        shapes = []
        for jid in s.junction.getIDList():
            if jid.startswith(":"):
                continue
            shape = np.asarray(s.junction.getShape(jid), dtype=float)
            if len(shape) >= 3:
                shapes.append(shape)
        return shapes

    def obstacle_polygons(self) -> Obstacles:
        """Polygons whose type starts with ``obstacle``, ids ``polygon:<id>``."""
        s = self.sumo
        polys, ids = [], []
        for pid in s.polygon.getIDList():
            if s.polygon.getType(pid).lower().startswith("obstacle"):
                shape = np.asarray(s.polygon.getShape(pid), dtype=float)
                if len(shape) >= 3:
                    polys.append(shape)
                    ids.append(f"polygon:{pid}")
        return Obstacles.from_polygons(polys, ids) if polys else Obstacles.empty()

    # -- vehicles ------------------------------------------------------------------------------
    def add_type(self, type_id: str, *, length: float, width: float, vclass: str,
                 max_speed: float, accel: float | None = None, decel: float | None = None,
                 emergency_decel: float | None = None,
                 color: tuple[int, int, int, int] = (255, 0, 0, 255)) -> None:
        """A vehicle type copied from SUMO's default, with these values."""
        vt = self.sumo.vehicletype
        vt.copy("DEFAULT_VEHTYPE", type_id)
        vt.setLength(type_id, length)
        vt.setWidth(type_id, width)
        vt.setVehicleClass(type_id, vclass)
        vt.setMaxSpeed(type_id, max_speed)
        if accel is not None:
            vt.setAccel(type_id, accel)
        if decel is not None:
            vt.setDecel(type_id, decel)
        if emergency_decel is not None:
            vt.setEmergencyDecel(type_id, emergency_decel)
        vt.setColor(type_id, color)

    def add_vehicle(self, vid: str, edges: list[str], *, type_id: str, depart: float,
                    depart_pos: float, depart_lane: int, arrival_pos: float | None = None
                    ) -> None:
        """Insert a vehicle on its own route ``<vid>_route``, departing at rest."""
        rid = f"{vid}_route"
        self.sumo.route.add(rid, list(edges))
        extra = {} if arrival_pos is None else {"arrivalPos": f"{arrival_pos:g}"}
        self.sumo.vehicle.add(vid, rid, typeID=type_id, depart=f"{depart:g}",
                              departPos=f"{depart_pos:g}", departLane=str(depart_lane),
                              departSpeed="0", **extra)

    def take_control(self, vid: str, *, subscribe_range: float, remote: bool,
                     limits: tuple[float, float, float] | None = None) -> None:
        """Subscribe to a planned vehicle and to the vehicles within ``subscribe_range`` [m]
        of it; ``remote``: switch off SUMO's own speed and lane-change control of it.
        ``limits``: its accel, decel, emergency decel [m/s²] (for a vehicle SUMO inserted
        with its own type)."""
        s, c = self.sumo, self.c
        # its own lane too; the others round it come from every vehicle's subscription
        # (:meth:`around`)
        s.vehicle.subscribe(vid, [*self._every(), c.VAR_LANE_ID])
        self._ranges[vid] = float(subscribe_range)
        if limits is not None:
            s.vehicle.setAccel(vid, limits[0])
            s.vehicle.setDecel(vid, limits[1])
            s.vehicle.setEmergencyDecel(vid, limits[2])
        if remote:
            s.vehicle.setSpeedMode(vid, 0)
            s.vehicle.setLaneChangeMode(vid, 0)

    def release(self, vid: str) -> None:
        """Stop following a vehicle as a planned one (it left, or is no longer planned): it
        keeps the subscription every vehicle has while it stays in the simulation."""
        self._ranges.pop(vid, None)
        with contextlib.suppress(Exception):
            if vid in self.sumo.vehicle.getIDList():  # still seen by the others
                self.sumo.vehicle.subscribe(vid, self._every())
            else:  # (a subscription to a vehicle that is gone fails the next step)
                self.sumo.vehicle.unsubscribe(vid)

    def pose(self, vid: str) -> tuple[FloatArray, float]:
        """Front bumper ``(2,)`` [m] and heading [rad] of a vehicle, read now."""
        front = np.asarray(self.sumo.vehicle.getPosition(vid), dtype=float)
        return front, float(heading_from_sumo_angle(self.sumo.vehicle.getAngle(vid)))

    def state(self, vid: str) -> VehicleState | None:
        """A subscribed vehicle after the step, ``None`` if it is no longer in SUMO."""
        t0 = time.perf_counter()
        s, c = self.sumo, self.c
        st = s.vehicle.getSubscriptionResults(vid)
        try:  # subscription results outlive a removal until the next step
            s.vehicle.getLaneID(vid)
        except Exception:
            st = None
        self.seconds += time.perf_counter() - t0
        if not st:
            return None
        fx, fy = st[c.VAR_POSITION]
        return VehicleState((fx, fy), st[c.VAR_ANGLE], st[c.VAR_SPEED], st[c.VAR_LANE_ID])

    def _every(self) -> list[int]:
        """The variables subscribed for every vehicle."""
        c = self.c
        return [c.VAR_POSITION, c.VAR_ANGLE, c.VAR_SPEED, c.VAR_STOPSTATE]

    def _snapshot(self) -> tuple[dict[str, int], list[str], FloatArray]:
        """Every vehicle's row index by id, the ids, and ``(n, 5)`` front bumper x, y [m],
        SUMO angle [deg], speed [m/s] and stop state, from one call a step (one
        subscription per vehicle instead of a context subscription per planned vehicle,
        which SUMO and the binding would fill for each planned vehicle apart)."""
        if self._snap_at != self.time:
            c = self.c
            t0 = time.perf_counter()
            res = self.sumo.vehicle.getAllSubscriptionResults()
            pos, ang, spd, stop = c.VAR_POSITION, c.VAR_ANGLE, c.VAR_SPEED, c.VAR_STOPSTATE
            ids = [v for v, r in res.items() if stop in r]
            rows = np.array([(*r[pos], r[ang], r[spd], r[stop])
                             for r in map(res.__getitem__, ids)],
                            dtype=float).reshape(len(ids), 5)
            self._snap = ({v: i for i, v in enumerate(ids)}, ids, rows)
            self._snap_at = self.time
            self.seconds += time.perf_counter() - t0
        return self._snap

    def _size(self, vid: str) -> tuple[float, float]:
        """A vehicle's length and width [m], read from SUMO the first time only."""
        size = self._sizes.get(vid)
        if size is None:
            veh = self.sumo.vehicle
            size = self._sizes[vid] = (float(veh.getLength(vid)), float(veh.getWidth(vid)))
        return size

    def around(self, vid: str, stopped_speed: float) -> Others:
        """The vehicles within the search radius of ``vid``'s front bumper (as SUMO's
        context subscription finds them), as arrays."""
        index, every, rows = self._snapshot()
        me = index.get(vid)
        if me is None or len(rows) < 2:
            return NO_OTHERS
        d = rows[:, :2] - rows[me, :2]
        near = np.flatnonzero((d[:, 0] ** 2 + d[:, 1] ** 2) <= self._ranges.get(vid, 0.0) ** 2)
        near = near[near != me]
        if not len(near):
            return NO_OTHERS
        ids = [every[j] for j in near]
        missing = [v for v in ids if v not in self._sizes]
        if missing:
            t1 = time.perf_counter()
            for v in missing:
                self._size(v)
            self.seconds += time.perf_counter() - t1
        size = np.array([self._sizes[v] for v in ids], dtype=float)
        sel = rows[near]
        a = np.column_stack((sel[:, :3], size, sel[:, 3:]))
        return Others(ids, a, stopped_speed)

    def signals(self, vid: str, lookahead: float, *, near: float = 0.0,
                long: tuple[str, ...] = (), planned: Container[str] = (),
                lane: str = "") -> Signals:
        """Traffic lights and junction foes ahead of ``vid`` within ``lookahead`` [m]: the
        foes it must yield to, farther than ``near`` [m] from their conflict area (those
        that ``getJunctionFoes`` leaves out found by :meth:`_unreported_foes`, except the
        ``planned`` vehicles, whose published plans time the meeting); and where the
        vehicles ``long`` are on their lanes (:meth:`places`). ``lane``: the lane SUMO
        has ``vid`` on, where the caller knows it."""
        s = self.sumo
        t0 = time.perf_counter()
        try:
            lights: tuple[tuple[Any, ...], ...] | None = tuple(s.vehicle.getNextTLS(vid))
        except Exception:
            lights = None
        foes: list[JunctionFoe] | None = []
        try:
            raw = s.vehicle.getJunctionFoes(vid, lookahead)
        except Exception:  # an older SUMO, or the vehicle not on its route
            raw = None
            foes = None
        for f in raw or ():
            if not f[7] or f[1] <= near:
                continue  # the vehicle has the way, or is at (or in) the area already
            try:
                v_f = s.vehicle.getSpeed(f[0])
                size = self._size(f[0])
            except Exception:
                continue
            assert foes is not None
            foes.append(JunctionFoe(f[0], f[1], f[2], f[3], f[4], bool(f[7]), v_f, size[0],
                                    str(f[6]), size[1]))
        if foes is not None:
            with contextlib.suppress(Exception):  # not on its route, or off the lanes
                foes.extend(self._unreported_foes(vid, lane, lookahead, near,
                                                  {f.id for f in foes}, planned))
        self.seconds += time.perf_counter() - t0
        return Signals(lights, None if foes is None else tuple(foes),
                       self.places(long) if long else ())

    def _unreported_foes(self, vid: str, lane: str, lookahead: float, near: float,
                         reported: set[str], planned: Container[str]) -> list[JunctionFoe]:
        """Vehicles that ``vid`` must give way to at the link at the end of its lane (one
        without a traffic light) and that ``getJunctionFoes`` leaves out: it misses the
        foes of some links altogether (SUMO 1.28; on the bundled city network, every foe
        of the links from ``D0C0`` at ``C0``), though SUMO's own drivers give way to them.
        They are the vehicles on the incoming lanes with the right of way over the link
        (``lane.getFoes``) whose next junction lane crosses it (``lane.getInternalFoes``).
        The whole junction counts as their conflict area, as in SUMO's own junction model:
        the distances are to the stop lines and on past the junction's lanes."""
        veh, lanes = self.sumo.vehicle, self.sumo.lane
        lane = lane or veh.getLaneID(vid)
        if not lane or lane.startswith(":"):
            return []
        link = self._next_link.get((vid, lane))
        if link is None:  # the link at the lane's end on the vehicle's route
            links = veh.getNextLinks(vid)
            link = self._next_link[(vid, lane)] = (
                (links[0][0], links[0][4]) if links and not links[0][1]
                and links[0][5] in YIELD_STATES and links[0][4] else ("", ""))
        to_lane, via = link
        if not via:
            return []  # it has the way there, or a traffic light says
        ego_in = self._length(lane) - float(veh.getLanePosition(vid))
        if ego_in > min(lookahead, YIELD_LOOK) or ego_in <= near:
            return []
        known = self._link_foes.get((lane, to_lane))
        if known is None:
            known = self._link_foes[(lane, to_lane)] = (
                tuple(dict.fromkeys(lanes.getFoes(lane, to_lane))),
                frozenset(lanes.getInternalFoes(via)))
        prior, crossing = known
        ego_out = ego_in + self._through_length(via)
        out = []
        if self._on_lanes_at != self.time:
            self._on_lanes_at, self._on_lanes = self.time, {}
        for foe_lane in prior:
            on = self._on_lanes.get(foe_lane)
            if on is None:
                on = self._on_lanes[foe_lane] = tuple(lanes.getLastStepVehicleIDs(foe_lane))
            inside = foe_lane.startswith(":")  # waiting inside, to turn left
            for v in on:
                if v == vid or v in reported or v in planned:
                    continue
                foe_via = foe_lane if inside else self._via_of(v, foe_lane)
                if foe_via not in crossing:
                    continue  # turns away from the link
                pos = float(veh.getLanePosition(v))
                foe_in = -pos if inside else self._length(foe_lane) - pos
                length, width = self._size(v)
                out.append(JunctionFoe(v, ego_in, foe_in, ego_out,
                                       foe_in + self._through_length(foe_via), True,
                                       float(veh.getSpeed(v)), length, foe_via, width))
        return out

    def _via_of(self, vid: str, lane: str) -> str:
        """The internal lane that vehicle ``vid`` on ``lane`` takes next, read from SUMO
        once per vehicle and lane (a reroute seldom changes the turn from the lane a
        vehicle is on)."""
        key = (vid, lane)
        via = self._next_via.get(key)
        if via is None:
            links = self.sumo.vehicle.getNextLinks(vid)
            via = self._next_via[key] = str(links[0][4]) if links else ""
        return via

    def _length(self, lane: str) -> float:
        """A lane's length [m], read from SUMO the first time only."""
        length = self._lengths.get(lane)
        if length is None:
            length = self._lengths[lane] = float(self.sumo.lane.getLength(lane))
        return length

    def _through_length(self, via: str) -> float:
        """Length [m] of a junction's lanes from internal lane ``via`` on to the lane after
        the junction (a left turn with a waiting place has two)."""
        total = self._through.get(via)
        if total is None:
            total, lane = 0.0, via
            for _ in range(8):
                total += self._length(lane)
                nxt = self.sumo.lane.getLinks(lane)
                if not nxt or not nxt[0][4]:
                    break
                lane = str(nxt[0][4])
            self._through[via] = total
        return total

    def places(self, vids: tuple[str, ...]) -> tuple[LanePlace, ...]:
        """Where SUMO has each of ``vids`` (read once a step, whichever planned vehicle
        asks; those no longer in SUMO left out)."""
        t0 = time.perf_counter()
        if self._places_at != self.time:
            self._places_at, self._places = self.time, {}
        veh, out = self.sumo.vehicle, []
        for vid in vids:
            place = self._places.get(vid)
            if place is None:
                try:
                    lane = veh.getLaneID(vid)
                    via = ""
                    if lane and not lane.startswith(":"):
                        links = veh.getNextLinks(vid)
                        via = links[0][4] if links else ""
                    place = LanePlace(vid, lane, float(veh.getLanePosition(vid)),
                                      float(veh.getSpeed(vid)), via)
                except Exception:
                    continue
                self._places[vid] = place
            if place.lane:
                out.append(place)
        self.seconds += time.perf_counter() - t0
        return tuple(out)

    def move(self, vid: str, edge: str, lane: int, centre: tuple[float, float], heading: float,
             length: float, speed: float) -> None:
        """Put a vehicle's centre at ``centre`` [m] with ``heading`` [rad] (``moveToXY`` of
        its front bumper, keepRoute 3) and set its speed [m/s] (else SUMO infers one from
        the move, measured along its lanes and capped by their speed limits)."""
        x, y = centre
        fx = x + length / 2.0 * math.cos(heading)
        fy = y + length / 2.0 * math.sin(heading)
        t0 = time.perf_counter()
        try:
            self.sumo.vehicle.moveToXY(vid, edge, lane, fx, fy, sumo_angle_from_heading(heading),
                                       KEEP_ROUTE)
            self.sumo.vehicle.setSpeed(vid, speed)
        except Exception as err:
            raise SumoError(f"SUMO refused to move vehicle '{vid}' at t={self.time:.1f} s: "
                            f"{sumo_message(err)}") from err
        finally:
            self.seconds += time.perf_counter() - t0

    def set_route(self, vid: str, edges: list[str]) -> None:
        """Give a vehicle a new route (its current edge first)."""
        self._next_link = {k: v for k, v in self._next_link.items() if k[0] != vid}
        try:
            self.sumo.vehicle.setRoute(vid, list(edges))
        except Exception as err:
            raise SumoError(f"SUMO refused the new route: {sumo_message(err)}") from err

    def remove(self, vid: str) -> None:
        """Take a vehicle out of the simulation, with its subscriptions (never raises)."""
        self._ranges.pop(vid, None)
        with contextlib.suppress(Exception):
            self.sumo.vehicle.unsubscribe(vid)
        with contextlib.suppress(Exception):
            self.sumo.vehicle.remove(vid)

    def route_of(self, vid: str) -> tuple[tuple[str, ...], str, float, int, str]:
        """A vehicle's route edges, its current edge, lane position [m], lane index and
        type id."""
        v = self.sumo.vehicle
        return (tuple(v.getRoute(vid)), v.getRoadID(vid), float(v.getLanePosition(vid)),
                int(v.getLaneIndex(vid)), v.getTypeID(vid))

    def type_of(self, type_id: str) -> dict[str, Any]:
        """Length, width [m], vehicle class and max speed [m/s] of a vehicle type."""
        vt = self.sumo.vehicletype
        return {"length": float(vt.getLength(type_id)), "width": float(vt.getWidth(type_id)),
                "vclass": vt.getVehicleClass(type_id),
                "max_speed": float(vt.getMaxSpeed(type_id))}

    def type_sizes(self) -> dict[str, tuple[float, float]]:
        """Length and width [m] of every vehicle type."""
        vt = self.sumo.vehicletype
        return {t: (float(vt.getLength(t)), float(vt.getWidth(t))) for t in vt.getIDList()}

    def loaded_types(self, vids: list[str]) -> dict[str, str]:
        """Type id of each loaded (not yet departed) vehicle id asked for."""
        v = self.sumo.vehicle
        out = {}
        for vid in vids:
            with contextlib.suppress(Exception):
                out[vid] = v.getTypeID(vid)
        return out

    def speed(self, vid: str) -> float:
        """A vehicle's speed [m/s], read now."""
        return float(self.sumo.vehicle.getSpeed(vid))

    def vehicle_ids(self) -> tuple[str, ...]:
        """The vehicles in the simulation now."""
        return tuple(self.sumo.vehicle.getIDList())

    def expected(self) -> int:
        """Vehicles in the simulation or still to come (``getMinExpectedNumber``)."""
        return int(self.sumo.simulation.getMinExpectedNumber())

    def loaded_ids(self) -> tuple[str, ...]:
        """Vehicles loaded and not yet departed."""
        return tuple(self.sumo.simulation.getPendingVehicles())

    # -- stepping ------------------------------------------------------------------------------
    def step(self) -> StepEvents:
        """One simulation step."""
        s = self.sumo
        t0 = time.perf_counter()
        try:
            s.simulationStep()
        except Exception as err:
            raise SumoError(f"SUMO failed at t={self.time:.1f} s: {sumo_message(err)}") from err
        self.time = float(s.simulation.getTime())
        departed = tuple(s.simulation.getDepartedIDList())
        # on the road again after a teleport: subscribed again (one no longer planned may
        # have been released while away)
        back = (*departed, *s.simulation.getEndingTeleportIDList())
        if back:
            # (a subscription to a vehicle that is gone again fails the next step)
            present = set(s.vehicle.getIDList())
            every = self._every()
            for vid in back:
                if vid in present and vid not in self._ranges:
                    s.vehicle.subscribe(vid, every)
        collisions = tuple({"time": self.time, "collider": c.collider, "victim": c.victim,
                            "type": c.type, "lane": c.lane, "pos": c.pos}
                           for c in s.simulation.getCollisions())
        events = StepEvents(self.time, collisions,
                            tuple(s.simulation.getStartingTeleportIDList()),
                            departed,
                            tuple(s.simulation.getArrivedIDList()))
        self.seconds += time.perf_counter() - t0
        return events

    def present(self, vid: str) -> bool:
        """Whether a vehicle is in the simulation now."""
        return vid in self.sumo.vehicle.getIDList()


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


def _safe_close(sumo_mod: Any) -> None:
    with contextlib.suppress(Exception):
        sumo_mod.close()


def _tail(path: Path, n: int = 3) -> str:
    try:
        lines = [ln.strip() for ln in path.read_text().splitlines() if ln.strip()]
    except OSError:
        return ""
    return " | ".join(lines[-n:])
