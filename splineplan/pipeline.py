"""The three levels in one call: road selection, roadmaps and a trajectory.

Level 1 picks the roads; the route's drivable area becomes a corridor; levels 2 and 3 plan
along it (:func:`splineplan.planner.plan_corridor`). Where level 2 finds a road closed, the
closed edge is avoided and level 1 plans again, as the paper's conclusion proposes.

Tight turns. Level 1 gets the vehicle's footprint and turning radius
(:class:`~splineplan.network.CarShape`, from the roadmap and trajectory parameters) and
routes round junction turns that this car cannot make within SUMO's paving, where another
route exists (:func:`splineplan.route.shortest_route`). A turn it makes only on a path
that level 1 searched for, at its turning limit (:func:`splineplan.network.searched_path`),
is taken; where the plan then breaks a limit, the plan along that path
(``route_corridor(..., car=...)``) and the plan along a route without such turns are
tried too, and the best of them kept.

Turnarounds. Level 1 is length-optimal and may turn back onto the reverse edge (at a dead
end, or where a U-turn is shorter than going round a block). A corridor cannot fold back
on itself, and levels 2 and 3 plan forward motion only, so the pipeline asks level 1 for
the shortest route without turnaround connections (SUMO direction ``t``) and falls back to
the shortest route only when every route needs one. :attr:`Plan.route` is the route
planned; it is longer than level 1's optimum exactly when the optimum turns around. The
segments that hold such a turnaround get the first curve through their roadmap, without
the repair, optimisation and retries that mend other curves: no forward curve can drive
them (a three-point turn would be needed), and the trajectory reports itself infeasible.
"""

from __future__ import annotations

import itertools
import logging
import time
from collections.abc import Iterable
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from splineplan.corridor import Corridor
from splineplan.errors import NoRouteError, ParameterError, RoadBlockedError
from splineplan.network import CarShape, RoadNetwork, route_corridor, searched_path
from splineplan.obstacles import Obstacles
from splineplan.planner import plan_corridor
from splineplan.roadmap import Roadmap, RoadmapParams
from splineplan.route import Route, forward_route, is_turnaround
from splineplan.trajectory import Trajectory, TrajectoryParams, _less_violating

log = logging.getLogger(__name__)


@dataclass(frozen=True, eq=False)
class Plan:
    """Result of :func:`plan`.

    Attributes
    ----------
    route, corridor
        The road-level route and its drivable area.
    roadmaps
        Level 2's roadmap of each road segment.
    trajectory
        The joined level-3 trajectory.
    blocked
        Edges found closed by level 2 and avoided by a new road selection, in order.
    route_seconds, roadmap_seconds, trajectory_seconds
        Time [s] spent in each level (summed over re-routes).
    """

    route: Route
    corridor: Corridor
    roadmaps: tuple[Roadmap, ...]
    trajectory: Trajectory
    blocked: tuple[str, ...]
    route_seconds: float
    roadmap_seconds: float
    trajectory_seconds: float

    @property
    def total_seconds(self) -> float:
        """Time [s] of the three levels together."""
        return self.route_seconds + self.roadmap_seconds + self.trajectory_seconds


