"""CommonRoad scenarios in, solutions out (the optional extra ``splineplan[commonroad]``).

A CommonRoad scenario holds a lanelet network, static and dynamic obstacles and a planning
problem: an initial state and a goal region (a position or goal lanelets, a time window, a
speed and an orientation interval, each optional). :func:`plan` solves it with splineplan's
three levels:

1. Level 1 (the paper's Dijkstra) on a lanelet graph: an arc to each successor (cost: the
   lanelet's length) and to each same-direction neighbour (a lane change, cost
   :data:`LANE_CHANGE_COST`), to any goal lanelet (:func:`lanelet_route`). A goal with a time
   window only follows the straightest successors far enough for it.
2. The corridor (:func:`route_corridor`): along the route, each lanelet with its
   same-direction neighbours; where a static obstacle leaves the route's lanes no passage,
   the oncoming lane beside them is added as passing space. Static obstacles go to level 2.
3. Level 3 with the vehicle as CommonRoad models it (:class:`Vehicle`: the kinematic
   single-track model's wheelbase, steering angle and rate limits; BMW 320i, vehicle
   type 2, by default). Dynamic obstacles (their trajectories are known) are handled by
   :func:`splineplan.spacetime.retime` (speed first), and where speed alone cannot keep the
   margin by planning the path again around the obstacle where the conflict lies.
4. The goal: the speed is capped (the highest cap that works) so that the car is in the
   goal region inside its time window with its speed and orientation; the solution ends at
   the first state that reaches the goal (CommonRoad's own ``GoalRegion.is_reached``).

The solution is written in CommonRoad's solution format (:func:`write_solution`) as KS
states: the planner's centre path is converted to the single-track model's state
(:func:`ks_states`). Everything from commonroad-io is imported inside the functions, so that
the package works without the extra; without it they raise one clear error.
"""

from __future__ import annotations

import contextlib
import functools
import logging
import math
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from splineplan.corridor import UNBOUNDED, Corridor
from splineplan.errors import (
    GeometryError,
    NoRouteError,
    ParameterError,
    RoadBlockedError,
    ScenarioError,
    SplineplanError,
)
from splineplan.geometry import FloatArray, dedupe_polyline, wrap_angle
from splineplan.obstacles import Obstacles
from splineplan.roadmap import RoadmapParams
from splineplan.speed import speed_profile, steady_slip
from splineplan.trajectory import Trajectory, TrajectoryParams, _times, speed_limit

log = logging.getLogger(__name__)

#: Cost [m] of a lane change in level 1: a lane change is preferred to a detour longer
#: than this.
LANE_CHANGE_COST = 15.0
#: CommonRoad's vehicle types (``commonroad.common.solution.VehicleType``).
VEHICLE_TYPES = {1: "FORD_ESCORT", 2: "BMW_320i", 3: "VW_VANAGON"}
#: Time step [s] of the integration that turns the centre path into the car's body
#: (:func:`ks_states`).
TOW_STEP = 0.002
#: Slip angle [rad] at the start above which the path is planned again from the centre's
#: direction (the body's orientation plus the slip, see :func:`plan`).
SLIP_REPLAN = 0.02
#: How far inside the goal's speed [m/s] and orientation [rad] intervals the planner's
#: approximate states must be for the goal to count as reached: the solution's states (the
#: rear axle's speed, the towed body's orientation) differ from them by about that much.
REACH_INSET = (0.05, 0.01)
#: Longest time [s] ahead over which a profile meeting the goal (:meth:`_Timing.meet`) is
#: sought, and how many steps of the goal's time window it tries.
MEET_HORIZON = 20.0
MEET_STEPS = 6
#: How many stations of the goal's a meeting profile tries per time step and speed.
MEET_STATIONS = 5
#: Lowest speed cap [m/s] tried to meet a goal's time window.
MIN_CAP = 0.5
#: Cost function named in the solutions (CommonRoad's ``SM1``: acceleration, jerk, lane
#: deviation, path length, time).
COST_FUNCTION = "SM1"
#: Braking [m/s^2] planned with: a hard stop on a dry road (CommonRoad's KS model allows
#: up to its ``a_max``, 11.5 m/s^2 for the BMW); splineplan's 4 m/s^2 is a comfortable stop.
BRAKING = 8.0
#: Margin [m] kept from moving obstacles by the space-time speed plan. A scenario's
#: dynamic obstacles drive a recorded future exactly, and the occupancy is already widened
#: by a time step and a path sample each side; the margin covers the few centimetres by
#: which CommonRoad's body (centred ``b`` ahead of the rear axle, turned by the slip
#: angle) lies beside the planner's. 0.5 m kept the car from goals that a recorded car
#: reached just behind a cyclist (RUS_Bicycle-4_1, -4_2, -6_1); 0.15 m let a car turning
#: at a junction touch one turning beside it (DEU_Muc-8_2).
MOVING_MARGIN = 0.2
#: How far [m] beyond the goal the corridor runs (the goal lanelets' successors), so
#: that the curve does not end on the goal's edge.
RUN_ON = 40.0
#: How far inside the goal's lateral extent [m] the vehicle's centre keeps where it passes
#: the goal (see :func:`goal_keep`), and how fast that band widens away from it [m/m].
GOAL_INSET = 0.2
GOAL_TAPER = 0.15


def _require() -> None:
    """Raise one clear error when the CommonRoad extra is missing."""
    try:
        import commonroad  # noqa: F401
    except ImportError as err:
        raise SplineplanError("CommonRoad support needs the commonroad extra: "
                              "pip install 'splineplan[commonroad]'") from err


# -- the vehicle --------------------------------------------------------------------------
@dataclass(frozen=True)
class Vehicle:
    """A CommonRoad vehicle type as the kinematic single-track (KS) model sees it.

    Attributes
    ----------
    type_id
        CommonRoad's vehicle type (1 Ford Escort, 2 BMW 320i, 3 VW Vanagon).
    length, width
        The body [m].
    wheelbase
        Front to rear axle [m] (``a + b``).
    b
        Rear axle to the centre of gravity [m]: the KS state's position lies there.
    max_steering_angle, max_steering_rate
        Front-wheel limits [rad], [rad/s].
    a_max, v_max
        Largest acceleration [m/s^2] and speed [m/s].
    v_switch
        Speed [m/s] above which the largest acceleration falls as ``a_max v_switch / v``
        (the engine's power).
    """

    type_id: int
    length: float
    width: float
    wheelbase: float
    b: float
    max_steering_angle: float
    max_steering_rate: float
    a_max: float
    v_max: float
    v_switch: float = math.inf

    @property
    def name(self) -> str:
        """CommonRoad's name of the type (``BMW_320i``)."""
        return VEHICLE_TYPES[self.type_id]

    @property
    def reference_ahead(self) -> float:
        """How far [m] CommonRoad's reference point (``b`` ahead of the rear axle) lies
        ahead of the planner's centre (half the wheelbase ahead of it), along the body."""
        return self.b - self.wheelbase / 2.0

    def trajectory_params(self, s_max: float) -> TrajectoryParams:
        """Level 3's parameters for this car at top speed ``s_max`` [m/s]: its wheelbase and
        steering rate, and a turning radius no tighter than its steering angle allows
        (nor than splineplan's default kerb-to-kerb circle)."""
        rear = self.wheelbase / math.tan(self.max_steering_angle)
        centre = math.hypot(rear, self.wheelbase / 2.0)
        base = TrajectoryParams()
        return replace(base, s_max=float(min(s_max, self.v_max)), wheelbase=self.wheelbase,
                       max_steering_rate=self.max_steering_rate,
                       min_turn_radius=max(centre, base.min_turn_radius),
                       a_max=min(base.a_max, self.a_max), b_max=BRAKING, road_margin=0.1)

    def roadmap_params(self) -> RoadmapParams:
        """Level 2's parameters for this car's body. The corridor is already the route's
        own lanes, shifting at a lane change: level 2 keeps the paper's midpoints there
        (``place=False``), which spread the lane change over the corridor's shift; placed
        for a lane's centre, the vertices held the old lane and changed late (USA_US101-16
        then missed its goal)."""
        return RoadmapParams(vehicle_length=self.length, vehicle_width=self.width,
                             place=False)


@functools.lru_cache(maxsize=8)
def vehicle(type_id: int) -> Vehicle:
    """CommonRoad's parameters of vehicle type ``type_id`` (from commonroad-vehicle-models)."""
    if isinstance(type_id, bool) or type_id not in VEHICLE_TYPES:
        known = ", ".join(f"{k} ({v})" for k, v in VEHICLE_TYPES.items())
        raise ParameterError(f"unknown vehicle type {type_id!r}; CommonRoad's are {known}")
    _require()
    try:
        import vehiclemodels.parameters_vehicle1 as p1
        import vehiclemodels.parameters_vehicle2 as p2
        import vehiclemodels.parameters_vehicle3 as p3
    except ImportError as err:
        raise SplineplanError("CommonRoad support needs the commonroad extra: "
                              "pip install 'splineplan[commonroad]'") from err
    p = {1: p1.parameters_vehicle1, 2: p2.parameters_vehicle2,
         3: p3.parameters_vehicle3}[type_id]()
    return Vehicle(type_id, float(p.l), float(p.w), float(p.a + p.b), float(p.b),
                   float(p.steering.max), float(p.steering.v_max),
                   float(p.longitudinal.a_max), float(p.longitudinal.v_max),
                   float(p.longitudinal.v_switch))


# -- reading ------------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class Problem:
    """A scenario and the planning problem to solve in it (commonroad-io objects)."""

    scenario: Any
    planning_problem: Any
    source: str

    @property
    def dt(self) -> float:
        """The scenario's time step [s]."""
        return float(self.scenario.dt)


def read(path: str | Path, *, planning_problem_id: int | None = None) -> Problem:
    """Read a CommonRoad scenario file and one of its planning problems (the first, or
    ``planning_problem_id``)."""
    _require()
    import warnings
    from xml.etree.ElementTree import ParseError

    from commonroad.common.file_reader import CommonRoadFileReader

    p = Path(path)
    if not p.exists():
        raise ScenarioError(f"scenario file not found: {p}")
    if p.is_dir():
        raise ScenarioError(f"{p} is a folder, not a CommonRoad scenario file")
    head = p.read_bytes()[:4096].lower()
    if b"<commonroad" not in head:
        raise ScenarioError(f"{p} is not a CommonRoad scenario (no <commonRoad> root element)")
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            logging.getLogger("commonroad").setLevel(logging.ERROR)
            scenario, problems = CommonRoadFileReader(str(p)).open()
    except (ParseError, ValueError, KeyError, AttributeError, TypeError, AssertionError) as err:
        raise ScenarioError(f"cannot read CommonRoad scenario {p}: {err}") from err
    pps = problems.planning_problem_dict
    if not pps:
        raise ScenarioError(f"{p} holds no planning problem: nothing to solve")
    if planning_problem_id is None:
        pp = pps[sorted(pps)[0]]
    elif planning_problem_id in pps:
        pp = pps[planning_problem_id]
    else:
        raise ScenarioError(f"{p} has no planning problem {planning_problem_id} (it has "
                            f"{', '.join(map(str, sorted(pps)))})")
    return Problem(scenario, pp, str(p))


# -- level 1 ------------------------------------------------------------------------------
@dataclass(frozen=True)
class LaneletRoute:
    """Level 1's result on a lanelet network.

    Attributes
    ----------
    lanelets
        Lanelet ids in the order driven; consecutive ones are successors or (a lane change)
        same-direction neighbours.
    chain
        The lanelets one after another along the road: each lane change's first lanelet is
        left out (its neighbour stands for the same stretch of road).
    length
        Length [m] of the chain.
    lane_changes
        Number of lane changes.
    """

    lanelets: tuple[int, ...]
    chain: tuple[int, ...]
    length: float
    lane_changes: int


@dataclass(frozen=True)
class _Side:
    """A lanelet's neighbour on one side: its id (``None``: none) and whether it runs the
    same way."""

    id: int | None
    same: bool


#: Distance [m] within which a boundary's ends meet another lanelet's boundary's ends for
#: the two to count as neighbours where the scenario links none.
SHARED_BOUNDARY = 0.3


def _neighbours(network: Any) -> dict[int, tuple[_Side, _Side]]:
    """Each lanelet's left and right neighbour: as the scenario links them, and where it
    links none, the lanelet whose boundary has the same ends (some recorded scenarios
    leave parallel lanes unlinked)."""
    cached = getattr(network, "_splineplan_neighbours", None)
    if cached is not None:
        return cached  # type: ignore[no-any-return]
    lls = list(network.lanelets)
    ends = {ll.lanelet_id: (ll.left_vertices[[0, -1]], ll.right_vertices[[0, -1]])
            for ll in lls}
    out: dict[int, tuple[_Side, _Side]] = {}
    for ll in lls:
        sides = []
        for adj, same, mine, k in ((ll.adj_left, ll.adj_left_same_direction, 0, 1),
                                   (ll.adj_right, ll.adj_right_same_direction, 1, 0)):
            if adj is not None:
                sides.append(_Side(int(adj), bool(same)))
                continue
            here = ends[ll.lanelet_id][mine]
            found = _Side(None, True)
            for other in lls:
                if other is ll:
                    continue
                theirs = ends[other.lanelet_id]
                if np.all(np.hypot(*(here - theirs[k]).T) < SHARED_BOUNDARY):
                    found = _Side(int(other.lanelet_id), True)
                    break
                if np.all(np.hypot(*(here - theirs[mine][::-1]).T) < SHARED_BOUNDARY):
                    found = _Side(int(other.lanelet_id), False)
                    break
            sides.append(found)
        out[ll.lanelet_id] = (sides[0], sides[1])
    with contextlib.suppress(AttributeError):  # a network that takes no attributes
        network._splineplan_neighbours = out
    return out


def _lanelet_graph(network: Any) -> tuple[list[int], dict[int, int], list[list[tuple[int, float]]]]:
    """Lanelet ids, their indices, and the arcs ``(to, cost)`` of each (see the module
    docstring)."""
    ids = [ll.lanelet_id for ll in network.lanelets]
    index = {lid: i for i, lid in enumerate(ids)}
    adjacency: list[list[tuple[int, float]]] = [[] for _ in ids]
    for ll in network.lanelets:
        i = index[ll.lanelet_id]
        length = float(ll.distance[-1])
        for nxt in ll.successor:
            if nxt in index:
                adjacency[i].append((index[nxt], length))
        for side in _neighbours(network)[ll.lanelet_id]:
            if side.id is not None and side.same and side.id in index:
                adjacency[i].append((index[side.id], LANE_CHANGE_COST))
    return ids, index, adjacency


def lanelet_route(network: Any, start: Sequence[int], goals: Sequence[int]) -> LaneletRoute:
    """Least-cost lanelet route from any of ``start`` to any of ``goals`` (ids).

    splineplan's Dijkstra (:func:`splineplan.route.dijkstra`) on the lanelet graph with a
    virtual source before the starts and a virtual target after the goals.
    """
    from splineplan.route import dijkstra

    ids, index, adjacency = _lanelet_graph(network)
    n = len(ids)
    source, target = n, n + 1
    adjacency = [*adjacency, [(index[s], 0.0) for s in start if s in index], []]
    for g in goals:
        if g in index:
            adjacency[index[g]] = [*adjacency[index[g]], (target, 0.0)]
    path = dijkstra(adjacency, source, target)
    if path is None:
        raise NoRouteError(
            f"no lanelet route from lanelet {', '.join(map(str, start))} to goal lanelet "
            f"{', '.join(map(str, goals))}: the goal cannot be reached along successors and "
            "lane changes")
    return _route_of(network, [ids[i] for i in path[1:-1]])


def _route_of(network: Any, lanelets: list[int]) -> LaneletRoute:
    chain: list[int] = []
    changes = 0
    for lid in lanelets:
        if chain and _same_direction_neighbour(network, chain[-1], lid):
            chain[-1] = lid
            changes += 1
        else:
            chain.append(lid)
    length = sum(float(network.find_lanelet_by_id(lid).distance[-1]) for lid in chain)
    return LaneletRoute(tuple(lanelets), tuple(chain), length, changes)


def _same_direction_neighbour(network: Any, a: int, b: int) -> bool:
    return any(side.id == b and side.same for side in _neighbours(network)[a])


def follow_road(network: Any, start: int, length: float) -> LaneletRoute:
    """The lanelets from ``start`` along the straightest successors until ``length`` [m]
    (or the road's end): the route of a goal that is a time window only."""
    out = [start]
    total = float(network.find_lanelet_by_id(start).distance[-1])
    while total < length:
        ll = network.find_lanelet_by_id(out[-1])
        options = [s for s in ll.successor if s not in out]
        if not options:
            break
        head = _end_heading(ll.center_vertices)

        def turn(lid: int, head: float = head) -> float:
            c = network.find_lanelet_by_id(lid).center_vertices
            return abs(float(wrap_angle(_end_heading(c[::-1]) + math.pi - head)))

        nxt = min(options, key=turn)
        out.append(nxt)
        total += float(network.find_lanelet_by_id(nxt).distance[-1])
    return _route_of(network, out)


def _end_heading(points: FloatArray) -> float:
    d = points[-1] - points[max(len(points) - 3, 0)]
    return math.atan2(float(d[1]), float(d[0]))