def plan(
    network: RoadNetwork,
    from_edge: str,
    to_edge: str,
    obstacles: Obstacles | None = None,
    *,
    start_pos: float = 0.0,
    start_xy: ArrayLike | None = None,
    start_heading: float | None = None,
    start_speed: float = 0.0,
    end_speed: float | None = 0.0,
    end_pos: float | None = None,
    vclass: str = "passenger",
    weight: str = "length",
    avoid: Iterable[str] = (),
    roadmap_params: RoadmapParams | None = None,
    trajectory_params: TrajectoryParams | None = None,
    max_reroutes: int = 8,
) -> Plan:
    """Plan from a start on ``from_edge`` to the end of ``to_edge`` (or ``end_pos`` on it)
    among obstacles.

    Parameters
    ----------
    network
        The road network (:func:`splineplan.network.load_network`).
    from_edge, to_edge
        Origin and destination edge ids.
    obstacles
        Static obstacles on the road (default: none).
    start_pos
        Position [m] along the origin edge where the vehicle's centre is.
    start_xy, start_heading
        The vehicle's centre ``(2,)`` [m] and heading [rad]; by default the middle of the
        drivable area at ``start_pos``, along the road.
    start_speed, end_speed
        Speeds [m/s] at the start and at the goal (``None``: keep going).
    end_pos
        Position [m] along ``to_edge`` where the plan ends, as SUMO's ``arrivalPos``
        (default: the edge's end). On a route of one edge it must lie ahead of
        ``start_pos``. Where no connection leaves ``to_edge`` (a dead end), the plan
        ends at the latest where the car's front keeps
        :data:`~splineplan.corridor.ROAD_END_GAP` from the road's end.
    vclass, weight, avoid
        As for :func:`splineplan.route.shortest_route`.
    roadmap_params, trajectory_params
        Parameters of levels 2 and 3.
    max_reroutes
        How many closed edges to plan around before giving up.

    Raises
    ------
    ParameterError
        ``end_pos`` outside ``to_edge``, or not ahead of the start on a one-edge route.
    NoRouteError
        No road route from the origin to the destination.
    RoadBlockedError
        Level 2 found the road closed on the origin or the destination edge itself (no way
        around it), or no route avoids the closed edges, or it was still closed after
        ``max_reroutes`` re-routes. Where level 2 finds a junction closed (a turn too sharp
        for the vehicle, or obstacles in it), the edge entered through it is avoided.
    """
    obstacles = obstacles if obstacles is not None else Obstacles.empty()
    rp = roadmap_params if roadmap_params is not None else RoadmapParams()
    tp = trajectory_params if trajectory_params is not None else TrajectoryParams()
    car = CarShape(rp.vehicle_length, rp.vehicle_width, tp.min_turn_radius)
    if end_pos is not None:
        _check_end_pos(network, from_edge, to_edge, start_pos, end_pos)
    avoided = list(avoid)
    blocked: list[str] = []
    last: RoadBlockedError | None = None
    clock = [0.0, 0.0, 0.0]  # level 1 (and the corridors), level 2, level 3 [s]

    def along(route: Route, corridor: Corridor) -> tuple[Route, Corridor, Any]:
        """Levels 2 and 3 on the route's ``corridor``, cut to the plan's end."""
        xy = (corridor.to_xy(start_pos, 0.0) if start_xy is None
              else np.asarray(start_xy, dtype=float).reshape(2))
        end = corridor.length if end_pos is None else end_station(network, corridor, end_pos)
        if network.dead_end(to_edge):
            # the car stops before a road that ends, its front inside
            end = min(end, corridor.stop_before_end(
                rp.vehicle_length / 2.0,
                least=float(corridor.to_sl(xy)[0, 0]) + rp.vehicle_length))
        if end_pos is not None or end < corridor.length:
            corridor = corridor.slice(0.0, end)
        heading = (float(corridor.heading_at(corridor.to_sl(xy)[0, 0]))
                   if start_heading is None else start_heading)
        back = {(route.edges[i], route.edges[i + 1]) for i in turnarounds(network, route)}
        result = plan_corridor(corridor, obstacles, xy, heading,
                               roadmap_params=roadmap_params, params=trajectory_params,
                               start_speed=start_speed, end_speed=end_speed,
                               turnarounds=back)
        clock[1] += result.roadmap_seconds
        clock[2] += result.trajectory_seconds
        return route, corridor, result

    def routed(avoid_limit_turns: bool = False) -> Route:
        t0 = time.perf_counter()
        try:
            return forward_route(network, from_edge, to_edge, vclass=vclass, weight=weight,
                                 avoid=avoided, start_pos=start_pos, car=car,
                                 avoid_limit_turns=avoid_limit_turns)
        finally:
            clock[0] += time.perf_counter() - t0

    def corridor_of(route: Route, path: bool = False) -> Corridor:
        t0 = time.perf_counter()
        corridor = route_corridor(network, route, vclass=vclass, car=car if path else None)
        clock[0] += time.perf_counter() - t0
        return corridor

    while True:
        try:
            route = routed()
        except NoRouteError as err:
            if last is None:
                raise
            raise RoadBlockedError(f"{last}; no other route: {err}", station=last.station,
                                   edge=last.edge, junction=last.junction) from err
        try:
            best = along(route, corridor_of(route))
            if not best[2].trajectory.feasible and _searched(network, route, car):
                # a turn the car makes only at its turning limit: along the path level 1
                # found for it, then by a route without such turns; the best plan
                for how in ("path", "route"):
                    try:
                        if how == "path":
                            other = along(route, corridor_of(route, path=True))
                        else:
                            again = routed(avoid_limit_turns=True)
                            if again.edges == route.edges:
                                continue
                            other = along(again, corridor_of(again))
                    except (RoadBlockedError, NoRouteError):
                        continue
                    if _less_violating(best[2].trajectory, other[2].trajectory,
                                       tp) is not best[2].trajectory:
                        best = other
                    if best[2].trajectory.feasible:
                        break
        except RoadBlockedError as err:
            edge = err.closed_edge
            if edge is None or edge in (from_edge, to_edge) or edge in avoided or \
                    len(blocked) >= max_reroutes:
                raise
            log.info("edge %s closed at station %.1f m: re-routing", edge, err.station)
            last = err
            blocked.append(edge)
            avoided.append(edge)
            continue
        route, corridor, result = best
        return Plan(route, corridor, tuple(result.roadmaps), result.trajectory,
                    tuple(blocked), clock[0], clock[1], clock[2])


def _searched(network: RoadNetwork, route: Route, car: CarShape) -> bool:
    """Whether the route takes a junction turn that the car makes only on a path level 1
    searched for (:func:`~splineplan.network.searched_path`)."""
    return any(searched_path(network, a, b, route.vclass, car) is not None
               for a, b in itertools.pairwise(route.edges))


def end_station(network: RoadNetwork, corridor: Corridor, end_pos: float) -> float:
    """Station [m] on a route's corridor of position ``end_pos`` [m] along its last edge.

    The last edge's stretch runs from its start station to the corridor's end; positions
    along it scale with the edge's length (the corridor's reference line runs midway
    across the lanes and may be a little longer or shorter than SUMO's lane length).
    """
    s0 = float(corridor.edge_starts[-1])
    length = network.length_of(corridor.edges[-1])
    return s0 + (corridor.length - s0) * min(max(end_pos / length, 0.0), 1.0)


def _check_end_pos(network: RoadNetwork, from_edge: str, to_edge: str, start_pos: float,
                   end_pos: float) -> None:
    length = network.length_of(to_edge)
    if not 0.0 <= end_pos <= length:
        raise ParameterError(f"end_pos {end_pos:g} m is outside edge '{to_edge}' "
                             f"[0, {length:g}] m")
    if from_edge == to_edge and end_pos <= start_pos:
        raise ParameterError(f"end_pos {end_pos:g} m is not ahead of start_pos "
                             f"{start_pos:g} m on edge '{to_edge}'")


def turnarounds(network: RoadNetwork, route: Route) -> tuple[int, ...]:
    """Indices ``i`` where the route turns back from ``edges[i]`` onto ``edges[i + 1]``."""
    return tuple(i for i, (e, f) in enumerate(itertools.pairwise(route.edges))
                 if is_turnaround(network, e, f, route.vclass))