# -- level 2's input ----------------------------------------------------------------------
def _group(network: Any, lid: int) -> list[Any]:
    """The lanelet and its same-direction neighbours, from the leftmost to the rightmost."""
    ll = network.find_lanelet_by_id(lid)
    left: list[Any] = []
    cur = ll
    sides = _neighbours(network)
    while sides[cur.lanelet_id][0].id is not None and sides[cur.lanelet_id][0].same:
        cur = network.find_lanelet_by_id(sides[cur.lanelet_id][0].id)
        if cur in left or cur is ll:
            break
        left.append(cur)
    right: list[Any] = []
    cur = ll
    while sides[cur.lanelet_id][1].id is not None and sides[cur.lanelet_id][1].same:
        cur = network.find_lanelet_by_id(sides[cur.lanelet_id][1].id)
        if cur in right or cur is ll:
            break
        right.append(cur)
    return [*left[::-1], ll, *right]


def _oncoming(network: Any, leftmost: Any) -> Any | None:
    """The oncoming lanelet beside a group's leftmost lanelet, if any."""
    side = _neighbours(network)[leftmost.lanelet_id][0]
    if side.id is not None and not side.same:
        return network.find_lanelet_by_id(side.id)
    return None


def route_corridor(network: Any, route: LaneletRoute, obstacles: Obstacles, *,
                   passing: bool = False, keep_lanes: bool = True) -> Corridor:
    """The corridor along ``route.chain``: each lanelet with its same-direction neighbours.

    The reference line is the chain's lanes joined, where possible each section's lane
    the successor of the previous one (so that it stays in one lane across the sections
    of a lane change). With ``passing``, where a static obstacle stands on the lanes of a
    section, the oncoming lane beside them is added (passing space: :func:`plan` asks for
    it when the route's lanes are blocked). With ``keep_lanes``, the vehicle's centre
    keeps to the route's own lanelets in each section (both lanes of a lane change; the
    corridor's keep offsets): level 2 plans among static obstacles only, and its widest
    path would otherwise take the middle of a multi-lane road, across the lane of the
    traffic beside; around where those lanes are blocked, level 2 uses the whole road
    (:func:`splineplan.roadmap.plan_roadmap`)."""
    on_route = set(route.lanelets)
    sections = [_group(network, lid) for lid in route.chain]
    # the reference lane of each section: the previous reference's successor where it is in
    # the section, else the chain's lanelet
    refs: list[Any] = []
    for lid, group in zip(route.chain, sections, strict=True):
        own = network.find_lanelet_by_id(lid)
        if refs:
            succ = [g for g in group if g.lanelet_id in refs[-1].successor]
            own = succ[0] if succ and own not in succ else own
        refs.append(own)
    reference = dedupe_polyline(np.concatenate([r.center_vertices for r in refs]), 1e-3)
    probe = Corridor.from_reference(reference, np.full(len(reference), 1e3),
                                    np.full(len(reference), -1e3))
    left = np.full(len(probe.s), -np.inf)
    right = np.full(len(probe.s), np.inf)
    keep_l = np.full(len(probe.s), UNBOUNDED)
    keep_r = np.full(len(probe.s), -UNBOUNDED)
    # each section's station window on the reference: its reference lane's ends
    ends_xy = np.array([r.center_vertices[-1] for r in refs])
    ends = probe.to_sl(ends_xy)[:, 0]
    lo = 0.0
    for i, group in enumerate(sections):
        hi = float(ends[i]) if i + 1 < len(refs) else float(probe.length)
        hi = max(hi, lo + 1e-3)
        lanes = list(group)
        onc = _oncoming(network, group[0])
        if passing and onc is not None and _touched(group, obstacles):
            lanes = [onc, *lanes]
        lb = group[0].left_vertices if lanes[0] is group[0] else lanes[0].right_vertices[::-1]
        rb = group[-1].right_vertices
        window = (probe.s >= lo - 1.0) & (probe.s <= hi + 1.0)
        for line, out, pick in ((lb, left, np.maximum), (rb, right, np.minimum)):
            sl = _project(probe, line)
            inside = (sl[:, 0] >= lo - 2.0) & (sl[:, 0] <= hi + 2.0)
            if inside.sum() < 2:
                continue
            order = np.argsort(sl[inside, 0])
            vals = np.interp(probe.s[window], sl[inside, 0][order], sl[inside, 1][order])
            out[window] = pick(out[window], vals)
        if keep_lanes:
            mine = [g for g in group if g.lanelet_id in on_route] or [
                network.find_lanelet_by_id(route.chain[i])]
            for line, arr, pick in ((mine[0].left_vertices, keep_l, np.maximum),
                                    (mine[-1].right_vertices, keep_r, np.minimum)):
                sl = _project(probe, line)
                o = np.argsort(sl[:, 0])
                vals = np.interp(probe.s[window], sl[o, 0], sl[o, 1])
                arr[window] = np.where(np.abs(arr[window]) >= UNBOUNDED, vals,
                                       pick(arr[window], vals))
        lo = hi
    bad = ~np.isfinite(left) | ~np.isfinite(right)
    if bad.all():
        raise GeometryError(f"lanelet route {' '.join(map(str, route.chain))} has no width")
    idx = np.arange(len(left))
    good = ~bad
    left = np.interp(idx, idx[good], left[good])
    right = np.interp(idx, idx[good], right[good])
    right = np.minimum(right, left - 0.5)
    keeps = (None, None)
    if keep_lanes and np.any(keep_l < UNBOUNDED):
        keeps = (np.minimum(keep_l, left), np.maximum(keep_r, right))
    ids = tuple(str(lid) for lid in route.chain)
    return Corridor(probe.reference, probe.s, left, right, ids, _section_starts(ends),
                    0.0, keeps[0], keeps[1])


def _section_starts(ends: FloatArray) -> FloatArray:
    return np.maximum.accumulate(np.concatenate(([0.0], np.clip(ends[:-1], 0.0, None))))


def _project(probe: Corridor, line: ArrayLike) -> FloatArray:
    from splineplan.geometry import resample_polyline

    pts = resample_polyline(dedupe_polyline(np.asarray(line, dtype=float), 1e-3), 0.5)
    return probe.to_sl(pts)


def _touched(group: list[Any], obstacles: Obstacles) -> bool:
    """Whether a static obstacle lies on (or touches) the group's lanes."""
    if not len(obstacles):
        return False
    from shapely import Polygon, unary_union

    road = unary_union([g.polygon.shapely_object for g in group])
    return any(road.intersects(Polygon(p)) for p in obstacles.polygons())


def static_obstacles(scenario: Any) -> Obstacles:
    """The scenario's static obstacles as polygons (ids as strings)."""
    polys, ids = [], []
    for ob in scenario.static_obstacles:
        for k, poly in enumerate(_shape_polygons(ob.obstacle_shape.rotate_translate_local(
                ob.initial_state.position, ob.initial_state.orientation))):
            polys.append(poly)
            ids.append(str(ob.obstacle_id) + (f".{k}" if k else ""))
    return Obstacles.from_polygons(polys, ids) if polys else Obstacles.empty()


def _shape_polygons(shape: Any) -> list[FloatArray]:
    """Polygons ``(k, 2)`` of a CommonRoad shape (a shape group: one per member)."""
    if hasattr(shape, "shapes"):
        return [p for s in shape.shapes for p in _shape_polygons(s)]
    if hasattr(shape, "vertices"):
        return [np.asarray(shape.vertices, dtype=float)]
    if hasattr(shape, "radius"):
        a = np.linspace(0.0, 2.0 * math.pi, 16, endpoint=False)
        return [np.asarray(shape.center) + shape.radius * np.column_stack((np.cos(a),
                                                                          np.sin(a)))]
    raise GeometryError(f"CommonRoad shape {type(shape).__name__} is not supported")


def moving_obstacles(scenario: Any) -> list[Any]:
    """The scenario's dynamic obstacles with a known trajectory as
    :class:`splineplan.spacetime.MovingObstacle` (absolute times [s])."""
    from splineplan.spacetime import MovingObstacle

    out = []
    dt = float(scenario.dt)
    for ob in scenario.dynamic_obstacles:
        shape = ob.obstacle_shape
        length = float(getattr(shape, "length", 2.0 * getattr(shape, "radius", 1.0)))
        width = float(getattr(shape, "width", 2.0 * getattr(shape, "radius", 1.0)))
        states = [ob.initial_state]
        pred = ob.prediction
        if pred is not None and hasattr(pred, "trajectory"):
            states += list(pred.trajectory.state_list)
        states = [s for s in states if hasattr(s, "position") and hasattr(s, "orientation")]
        if len(states) < 2:
            continue
        t = np.array([s.time_step * dt for s in states], dtype=float)
        xy = np.array([s.position for s in states], dtype=float)
        head = np.array([s.orientation for s in states], dtype=float)
        keep = np.concatenate(([True], np.diff(t) > 0))
        out.append(MovingObstacle(str(ob.obstacle_id), t[keep], xy[keep], head[keep],
                                  length, width))
    return out


# -- the goal -----------------------------------------------------------------------------
@dataclass(frozen=True)
class Goal:
    """A planning problem's goal region, each part optional.

    Attributes
    ----------
    steps
        Time-step window ``(lo, hi)`` (CommonRoad's time steps).
    shapes
        shapely geometries of each goal state's position (``None``: anywhere).
    speed, orientation
        Per goal state: ``(lo, hi)`` [m/s], [rad], or ``None``.
    lanelets
        Goal lanelet ids (from the goal's lanelets or the lanelets its position touches).
    """

    steps: tuple[tuple[int, int], ...]
    shapes: tuple[Any, ...]
    speed: tuple[tuple[float, float] | None, ...]
    orientation: tuple[tuple[float, float] | None, ...]
    lanelets: tuple[int, ...]

    def reached(self, step: FloatArray, xy: FloatArray, heading: FloatArray,
                speed: FloatArray, *, inset: tuple[float, float] = (0.0, 0.0)) -> FloatArray:
        """Whether states (time steps, positions ``(n, 2)`` [m], orientations [rad],
        speeds [m/s]) reach the goal: ``(n,)`` booleans (any of the goal states). ``inset``
        narrows the speed [m/s] and orientation [rad] intervals by that much each side
        (for states that approximate the solution's)."""
        out = np.zeros(len(step), dtype=bool)
        for k in range(len(self.steps)):
            ok = (step >= self.steps[k][0]) & (step <= self.steps[k][1])
            if self.shapes[k] is not None:
                ok &= _contains(self.shapes[k], xy)
            if self.speed[k] is not None:
                lo, hi = self.speed[k]  # type: ignore[misc]
                ok &= (speed >= lo + inset[0]) & (speed <= hi - inset[0])
            if self.orientation[k] is not None:
                lo, hi = self.orientation[k]  # type: ignore[misc]
                mid = (lo + hi) / 2.0
                ok &= np.abs(wrap_angle(heading - mid)) <= (hi - lo) / 2.0 - inset[1]
            out |= ok
        return out

    @property
    def has_position(self) -> bool:
        """Whether any goal state has a position."""
        return any(s is not None for s in self.shapes)

    def inside(self, xy: FloatArray) -> NDArray[np.bool_]:
        """Whether points ``(n, 2)`` [m] lie in a goal position (all, without one)."""
        if not self.has_position:
            return np.ones(len(xy), dtype=bool)
        out = np.zeros(len(xy), dtype=bool)
        for shape in self.shapes:
            if shape is not None:
                out |= _contains(shape, xy)
        return out


def goal_of(problem: Problem) -> Goal:
    """The planning problem's goal region (:class:`Goal`)."""
    from shapely import unary_union

    goal = problem.planning_problem.goal
    net = problem.scenario.lanelet_network
    steps: list[tuple[int, int]] = []
    shapes: list[Any] = []
    speeds: list[tuple[float, float] | None] = []
    orients: list[tuple[float, float] | None] = []
    lanelets: list[int] = []
    for k, st in enumerate(goal.state_list):
        ts = getattr(st, "time_step", None)
        steps.append((int(ts.start), int(ts.end)) if ts is not None else (0, 10**9))
        pos = getattr(st, "position", None)
        if pos is None:
            shapes.append(None)
        else:
            parts = pos.shapes if hasattr(pos, "shapes") else [pos]
            shapes.append(unary_union([p.shapely_object for p in parts]))
            given = (goal.lanelets_of_goal_position or {}).get(k)
            if given:
                lanelets += [int(x) for x in given]
            else:
                o = getattr(st, "orientation", None)
                for p in parts:
                    touched = [int(x) for x in net.find_lanelet_by_shape(p)]
                    heading = [x for x in touched if _heads(net.find_lanelet_by_id(x), p, o)]
                    lanelets += heading or touched
        v = getattr(st, "velocity", None)
        speeds.append((float(v.start), float(v.end)) if v is not None else None)
        o = getattr(st, "orientation", None)
        orients.append((float(o.start), float(o.end)) if o is not None else None)
    return Goal(tuple(steps), tuple(shapes), tuple(speeds), tuple(orients),
                tuple(dict.fromkeys(lanelets)))


def _heads(lanelet: Any, shape: Any, orientation: Any) -> bool:
    """Whether the lanelet runs, where it meets the goal's ``shape``, within the goal's
    ``orientation`` interval (``None``: any), with 0.2 rad to spare."""
    if orientation is None:
        return True
    c = lanelet.center_vertices
    centre = np.asarray(shape.shapely_object.centroid.coords[0])
    j = min(int(np.argmin(np.hypot(*(c - centre).T))), len(c) - 2)
    d = c[j + 1] - c[j]
    mid = (float(orientation.start) + float(orientation.end)) / 2.0
    half = (float(orientation.end) - float(orientation.start)) / 2.0 + 0.2
    return bool(abs(float(wrap_angle(math.atan2(d[1], d[0]) - mid))) <= half)


# -- the plan -----------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class CommonRoadPlan:
    """Result of :func:`plan`.

    Attributes
    ----------
    problem, vehicle, goal
        What was solved, and for which car.
    route, corridor, obstacles
        Level 1's lanelet route, the corridor along it and the static obstacles (with the
        moving obstacles' conflict places added where the path was planned around them).
    trajectory
        Level 3's trajectory (time from the initial state) up to the goal.
    states
        The solution: CommonRoad KS states every ``dt`` from the initial state, ending at
        the first state that reaches the goal (or at the end of the plan).
    goal_reached
        Whether the last state reaches the goal by CommonRoad's ``GoalRegion.is_reached``.
    yielded, passed
        Dynamic obstacles the speed plan waits for and passes in front of.
    plan_seconds
        Time [s] of levels 1-3, the speed plan among moving obstacles and the goal timing
        (reading the file and converting the states not counted).
    """

    problem: Problem
    vehicle: Vehicle
    goal: Goal
    route: LaneletRoute
    corridor: Corridor
    obstacles: Obstacles
    trajectory: Trajectory
    states: list[Any]
    goal_reached: bool
    yielded: tuple[str, ...]
    passed: tuple[str, ...]
    plan_seconds: float


def plan(problem: Problem, *, vehicle_type: int = 2,
         roadmap_params: RoadmapParams | None = None,
         speed_limits: bool = False) -> CommonRoadPlan:
    """Solve the planning problem (see the module docstring). ``speed_limits``: keep to
    the limits the scenario's ``MAX_SPEED`` traffic signs post on the route's lanelets
    (:func:`posted_speed_limits`; the top speed is then the highest of them where the
    goal asks for no speed); otherwise the top speed is the start's, or 50 km/h, or the
    goal's upper speed."""

    car = vehicle(vehicle_type)
    t_start = time.perf_counter()
    sc, pp = problem.scenario, problem.planning_problem
    net = sc.lanelet_network
    init = pp.initial_state
    v0 = float(getattr(init, "velocity", 0.0))
    head0 = float(init.orientation)
    direction = np.array([math.cos(head0), math.sin(head0)])
    # the planner's centre lies half the wheelbase ahead of the rear axle, CommonRoad's
    # reference point ``b`` ahead of it
    centre0 = np.asarray(init.position, dtype=float) - car.reference_ahead * direction
    goal = goal_of(problem)
    rp = roadmap_params or car.roadmap_params()
    start_ids = _start_lanelets(net, np.asarray(init.position, dtype=float), head0,
                                problem.source)
    s_top = max(v0, _goal_top_speed(goal, v0))
    horizon = max(hi for _, hi in goal.steps) if goal.steps else 0
    horizon = min(horizon, int(60.0 / problem.dt)) if horizon < 10**9 else int(20 / problem.dt)
    if goal.lanelets:
        try:
            route = lanelet_route(net, start_ids, goal.lanelets)
        except NoRouteError as err:
            raise NoRouteError(f"{problem.source}: {err}") from err
        route = _run_on(net, route)
    else:
        route = follow_road(net, start_ids[0], s_top * horizon * problem.dt + 50.0)
    statics = static_obstacles(sc)
    posted = _Posted.of(net, route, s_top) if speed_limits else None
    if posted is not None and not any(v is not None for v in goal.speed):
        s_top = max(v0, *posted.on_route)  # the road's own limits, where posted
    tp = car.trajectory_params(max(s_top, 1.0))
    road_ends = not any(net.find_lanelet_by_id(route.chain[-1]).successor)

    def corridor_of(obstacles: Obstacles, passing: bool = False) -> Corridor:
        c = route_corridor(net, route, obstacles, passing=passing)
        return _short_of_end(c, car) if road_ends else c

    corridor = corridor_of(statics)
    moving = _moving(sc)
    end_speed = 0.0 if road_ends else None
    t0 = float(init.time_step) * problem.dt
    timing = _Timing(tp, goal, v0, problem.dt, int(init.time_step), t0, end_speed, moving,
                     car, head0, posted)
    solver = _Solver(statics, centre0, head0, rp, tp, min(v0, tp.s_max), end_speed, car,
                     timing)
    try:
        corridor, tr, sp, obstacles = solver.through_goal(corridor, goal)
    except RoadBlockedError:
        # the route's lanes are blocked: the oncoming lane beside them is passing space
        corridor, tr, sp, obstacles = solver.through_goal(corridor_of(statics, True), goal)
    yielded = tuple(sp.yielded) if sp is not None else ()
    passed = tuple(sp.passed) if sp is not None else ()
    seconds = time.perf_counter() - t_start
    states = ks_states(tr, car, problem.dt, int(init.time_step), goal=goal,
                       body0=float(init.orientation))
    reached = bool(pp.goal.is_reached(states[-1]))
    return CommonRoadPlan(problem, car, goal, route, corridor, obstacles, tr, states, reached,
                          yielded, passed, seconds)


@dataclass(frozen=True, eq=False)
class _Solver:
    """Levels 2 and 3 along a corridor, then the speed among the moving obstacles
    (:class:`_Timing`), for one planning problem."""

    statics: Obstacles
    centre: FloatArray
    heading: float
    rp: RoadmapParams
    tp: TrajectoryParams
    start_speed: float
    end_speed: float | None
    car: Vehicle
    timing: _Timing

    def path(self, corridor: Corridor, obstacles: Obstacles, heading: float) -> Trajectory:
        from splineplan.planner import plan_corridor

        return plan_corridor(corridor, obstacles, self.centre, heading,
                             roadmap_params=self.rp, params=self.tp,
                             start_speed=self.start_speed, end_speed=self.end_speed).trajectory

    def solve(self, corridor: Corridor) -> tuple[Corridor, Trajectory, Any, Obstacles]:
        """The corridor, the timed trajectory, its space-time speed plan (``None`` without
        moving obstacles) and the static obstacles it was planned among."""
        car, obstacles = self.car, self.statics
        tr = self.path(corridor, obstacles, self.heading)
        # a curve from the start: its tangent is the centre's direction, turned from the
        # body's orientation by the slip angle of the curve's first curvature (the wheels
        # then start at the curve's angle); the slip that the path planned with it has, by
        # the secant method
        tried = [(0.0, _slip(tr, car))]
        while abs(tried[-1][1] - tried[-1][0]) > SLIP_REPLAN and len(tried) < 3:
            if len(tried) == 1:
                beta = tried[0][1]
            else:
                (b0, g0), (b1, g1) = tried[-2], tried[-1]
                slope = (g1 - g0) / (b1 - b0) if b1 != b0 else 0.0
                beta = b1 + (g1 - b1) / (1.0 - slope) if slope != 1.0 else g1
            tr = self.path(corridor, obstacles, self.heading + beta)
            tried.append((beta, _slip(tr, car)))
        tr, sp = self.timing.best(tr)
        for _ in range(2):  # speed first; the path around a conflict speed cannot resolve
            if sp is None or sp.conflict is None:
                break
            swept = sp.conflict.as_static()
            if swept.near_mask(self.centre[None], car.length).any():
                break  # it reaches the car where it stands: no path can start clear of it
            more = obstacles + swept
            try:
                again = self.path(corridor, more, self.heading)
            except SplineplanError as err:
                log.debug("no path around moving obstacle %s: %s", sp.conflict.obstacle.id,
                          err)
                break
            obstacles = more
            tr, sp = self.timing.best(again)
        return corridor, tr, sp, obstacles

    def through_goal(self, corridor: Corridor, goal: Goal
                     ) -> tuple[Corridor, Trajectory, Any, Obstacles]:
        """:meth:`solve` through the goal's position (:func:`goal_keep`); along the plain
        corridor too where that leaves a conflict with a moving obstacle, an infeasible
        path or one that cannot be driven at the start's speed (a goal beside the lane just
        ahead), and the better of the two."""
        kept = goal_keep(corridor, goal)
        first = self.solve(kept)
        if kept is corridor or self._score(first)[:3] == (True, True, True):
            return first
        second = self.solve(corridor)
        return max((first, second), key=self._score)  # a tie keeps the goal's

    def _score(self, result: tuple[Corridor, Trajectory, Any, Obstacles]
               ) -> tuple[bool, bool, bool, float]:
        """Clear of the moving obstacles, feasible, driven at the start's speed, and the
        later conflict where both have one."""
        _, tr, sp, _ = result
        clear = sp is None or sp.conflict is None
        return (clear, bool(tr.feasible), bool(tr.speed[0] >= self.start_speed - 1e-6),
                math.inf if clear else float(sp.conflict.t))


def goal_keep(corridor: Corridor, goal: Goal) -> Corridor:
    """The corridor whose vehicle centre keeps, where it passes the goal's position, to the
    part of the road that the goal covers (the goal asks for the car's centre there; a goal
    box where a recorded car was is often narrower than the lane, or in the lane beside the
    path's). The keep offsets (level 2's sweep lines) narrow to the goal's lateral extent,
    less :data:`GOAL_INSET` each side, and widen again at :data:`GOAL_TAPER` metres per metre
    before and after it."""
    shapes = [sh for sh in goal.shapes if sh is not None]
    if not shapes:
        return corridor
    st = np.asarray(corridor.s, dtype=float)
    hi = np.full(len(st), UNBOUNDED) if corridor.keep_left is None else corridor.keep_left.copy()
    lo = (np.full(len(st), -UNBOUNDED) if corridor.keep_right is None
          else corridor.keep_right.copy())
    changed = False
    for shape in shapes:
        outline = np.asarray(shape.exterior.coords if hasattr(shape, "exterior")
                             else shape.convex_hull.exterior.coords, dtype=float)
        sl = corridor.to_sl(outline)
        s0, s1 = float(sl[:, 0].min()), float(sl[:, 0].max())
        if s1 <= st[0] or s0 >= st[-1]:
            continue  # beyond the corridor
        l0, l1 = float(sl[:, 1].min()) + GOAL_INSET, float(sl[:, 1].max()) - GOAL_INSET
        if l1 < l0:
            l0 = l1 = float((sl[:, 1].min() + sl[:, 1].max()) / 2.0)
        away = np.maximum(np.maximum(s0 - st, st - s1), 0.0) * GOAL_TAPER
        hi = np.minimum(hi, l1 + away)
        lo = np.maximum(lo, l0 - away)
        changed = True
    if not changed:
        return corridor
    return replace(corridor, keep_left=hi, keep_right=lo)


def driven(result: CommonRoadPlan) -> Trajectory:
    """The part of the plan that the solution drives (up to its last state)."""
    tr = result.trajectory
    end = (len(result.states) - 1) * result.problem.dt
    keep = np.flatnonzero(tr.t <= end + 1e-9)
    n = max(int(keep[-1]) + 2 if len(keep) else 2, 2)
    n = min(n, len(tr.t))
    return replace(tr, t=tr.t[:n], x=tr.x[:n], y=tr.y[:n], heading=tr.heading[:n],
                   speed=tr.speed[:n], curvature=tr.curvature[:n], s=tr.s[:n],
                   clearance_obstacles=tr.clearance_obstacles[:n],
                   clearance_road=tr.clearance_road[:n])


def _moving(scenario: Any) -> list[Any]:
    try:
        return moving_obstacles(scenario)
    except ImportError:  # pragma: no cover - without the space-time module
        return []


def _short_of_end(corridor: Corridor, car: Vehicle) -> Corridor:
    """The corridor of a road that ends, cut so that the car stopping at its end keeps its
    front :data:`~splineplan.corridor.ROAD_END_GAP` inside the road (unless that leaves
    less than a car length):
    CommonRoad's body is centred ``b`` ahead of the rear axle, the planner's centre half the
    wheelbase."""
    return corridor.short_of_end(car.length / 2.0 + max(car.reference_ahead, 0.0),
                                 least=car.length)


def _run_on(network: Any, route: LaneletRoute) -> LaneletRoute:
    """The route with the goal lanelet's straightest successors for :data:`RUN_ON` m."""
    last = route.chain[-1]
    more = follow_road(network, last, float(network.find_lanelet_by_id(last).distance[-1])
                       + RUN_ON)
    if len(more.chain) <= 1:
        return route
    return _route_of(network, [*route.lanelets, *more.lanelets[1:]])


def _goal_top_speed(goal: Goal, v0: float) -> float:
    """Top speed [m/s] to plan with: the goal's upper speed where it has one (at least the
    start's), else the start's speed and at least 50 km/h."""
    highs = [s[1] for s in goal.speed if s is not None]
    return max(v0, min(highs)) if highs else max(v0, 13.89)


def posted_speed_limits(network: Any) -> dict[int, float]:
    """The posted speed limit [m/s] of each lanelet that has one: the lowest of its
    ``MAX_SPEED`` traffic signs."""
    signs: dict[int, float] = {}
    for sign in network.traffic_signs:
        for el in sign.traffic_sign_elements:
            if el.traffic_sign_element_id.name != "MAX_SPEED" or not el.additional_values:
                continue
            try:
                v = float(el.additional_values[0])
            except (TypeError, ValueError):
                continue
            if v > 0.0 and math.isfinite(v):
                signs[sign.traffic_sign_id] = min(v, signs.get(sign.traffic_sign_id, math.inf))
    out: dict[int, float] = {}
    for ll in network.lanelets:
        posted = [signs[i] for i in ll.traffic_signs if i in signs]
        if posted:
            out[ll.lanelet_id] = min(posted)
    return out


@dataclass(frozen=True, eq=False)
class _Posted:
    """The posted speed limits along a route (:func:`posted_speed_limits`); ``default``
    [m/s] where the lanelets under a point post none."""

    network: Any
    limits: Mapping[int, float]
    route: frozenset[int]
    default: float

    @classmethod
    def of(cls, network: Any, route: LaneletRoute, default: float) -> _Posted | None:
        """The route's posted limits; ``None`` where none of its lanelets posts one."""
        limits = posted_speed_limits(network)
        if not any(i in limits for i in route.lanelets):
            return None
        return cls(network, limits, frozenset(route.lanelets), default)

    @property
    def on_route(self) -> list[float]:
        """The limits posted on the route's lanelets [m/s]."""
        return [self.limits[i] for i in self.route if i in self.limits]

    def at(self, xy: FloatArray) -> FloatArray:
        """The limit [m/s] at points ``(n, 2)`` [m]: the lowest posted on the route's
        lanelets under each (on any lanelet under it, where it is on none of the route's)."""
        out = np.full(len(xy), self.default)
        found = self.network.find_lanelet_by_position([p for p in np.asarray(xy, dtype=float)])
        for k, ids in enumerate(found):
            mine = [i for i in ids if i in self.route] or list(ids)
            posted = [self.limits[i] for i in mine if i in self.limits]
            if posted:
                out[k] = min(posted)
        return out


def _start_lanelets(network: Any, xy: FloatArray, heading: float, source: str) -> list[int]:
    """The lanelets under the start, the one best aligned with its heading first."""
    found = network.find_lanelet_by_position([xy])[0]
    if not found:
        raise NoRouteError(f"{source}: the initial state ({xy[0]:.1f}, {xy[1]:.1f}) lies on no "
                           "lanelet")

    def misalign(lid: int) -> float:
        ll = network.find_lanelet_by_id(lid)
        c = ll.center_vertices
        j = int(np.argmin(np.hypot(*(c - xy).T)))
        j = min(j, len(c) - 2)
        d = c[j + 1] - c[j]
        return abs(float(wrap_angle(math.atan2(d[1], d[0]) - heading)))

    return sorted(found, key=misalign)[:1] + [f for f in found if misalign(f) < 0.5][1:]


@dataclass(frozen=True, eq=False)
class _Timing:
    """The speed along a path: the fastest among the moving obstacles, under the highest
    cap with which the goal is reached (its time window, speed and orientation)."""

    tp: TrajectoryParams
    goal: Goal
    v0: float
    dt: float
    step0: int
    t0: float
    end_speed: float | None
    moving: list[Any]
    car: Vehicle
    body0: float
    posted: _Posted | None = None

    def reaches(self, tr: Trajectory) -> bool:
        """Whether the timed trajectory reaches the goal."""
        return _reaches(tr, self.goal, self.dt, self.step0, self.car)

    def best(self, tr: Trajectory) -> tuple[Trajectory, Any]:
        """The trajectory with the best speed profile, and the space-time speed plan
        (``None`` without moving obstacles). Without a cap that reaches the goal: the
        fastest.

        The cap is found by bisection so that the car is in the middle of the goal region
        (along its path) in the middle of the time window; a few caps around it and a
        coarse scan follow if that state misses the goal (its speed or orientation)."""
        limit = self.path_limit(tr)
        if self.posted is not None:  # from the start's speed, braking to the limit
            posted = self.posted.at(tr.xy)
            limit = np.minimum(limit, np.maximum(posted, self._braking(tr.s, float(posted[0]))))
        inside = self.goal.inside(tr.xy)
        highs = [v[1] for v in self.goal.speed if v is not None]
        if highs and inside.any():
            limit = np.where(inside, np.minimum(limit, max(min(highs), MIN_CAP)), limit)
        first = self.timed(tr, limit, np.inf)
        if not self.goal.steps or self.reaches(first[0]):
            return first
        lo_step, hi_step = min(self.goal.steps)
        target = ((lo_step + min(hi_step, lo_step + 10**6)) / 2.0 - self.step0) * self.dt
        s_mid = _middle(tr.s, inside) if inside.any() else None
        caps: list[float] = []
        if s_mid is not None and _time_at(first[0], s_mid) < target:
            # bisection on the profile without the moving obstacles (they only slow it)
            lo, hi = MIN_CAP, max(self.tp.s_max, MIN_CAP)
            for _ in range(12):
                mid = math.sqrt(lo * hi)
                if _time_at(self.timed(tr, limit, mid, alone=True)[0], s_mid) > target:
                    lo = mid
                else:
                    hi = mid
            caps = [hi * f for f in (1.0, 1.04, 0.96, 1.1, 0.9)]
        caps += list(np.geomspace(max(self.tp.s_max, MIN_CAP), MIN_CAP, 6 if self.moving
                                  else 10))
        for cap in caps:
            cand = self.timed(tr, limit, float(cap))
            if self.reaches(cand[0]):
                return cand
        return self.meet(tr, limit) or first

    def path_limit(self, tr: Trajectory) -> FloatArray:
        """The path's speed limit ``(n,)`` [m/s]: the cornering speed (equation (1),
        ``s_max``) and the steering rate's for the wheel angles that the car's towed rear
        axle needs (:func:`~splineplan.speed.towed_steering`, from the body's orientation
        ``body0`` [rad] at the start), as :func:`ks_states` drives it: the checker's KS
        model asks no more of the steering."""
        return speed_limit(tr.s, tr.curvature, self.tp,
                           slip0=float(wrap_angle(float(tr.heading[0]) - self.body0)))

    def meet(self, tr: Trajectory, limit: FloatArray) -> tuple[Trajectory, Any] | None:
        """A speed profile that meets the goal where no cap does: slow (or stop) first,
        then reach the goal's stations at a step of its time window with its speed, at the
        car's own acceleration limits (:func:`splineplan.speed.meeting_profile`; the
        profile that changes speed least is tried first), then brake to a stop. It must
        keep the path's speed limit and, until the goal, the margin from every moving
        obstacle. A goal that asks for speed just where the road
        ahead is blocked (a cyclist stopping in the lane) needs it. ``None`` if no such
        profile reaches the goal."""
        from splineplan.spacetime import occupancy
        from splineplan.speed import meeting_distances

        goal, car, dt = self.goal, self.car, self.dt
        last = self.step0 + round(MEET_HORIZON / dt)
        head = np.unwrap(tr.heading)

        @functools.cache
        def occ_of() -> Any:
            return occupancy(tr.s, tr.xy, tr.heading,
                             self.t0 + np.arange(last - self.step0 + 1) * dt, self.moving,
                             length=car.length, width=car.width, margin=MOVING_MARGIN)

        for k, (lo, hi) in enumerate(goal.steps):
            lo, hi = max(lo, self.step0 + 1), min(hi, last)
            if hi < lo:
                continue
            where = (np.ones(len(tr.s), dtype=bool) if goal.shapes[k] is None
                     else _contains(goal.shapes[k], tr.xy))
            if goal.orientation[k] is not None:
                o_lo, o_hi = goal.orientation[k]  # type: ignore[misc]
                where &= np.abs(wrap_angle(head - (o_lo + o_hi) / 2.0)) <= (o_hi - o_lo) / 2.0
            if not where.any():
                continue
            i, j = _first_run(where)
            s_lo, s_hi = float(tr.s[i]), float(tr.s[j])
            v_top = float(min(np.max(limit[i:j + 1]), self.tp.s_max))
            if goal.speed[k] is not None:
                v_lo, v_hi = goal.speed[k]  # type: ignore[misc]
                ends = [v for v in (v_lo + min(0.05, (v_hi - v_lo) / 4.0), (v_lo + v_hi) / 2.0)
                        if v <= v_top]
            else:
                ends = [v_top, v_top / 2.0]
            a_down = BRAKING
            for step in np.unique(np.round(np.linspace(lo, hi, MEET_STEPS)).astype(int)):
                t_end = (int(step) - self.step0) * dt
                for v_end in ends:
                    top = max(v_end, self.v0, 1e-9)  # the engine's power above v_switch
                    a_up = min(BRAKING, car.a_max * min(1.0, car.v_switch / top))
                    vc_max = ((t_end + self.v0 / a_up + v_end / a_down)
                              / (1.0 / a_up + 1.0 / a_down))
                    grid = np.linspace(0.0, vc_max, 200)
                    d = meeting_distances(self.v0, t_end, v_end, a_up=a_up, a_down=a_down,
                                          cruise=grid)
                    ok = np.flatnonzero((d >= s_lo) & (d <= s_hi))
                    # the gentlest first (the cruise nearest the start's speed), then others
                    order = ok[np.argsort(np.abs(grid[ok] - self.v0))]
                    spread = ok[np.linspace(0, len(ok) - 1, min(len(ok), MEET_STATIONS)
                                            ).astype(int)] if len(ok) else ok
                    for c in dict.fromkeys([*order[:1].tolist(), *spread.tolist()]):
                        met = self._meeting(tr, limit, float(grid[c]), t_end, v_end,
                                            a_up, a_down, occ_of)
                        if met is not None:
                            return met
        return None

    def _meeting(self, tr: Trajectory, limit: FloatArray, cruise: float, t_end: float,
                 v_end: float, a_up: float, a_down: float, occ_of: Callable[[], Any]
                 ) -> tuple[Trajectory, Any] | None:
        """:meth:`meet`'s profile with that cruise speed, if it keeps the limits and
        reaches the goal."""
        from splineplan.spacetime import SpeedPlan, _with_plan
        from splineplan.speed import meeting_profile

        dt = self.dt
        n = round(t_end / dt)
        t_meet = np.arange(n + 1) * dt
        s_m, v_m = meeting_profile(self.v0, cruise, t_end, v_end, t_meet,
                                   a_up=a_up, a_down=a_down)
        tb = np.arange(1, math.ceil(v_end / a_down / dt) + 1) * dt
        v_b = np.maximum(v_end - a_down * tb, 0.0)
        s_b = s_m[-1] + (v_end + v_b) / 2.0 * np.minimum(tb, v_end / a_down)
        t_all = np.concatenate((t_meet, t_end + tb))
        s_all = np.concatenate((s_m, s_b))
        v_all = np.concatenate((v_m, v_b))
        # the path may end while it brakes (the solution ends at the goal)
        beyond = np.flatnonzero(s_all > tr.s[-1])
        if len(beyond):
            if beyond[0] <= n:
                return None
            t_all, s_all, v_all = t_all[:beyond[0]], s_all[:beyond[0]], v_all[:beyond[0]]
        if np.any(v_all > np.interp(s_all, tr.s, limit) + 0.05):
            return None
        if self.moving:
            occ = occ_of()
            on = (s_m[None, :] >= occ.lo[:, :n + 1]) & (
                s_m[None, :] <= occ.hi[:, :n + 1])
            if on.any():
                return None
        plan = SpeedPlan(self.t0 + t_all, s_all, v_all)
        cand = _with_plan(tr, plan, self.t0)
        if self.reaches(cand):
            return cand, (plan if self.moving else None)
        return None

    def _braking(self, s: FloatArray, to: float | None = None) -> FloatArray:
        """The speed [m/s] at stations ``s`` [m] braking at ``b_max`` from the start's;
        with ``to`` [m/s], as hard as reaches that speed at the end of a time step (the
        checker rebuilds each step with one acceleration)."""
        b = self.tp.b_max
        if to is not None and to < self.v0:
            steps = math.ceil((self.v0 - to) / (b * self.dt) - 1e-9)
            b = (self.v0 - to) / (steps * self.dt)
        return np.sqrt(np.maximum(self.v0**2 - 2.0 * b * s, 0.0))

    def timed(self, tr: Trajectory, limit: FloatArray, cap: float, *, alone: bool = False
              ) -> tuple[Trajectory, Any]:
        """The path with its speed under ``cap`` [m/s]; the cap applies from where braking
        from the start's speed reaches it. ``alone``: without the moving obstacles."""
        lim = np.minimum(limit, np.maximum(cap, self._braking(tr.s)))
        v = speed_profile(tr.s, lim, a_max=self.tp.a_max, b_max=self.tp.b_max,
                          start_speed=min(self.v0, float(lim[0])), end_speed=self.end_speed)
        if alone or not self.moving:
            return replace(tr, speed=v, t=_times(tr.s, v)), None
        from splineplan.spacetime import retime

        return retime(replace(tr, speed=v), self.moving, self.tp,
                      t0=self.t0, length=self.car.length, width=self.car.width,
                      margin=MOVING_MARGIN, end_speed=self.end_speed, path_limit=lim,
                      pass_from_behind=True)


def _contains(shape: Any, xy: FloatArray) -> NDArray[np.bool_]:
    """Whether points ``(n, 2)`` [m] lie in a shapely geometry."""
    import shapely

    return np.asarray(shapely.contains_xy(shape, xy[:, 0], xy[:, 1]))


def _first_run(inside: NDArray[np.bool_]) -> tuple[int, int]:
    """First and last index of the first run of ``inside`` samples (one is true)."""
    i = int(np.argmax(inside))
    rest = inside[i:]
    return i, (i + int(np.argmin(rest)) - 1 if not rest.all() else len(inside) - 1)


def _middle(s: FloatArray, inside: NDArray[np.bool_]) -> float:
    """The middle station [m] of the first run of ``inside`` samples."""
    i, j = _first_run(inside)
    return float((s[i] + s[j]) / 2.0)


def _time_at(tr: Trajectory, station: float) -> float:
    """Time [s] at which the trajectory first reaches ``station`` [m]."""
    finite = np.isfinite(tr.t)
    if not finite.any() or station > tr.s[finite][-1]:
        return math.inf
    return float(np.interp(station, tr.s[finite], tr.t[finite]))


def _reaches(tr: Trajectory, goal: Goal, dt: float, step0: int, car: Vehicle) -> bool:
    steps, xy, head, v = _sampled(tr, dt, step0, car)
    return bool(goal.reached(steps, xy, head, v, inset=REACH_INSET).any())


def _sampled(tr: Trajectory, dt: float, step0: int, car: Vehicle
             ) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """Time steps and, approximately, the body's reference point, heading and speed every
    ``dt`` [s] (past the end of the trajectory the car stands at its end): the body points
    from the path half the wheelbase behind the centre to the centre (the towed rear
    axle, :func:`ks_states`), and its reference point lies ``b`` ahead of that rear axle
    (the centre's speed stands for the rear axle's)."""
    end = tr.t[-1] if np.isfinite(tr.t[-1]) else tr.t[np.isfinite(tr.t)][-1]
    n = int(np.floor(end / dt + 1e-9)) + 1
    t = np.arange(n, dtype=np.float64) * dt
    x, y, _, v, st = centre_at(tr, t)
    back = np.maximum(st - car.wheelbase / 2.0, 0.0)
    rx, ry = np.interp(back, tr.s, tr.x), np.interp(back, tr.s, tr.y)
    h = np.arctan2(y - ry, x - rx)
    h = np.where(st - back > 1e-6, h, np.interp(st, tr.s, np.unwrap(tr.heading)))
    ahead = car.reference_ahead
    xy = np.column_stack((x + ahead * np.cos(h), y + ahead * np.sin(h)))
    return (step0 + np.arange(n)).astype(float), xy, h, v


def centre_at(tr: Trajectory, t: FloatArray) -> tuple[FloatArray, ...]:
    """The centre's x, y [m], path heading [rad], speed [m/s] and station [m] at times
    ``t`` [s] from the trajectory's start: the speed changes at constant acceleration
    between samples (as the profile was made), so that positions and speeds agree at any
    speed, and the pose follows the arc length."""
    finite = np.isfinite(tr.t)
    tt, ss, vv = tr.t[finite], tr.s[finite], tr.speed[finite]
    if len(tt) < 2:
        tt, ss, vv = np.array([0.0, 1.0]), tr.s[:2], np.zeros(2)
    i = np.clip(np.searchsorted(tt, t, side="right") - 1, 0, len(tt) - 2)
    ds = ss[i + 1] - ss[i]
    acc = (vv[i + 1] ** 2 - vv[i] ** 2) / (2 * np.where(ds > 0, ds, 1.0))
    tau = np.maximum(t - tt[i], 0.0)
    # past a stop (speed reaching 0) the car stands
    t_stop = np.where(acc < 0, vv[i] / np.where(acc < 0, -acc, 1.0), np.inf)
    tau = np.minimum(tau, t_stop)
    s = np.minimum(ss[i] + vv[i] * tau + acc * tau**2 / 2, ss[i + 1])
    v = np.where(t > tt[-1], 0.0 if vv[-1] == 0 else vv[-1], np.maximum(vv[i] + acc * tau, 0.0))
    s = np.where(t > tt[-1], ss[-1] + (t - tt[-1]) * vv[-1], s)
    s = np.minimum(s, tr.s[-1])
    head = np.interp(s, tr.s, np.unwrap(tr.heading))
    return np.interp(s, tr.s, tr.x), np.interp(s, tr.s, tr.y), head, v, s


def ks_states(tr: Trajectory, car: Vehicle, dt: float, step0: int = 0, *,
              goal: Goal | None = None, body0: float | None = None) -> list[Any]:
    """The trajectory every ``dt`` [s] as CommonRoad's KS states (time steps from
    ``step0``), up to the first that reaches ``goal`` where given; the body starts at
    orientation ``body0`` [rad] (default: along the path).

    The car's body follows from its centre's path as a kinematic single-track car's does:
    the rear axle, half the wheelbase behind the centre, is towed without slipping
    sideways (``theta' = v_c . n(theta) / (L / 2)``, integrated every :data:`TOW_STEP`
    seconds, second order); its speed is the centre's along the body, and the wheel angle
    gives the body's turn rate, ``tan(delta) = L theta' / v_rear``. The state's position
    is the rear axle plus ``b`` along the body.
    """
    _require()
    from commonroad.scenario.state import KSState

    end = tr.t[-1] if np.isfinite(tr.t[-1]) else tr.t[np.isfinite(tr.t)][-1]
    n = int(np.floor(end / dt + 1e-9)) + 1
    sub = max(round(dt / TOW_STEP), 1)
    t = np.arange((n - 1) * sub + 1, dtype=np.float64) * (dt / sub)
    x, y, head, v, _ = centre_at(tr, t)
    vx, vy = v * np.cos(head), v * np.sin(head)
    if body0 is None:
        body0 = float(head[0])
    theta = _tow(t, vx, vy, body0, car.wheelbase / 2.0)
    rate = np.gradient(theta, t) if len(t) > 1 else np.zeros(1)
    v_rear = vx * np.cos(theta) + vy * np.sin(theta)
    wheel = np.arctan2(car.wheelbase * rate, np.maximum(v_rear, 1e-3))
    wheel = np.where(v_rear < 1e-3, 0.0, wheel)
    rear = np.column_stack((x - car.wheelbase / 2 * np.cos(theta),
                            y - car.wheelbase / 2 * np.sin(theta)))
    cog = rear + car.b * np.column_stack((np.cos(theta), np.sin(theta)))
    keep = np.arange(0, len(t), sub)
    if goal is not None:
        hit = np.flatnonzero(goal.reached((step0 + np.arange(len(keep))).astype(float),
                                          cog[keep], theta[keep], v_rear[keep]))
        if len(hit):
            keep = keep[:int(hit[0]) + 1]
    return [KSState(position=cog[i], orientation=float(theta[i]),
                    velocity=float(max(v_rear[i], 0.0)), steering_angle=float(wheel[i]),
                    time_step=int(step0 + k)) for k, i in enumerate(keep)]


def _slip(tr: Trajectory, car: Vehicle) -> float:
    """Slip angle [rad] of the centre's path against the body at the trajectory's start
    (:func:`~splineplan.speed.steady_slip`)."""
    return steady_slip(float(tr.curvature[0]), car.wheelbase)


def _tow(t: FloatArray, vx: FloatArray, vy: FloatArray, theta0: float, half: float
         ) -> FloatArray:
    """The body's heading [rad] of a rear axle towed ``half`` [m] behind a point moving at
    ``(vx, vy)`` [m/s] (Heun's method)."""
    theta = np.empty(len(t))
    theta[0] = theta0
    h = np.diff(t)
    for i in range(len(t) - 1):
        a = theta[i]
        k1 = (-vx[i] * math.sin(a) + vy[i] * math.cos(a)) / half
        b = a + h[i] * k1
        k2 = (-vx[i + 1] * math.sin(b) + vy[i + 1] * math.cos(b)) / half
        theta[i + 1] = a + h[i] * (k1 + k2) / 2.0
    return theta


# -- the solution -------------------------------------------------------------------------
def solution(result: CommonRoadPlan) -> Any:
    """The plan as a commonroad-io ``Solution``: KS model, the vehicle type, cost function
    :data:`COST_FUNCTION`."""
    _require()
    from commonroad.common.solution import (
        CostFunction,
        PlanningProblemSolution,
        Solution,
        VehicleModel,
        VehicleType,
    )

    pps = PlanningProblemSolution(
        planning_problem_id=result.problem.planning_problem.planning_problem_id,
        vehicle_model=VehicleModel.KS, vehicle_type=VehicleType(result.vehicle.type_id),
        cost_function=CostFunction[COST_FUNCTION], trajectory=solution_trajectory(result))
    return Solution(result.problem.scenario.scenario_id, [pps],
                    computation_time=result.plan_seconds)


def write_solution(result: CommonRoadPlan, out_dir: str | Path) -> Path:
    """Write the solution in CommonRoad's solution format into ``out_dir`` (made if
    missing); returns the file's path."""
    from commonroad.common.solution import CommonRoadSolutionWriter

    sol = solution(result)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    name = f"solution_{sol.benchmark_id}.xml"
    CommonRoadSolutionWriter(sol).write_to_file(output_path=str(out), filename=name,
                                                overwrite=True)
    return out / name


@dataclass(frozen=True)
class Certificate:
    """CommonRoad's drivability checker's verdict on a solution (its ``solution_checker``,
    as the CommonRoad website judges submissions).

    Attributes
    ----------
    collision_free
        No collision with any obstacle at its time.
    road_compliant
        The car's rectangle stays within the road boundary.
    feasible
        ``trajectory_feasibility`` with the KS model of the vehicle type.
    goal_reached
        The planning problem's goal is reached by some state.
    starts_right
        The solution starts at the planning problem's initial state.
    """

    collision_free: bool
    road_compliant: bool
    feasible: bool
    goal_reached: bool
    starts_right: bool

    @property
    def passed(self) -> bool:
        """All checks passed."""
        return (self.collision_free and self.road_compliant and self.feasible
                and self.goal_reached and self.starts_right)


def certify(result: CommonRoadPlan) -> Certificate:
    """Judge the plan's solution with commonroad-drivability-checker (which must be
    installed)."""
    return certify_solution(result.problem.scenario, result.problem.planning_problem,
                            solution(result))


def certify_solution(scenario: Any, planning_problem: Any, sol: Any) -> Certificate:
    """Judge a commonroad-io ``Solution`` of ``planning_problem`` in ``scenario`` (any
    planner's) with commonroad-drivability-checker."""
    _require()
    try:
        from commonroad_dc.feasibility import solution_checker as sc
    except ImportError as err:
        raise SplineplanError("certifying a solution needs commonroad-drivability-checker: "
                              "pip install commonroad-drivability-checker") from err
    from commonroad.planning.planning_problem import PlanningProblemSet

    pps = PlanningProblemSet([planning_problem])

    def check(fn: Any, ok_when: bool) -> bool:
        try:
            return bool(fn(scenario, pps, sol)) == ok_when
        except Exception as err:  # the checker signals a failed check by raising
            log.debug("%s: %s", fn.__name__, err)
            return False

    try:
        feasible = all(r[0] for r in sc.solution_feasible(sol, scenario.dt, pps).values())
    except Exception as err:
        log.debug("solution_feasible: %s", err)
        feasible = False
    try:
        starts = bool(sc.starts_at_correct_state(sol, pps))
    except Exception as err:
        log.debug("starts_at_correct_state: %s", err)
        starts = False
    return Certificate(check(sc.obstacle_collision, False), check(sc.boundary_collision, False),
                       feasible, check(sc.goal_reached, True), starts)


def solution_trajectory(result: CommonRoadPlan) -> Any:
    """The solution's states as a commonroad-io ``Trajectory``."""
    from commonroad.scenario.trajectory import Trajectory as CRTrajectory

    return CRTrajectory(result.states[0].time_step, result.states)


def lanelet_outline(lanelet: Any) -> FloatArray:
    """A lanelet's outline ``(k, 2)`` [m]."""
    return np.vstack((lanelet.left_vertices, lanelet.right_vertices[::-1]))


def lanelet_polygons(scenario: Any) -> list[FloatArray]:
    """Each lanelet's outline ``(k, 2)`` [m], for pictures."""
    return [lanelet_outline(ll) for ll in scenario.lanelet_network.lanelets]


def goal_outlines(goal: Goal) -> list[FloatArray]:
    """The goal positions' outlines ``(k, 2)`` [m], for pictures."""
    out = []
    for shape in goal.shapes:
        if shape is None:
            continue
        for g in getattr(shape, "geoms", [shape]):
            out.append(np.asarray(g.exterior.coords))
    return out


def moving_paths(scenario: Any) -> list[FloatArray]:
    """Each dynamic obstacle's centre path ``(n, 2)`` [m], for pictures."""
    out = []
    for ob in scenario.dynamic_obstacles:
        pts = [ob.initial_state.position]
        pred = ob.prediction
        if pred is not None and hasattr(pred, "trajectory"):
            pts += [s.position for s in pred.trajectory.state_list]
        out.append(np.asarray(pts, dtype=float))
    return out
