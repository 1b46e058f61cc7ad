"""Levels 2 and 3 along a whole corridor: segments planned in turn and joined.

The corridor is cut into overlapping segments of at most ``RoadmapParams.segment_length``.
Each segment's roadmap and trajectory start from the pose of the previous segment's
trajectory at a join point in the middle half of their overlap, where that trajectory runs
straightest along the road (:func:`join_indices`; the next best joins are tried if the
segment comes out infeasible), so position and heading are continuous there; the speed
profile then runs once over the joined curve, so speed is continuous too. The cuts are
placed where the road is straightest and keeps its width (:func:`cut_stations`): a join
inside a tight turn would restart the next curve with zero curvature there, and a
segment's end inside a turn ends its curve on a clamped corner.

Where a segment's curve is infeasible between the corridor's sides (a junction turn whose
lanes are too tight for the car), the segment is planned again on the corridor widened to
SUMO's paving around its junctions (:meth:`Corridor.paved`, at most
:data:`~splineplan.network.PAVED_REACH` beyond the lanes), and the better plan is kept.

Level 2 models the vehicle as a disc of its width; a rectangle's corners reach
``(vehicle_length - vehicle_width) / 2`` [m] further ahead and behind. So level 2 plans among
obstacles elongated by that much along the road (:meth:`Obstacles.elongated`, along the
reference line's heading at each obstacle's centroid); level 3 checks the exact footprint
against the original obstacles. That is exact for a car parallel to the road; where it
closes a segment, a car driving diagonally may still pass between staggered obstacles, so
the segment's passage is then looked for with the car's rectangle and turning limit
(:func:`splineplan.lattice.turning_passages`), and kept where level 3 makes a feasible
curve through it.
"""

from __future__ import annotations

import itertools
import logging
import time
from collections.abc import Collection, Iterator
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view
from numpy.typing import ArrayLike, NDArray

from splineplan.corridor import PAVED_MIN, Corridor
from splineplan.errors import RoadBlockedError, SplineplanError, TrajectoryError
from splineplan.geometry import FloatArray, wrap_angle
from splineplan.lattice import turning_passages
from splineplan.obstacles import Obstacles
from splineplan.roadmap import Roadmap, RoadmapParams, plan_roadmap
from splineplan.speed import speed_profile
from splineplan.trajectory import (
    IterationStats,
    Trajectory,
    TrajectoryParams,
    _less_violating,
    _times,
    broken_limits,
    check_start_speed,
    plan_trajectory,
    sample_violations,
    speed_limit,
)

log = logging.getLogger(__name__)

#: Overlap [m] of consecutive segments (at most a quarter of the segment length).
SEGMENT_OVERLAP = 30.0
#: Fraction of ``segment_length`` within which a segment's end is chosen (see
#: :func:`cut_stations`): each segment is between this fraction and all of it long.
CUT_WINDOW = 0.6
#: Distance [m] over which a join's curvature counts as heading error (see :func:`join_indices`).
JOIN_LOOKAHEAD = 5.0
#: Joins tried (see :func:`join_indices`) before a segment is left infeasible.
JOIN_TRIES = 3


@dataclass(frozen=True, eq=False)
class CorridorPlan:
    """Result of :func:`plan_corridor`; unpacks as ``(roadmaps, trajectory)``.

    Attributes
    ----------
    roadmaps
        Level 2's roadmap of each segment.
    trajectory
        The joined level-3 trajectory.
    roadmap_seconds, trajectory_seconds
        Time [s] spent in level 2 and in level 3, summed over the segments.
    """

    roadmaps: list[Roadmap]
    trajectory: Trajectory
    roadmap_seconds: float
    trajectory_seconds: float

    def __iter__(self) -> Iterator[Any]:
        return iter((self.roadmaps, self.trajectory))


def plan_corridor(
    corridor: Corridor,
    obstacles: Obstacles | None,
    start_xy: ArrayLike,
    start_heading: float | None,
    *,
    roadmap_params: RoadmapParams | None = None,
    params: TrajectoryParams | None = None,
    start_speed: float = 0.0,
    end_speed: float | None = 0.0,
    turnarounds: Collection[tuple[str, str]] = (),
    paving: bool = True,
) -> CorridorPlan:
    """Roadmaps and one continuous trajectory along the whole corridor.

    Parameters
    ----------
    corridor, obstacles
        The route's drivable area and its obstacles (``None``: none).
    start_xy, start_heading
        The vehicle's centre ``(2,)`` [m] and heading [rad] (``None``: along the roadmap),
        anywhere along the corridor: the plan covers the corridor from there on.
    roadmap_params, params
        Level-2 and level-3 parameters.
    start_speed, end_speed
        Speeds [m/s] at the start and at the end of the corridor (0 stops there, ``None``
        keeps going).
    turnarounds
        Junctions ``(from_edge, to_edge)`` of the corridor's edges where the route turns
        back. No forward curve turns within a road's width (a three-point turn would be
        needed), so a segment that holds one gets the first curve through its roadmap
        (``plan_trajectory(..., polish=False)``) from one join. Polishing it would spend
        tens of milliseconds on a curve that cannot be driven.
    paving
        Whether a segment whose curve is infeasible between the corridor's sides may be
        planned again on its junctions' paving (:meth:`Corridor.paved`). In the closed
        loop a vehicle that keeps to its lane among SUMO's traffic plans without it: SUMO's
        drivers expect it on its lane.
    """
    rp = roadmap_params or RoadmapParams()
    tp = params or TrajectoryParams()
    check_start_speed(start_speed, tp)  # before any planning
    obstacles = Obstacles.empty() if obstacles is None else obstacles
    overlap = min(SEGMENT_OVERLAP, rp.segment_length / 4.0)
    corridor = _from_start(corridor, start_xy, rp, overlap)
    cuts = cut_stations(corridor, rp.segment_length, overlap)
    # a join's pose lies on a curve planned past it: no lead-in for its speed, which would
    # hold the next curve on the join's tangent for up to half the lead-in
    tp_join = replace(tp, lead_in_time=0.0)
    pieces = [corridor.slice(a, b) for a, b in cuts] if len(cuts) > 1 else [corridor]
    pose = np.asarray(start_xy, dtype=float).reshape(2)
    roadmaps: list[Roadmap] = []
    parts: list[Trajectory] = []
    prev: Trajectory | None = None  # the previous segment's whole trajectory
    # level 2's obstacles, elongated along the road once for the whole corridor
    t0 = time.perf_counter()
    grown = elongate_for_roadmap(corridor, obstacles, rp)
    t_roadmap = time.perf_counter() - t0
    t_traj = 0.0
    for i, seg in enumerate(pieces):
        seg_obs, seg_grown = obstacles, grown
        if len(obstacles):
            near = obstacles.near_mask(seg.polygon(), 0.0)
            if not near.all():
                seg_obs, seg_grown = obstacles.subset(near), grown.subset(near)
        hopeless = bool(turnarounds) and any(
            pair in turnarounds for pair in itertools.pairwise(seg.edges))
        joins = ([-1] if prev is None else
                 join_indices(prev, pieces[i - 1], seg.offset - pieces[i - 1].offset,
                              overlap)[:1 if hopeless else JOIN_TRIES])
        tried: list[tuple[int, Roadmap, Trajectory]] = []
        for attempt, cut in enumerate(joins):
            if prev is not None:
                pose = np.array([prev.x[cut], prev.y[cut]])
            clock = [0.0, 0.0]
            try:
                rm, tr = _plan_segment(
                    seg, seg_grown, seg_obs, pose, rp, tp if prev is None else tp_join,
                    start_heading if prev is None else float(prev.heading[cut]),
                    start_speed if prev is None else float(prev.speed[cut]),
                    not hopeless, paving, clock)
            except SplineplanError:
                if attempt + 1 == len(joins):
                    raise
                continue
            finally:
                t_roadmap += clock[0]
                t_traj += clock[1]
            tried.append((cut, rm, tr))
            if tr.feasible or not _fails_near_start(tr, overlap, tp.kappa_max):
                break  # another join moves only the start: it cannot mend a failure further on
            log.debug("segment at %.1f m infeasible from join %d", seg.offset, attempt)
        # the first feasible attempt, else the one from the best join
        cut, rm, tr = tried[-1] if tried[-1][2].feasible else tried[0]
        if prev is not None:
            parts.append(_head(prev, cut + 1, tp.kappa_max))
        roadmaps.append(rm)
        prev = tr
    assert prev is not None
    parts.append(prev)
    t3 = time.perf_counter()
    joined = _join(parts, tp, start_speed, end_speed)
    t_traj += time.perf_counter() - t3
    return CorridorPlan(roadmaps, joined, t_roadmap, t_traj)


def _plan_segment(seg: Corridor, grown: Obstacles, obstacles: Obstacles, pose: FloatArray,
                  rp: RoadmapParams, tp: TrajectoryParams, heading: float | None,
                  speed: float, polish: bool, paving: bool, clock: list[float]
                  ) -> tuple[Roadmap, Trajectory]:
    """Levels 2 and 3 on one segment from ``pose``.

    Where that gives a curve that breaks the turning limit or leaves the road beside a
    junction's paving (:func:`_paving_helps`), or cannot start (a car that cut a
    junction's corner stands beside its lanes), the same on the segment widened to the
    junctions' paving (:meth:`Corridor.paved`): its plan is kept if it is feasible, or
    less infeasible (:func:`~splineplan.trajectory._less_violating`; a car already on
    the paving), or the only one where the segment was not found blocked; none of this
    without ``paving``. ``clock`` gains the seconds of level 2 and level 3."""
    wide = seg.paved() if polish and paving else None
    try:
        rm, tr = _levels_2_3(seg, grown, obstacles, pose, rp, tp, heading, speed, polish,
                             clock)
    except SplineplanError as err:
        if wide is None:
            raise
        try:
            rm2, tr2 = _levels_2_3(wide, grown, obstacles, pose, rp, tp, heading, speed,
                                   polish, clock)
        except SplineplanError:
            raise err from None
        if tr2.feasible or not isinstance(err, RoadBlockedError):
            return rm2, tr2
        raise
    if tr.feasible or wide is None or not _paving_helps(tr, seg):
        return rm, tr
    try:
        rm2, tr2 = _levels_2_3(wide, grown, obstacles, pose, rp, tp, heading, speed, polish,
                               clock)
    except SplineplanError:
        return rm, tr
    log.debug("segment at %.1f m: feasible on the paved junctions: %s", seg.offset,
              tr2.feasible)
    return (rm, tr) if _less_violating(tr, tr2, tp) is tr else (rm2, tr2)


def _paving_helps(tr: Trajectory, seg: Corridor) -> bool:
    """Whether the trajectory breaks the turning limit or leaves the road within
    :data:`PAVED_NEAR` of where the segment's paved offsets give room beyond its sides
    (an obstacle too close is no reason: among traffic, the room is the other vehicles')."""
    pl, pr = seg.paved_left, seg.paved_right
    if pl is None or pr is None:
        return False
    room = seg.s[np.maximum(pl - seg.left, seg.right - pr) > PAVED_MIN]
    if not len(room):
        return False
    for v in tr.violations:
        if v.kind in ("curvature", "road"):
            st = float(seg.to_sl(np.array([[v.x, v.y]]))[0, 0])
            if np.min(np.abs(room - st)) <= PAVED_NEAR:
                return True
    return False


#: Distance [m] along the corridor within which a broken limit counts as beside the room
#: of a junction's paving (:func:`_paving_helps`): the room changes the curve that far
#: (10 m: 69 of 100 random Monaco routes feasible, 20 m and more: 70).
PAVED_NEAR = 20.0


def _levels_2_3(seg: Corridor, grown: Obstacles, obstacles: Obstacles, pose: FloatArray,
                rp: RoadmapParams, tp: TrajectoryParams, heading: float | None,
                speed: float, polish: bool, clock: list[float]
                ) -> tuple[Roadmap, Trajectory]:
    """Level 2's roadmap and level 3's trajectory on one segment; ``clock`` gains their
    seconds."""
    t0 = time.perf_counter()
    try:
        rm = plan_roadmap(seg, grown, pose, rp)
    except RoadBlockedError as err:
        blocked: RoadBlockedError | None = err
    else:
        blocked = None
    finally:
        t1 = time.perf_counter()
        clock[0] += t1 - t0
    if blocked is not None:
        return _turning_passage(seg, obstacles, pose, rp, tp, heading, speed, polish,
                                blocked, clock)
    try:
        tr = plan_trajectory(rm, seg, obstacles, tp, heading, start_speed=speed,
                             end_speed=None, polish=polish)
    finally:
        clock[1] += time.perf_counter() - t1
    return rm, tr


def _turning_passage(seg: Corridor, obstacles: Obstacles, pose: FloatArray,
                     rp: RoadmapParams, tp: TrajectoryParams, heading: float | None,
                     speed: float, polish: bool, blocked: RoadBlockedError,
                     clock: list[float]) -> tuple[Roadmap, Trajectory]:
    """Where level 2 found the segment closed for a car parallel to the road: the first
    diagonal passage between staggered obstacles, with the car's footprint and turning
    limit (:func:`splineplan.lattice.turning_passages`), through which level 3 makes a
    feasible curve; ``blocked`` raised again where there is none. ``clock`` gains the
    search's seconds as level 2's, the curves' as level 3's."""
    passages = turning_passages(seg, obstacles, pose, heading, rp, tp.kappa_max,
                                tp.road_margin, blocked.station - seg.offset)
    while True:
        t0 = time.perf_counter()
        rm = next(passages, None)
        t1 = time.perf_counter()
        clock[0] += t1 - t0
        if rm is None:
            raise blocked
        try:
            tr = plan_trajectory(rm, seg, obstacles, tp, heading, start_speed=speed,
                                 end_speed=None, polish=polish)
        finally:
            clock[1] += time.perf_counter() - t1
        if tr.feasible:
            return rm, tr


def warm_up() -> None:
    """Load levels 2 and 3's compiled loops (compile them in parallel first, on the first
    run of an install: :func:`splineplan.precompile.ensure`) by planning a short straight
    road with one obstacle, so that a closed loop's first replan does not pay for it."""
    from splineplan.precompile import ensure

    ensure()
    road = Corridor.from_boundaries([[0.0, 3.5], [60.0, 3.5]], [[0.0, -3.5], [60.0, -3.5]])
    cars = Obstacles.from_boxes([[30.0, 1.5]], [0.0], 4.5, 1.8)
    plan_corridor(road, cars, [1.0, -1.5], 0.0)


def _from_start(corridor: Corridor, start_xy: ArrayLike, rp: RoadmapParams, overlap: float
                ) -> Corridor:
    """The corridor from a vehicle length behind the start on, where the start lies beyond
    its first segment (where the first segment would end behind or near the start); the
    corridor itself otherwise, so that plans from its beginning keep their segments."""
    start = np.asarray(start_xy, dtype=float).reshape(-1)
    if start.shape != (2,) or not np.all(np.isfinite(start)):
        return corridor  # level 2 says what is wrong with it
    s0 = float(corridor.to_sl(start[None])[0, 0])
    if s0 <= CUT_WINDOW * rp.segment_length - overlap or s0 >= corridor.length:
        return corridor
    return corridor.slice(s0 - rp.vehicle_length, corridor.length)


def _infeasible_samples(tr: Trajectory, kappa_max: float) -> NDArray[np.bool_]:
    """Per sample: curvature over ``kappa_max`` [1/m], or the footprint within the safety
    margin of an obstacle or the road margin of a road edge (with level 3's tolerance for
    rounding)."""
    obs, road, kappa = broken_limits(tr.curvature, tr.clearance_obstacles, tr.clearance_road,
                                     tr.safety_margin, tr.road_margin, kappa_max)
    return obs | road | kappa


def _fails_near_start(tr: Trajectory, reach: float, kappa_max: float) -> bool:
    """Whether the trajectory's first infeasible sample lies within ``reach`` [m] of its
    start."""
    hits = np.flatnonzero(_infeasible_samples(tr, kappa_max))
    return bool(len(hits)) and float(tr.s[hits[0]] - tr.s[0]) <= reach


def cut_stations(corridor: Corridor, length: float, overlap: float
                 ) -> list[tuple[float, float]]:
    """Start and end stations [m] of overlapping segments at most ``length`` [m] long.

    Each segment ends between ``CUT_WINDOW * length`` and ``length`` from its start, where
    the overlap ``[end - overlap, end]`` with the next segment is straightest: smallest
    largest turn of the reference line and change of the road's width over it (ties: the
    farthest end). The next segment starts at ``end - overlap``.
    """
    total = corridor.length
    if total <= length:
        return [(0.0, total)]
    grid = np.arange(0.0, total + 0.5, 1.0)
    grid[-1] = min(grid[-1], total)
    head = np.unwrap(corridor.heading_at(grid))
    right, left = corridor.bounds_at(grid)
    win = max(round(overlap), 1)

    def spread(a: FloatArray) -> FloatArray:
        # range of a over [grid[j] - overlap, grid[j]] for each j
        w = sliding_window_view(np.concatenate((np.full(win, a[0]), a)), win + 1)
        return np.asarray(w.max(axis=1) - w.min(axis=1))

    # 0.1 rad of turn weighs like 1 m of width change; rounded so that ties go farthest
    bad = np.round(10.0 * spread(head) + spread(np.asarray(left - right)), 1)
    cuts: list[tuple[float, float]] = []
    a = 0.0
    while total - a > length:
        lo = int(np.ceil(a + max(CUT_WINDOW * length, overlap + 1.0)))
        hi = int(np.floor(a + length))
        cand = np.arange(lo, hi + 1)
        j = int(cand[::-1][np.argmin(bad[cand[::-1]])])
        cuts.append((a, float(grid[j])))
        a = float(grid[j]) - overlap
    cuts.append((a, total))
    return cuts


def join_indices(tr: Trajectory, seg: Corridor, next_start: float, overlap: float
                 ) -> NDArray[np.int64]:
    """Candidate samples of ``tr`` (planned along ``seg``) where the next segment, which
    starts at station ``next_start`` [m] of ``seg``, may take over, best first.

    Joins lie in the middle half of the overlap ``[next_start, next_start + overlap]``.
    The best is where the curve runs most nearly along the road and straight (least
    heading error plus ``JOIN_LOOKAHEAD`` times the curvature, in steps of 0.01), nearest
    the overlap's middle among equals: the next curve starts on that tangent, so a join in
    the middle of a lane change would send it on sideways. The others follow at least
    ``overlap / 8`` [m] apart, in the same order.
    """
    st = seg.to_sl(tr.xy)[:, 0]
    lo, hi = next_start + overlap / 4.0, next_start + 3.0 * overlap / 4.0
    cand = np.flatnonzero((st >= lo) & (st <= hi))
    if len(cand) == 0 or cand[0] == 0:
        raise TrajectoryError(
            f"trajectory does not reach the join at station "
            f"{seg.offset + next_start + overlap / 2.0:.1f} m")
    off = np.abs(wrap_angle(tr.heading[cand] - seg.heading_at(st[cand])))
    bad = np.round((off + JOIN_LOOKAHEAD * np.abs(tr.curvature[cand])) / 0.01)
    mid = np.abs(st[cand] - (next_start + overlap / 2.0))
    order = cand[np.lexsort((mid, bad))]
    out: list[int] = []
    for j in order.tolist():
        if all(abs(st[j] - st[k]) >= overlap / 8.0 for k in out):
            out.append(j)
    return np.asarray(out, dtype=np.int64)


def elongate_for_roadmap(corridor: Corridor, obstacles: Obstacles,
                         params: RoadmapParams) -> Obstacles:
    """Obstacles lengthened along the road by ``(vehicle_length - vehicle_width) / 2`` [m]
    at each end, for level 2's disc model of the vehicle (see the module docstring)."""
    extra = max(params.vehicle_length - params.vehicle_width, 0.0) / 2.0
    if not len(obstacles) or extra <= 0:
        return obstacles
    starts = obstacles.offsets[:-1]
    centroids = (np.add.reduceat(obstacles.vertices, starts, axis=0)
                 / np.diff(obstacles.offsets)[:, None])
    return obstacles.elongated(corridor.heading_at(corridor.to_sl(centroids)[:, 0]), extra)


def _head(tr: Trajectory, n: int, kappa_max: float, first: int = 0) -> Trajectory:
    """Samples ``first`` to ``n - 1`` of a trajectory; feasible if those samples keep the
    margin and the turning limit (what fails outside them is not driven)."""
    part = slice(first, n)
    head = replace(tr, t=tr.t[part], x=tr.x[part], y=tr.y[part], heading=tr.heading[part],
                   speed=tr.speed[part], curvature=tr.curvature[part], s=tr.s[part],
                   clearance_obstacles=tr.clearance_obstacles[part],
                   clearance_road=tr.clearance_road[part])
    if tr.feasible:
        return head
    broken = sample_violations(head.s, head.xy, head.curvature, head.clearance_obstacles,
                               head.clearance_road, tr.safety_margin, tr.road_margin, kappa_max)
    return replace(head, feasible=not broken, violations=broken)


def continued(tr: Trajectory, first: int, join: int, after: Trajectory,
              params: TrajectoryParams, start_speed: float, end_speed: float | None
              ) -> Trajectory:
    """``tr`` from its sample ``first`` to its sample ``join``, where ``after`` starts, then
    ``after``: one trajectory, as the corridor's segments are joined (the speed profile run
    again over the whole, from ``start_speed`` [m/s] to ``end_speed``)."""
    return _join([_head(tr, join + 1, params.kappa_max, first), after], params, start_speed,
                 end_speed)


def _join(parts: list[Trajectory], tp: TrajectoryParams, start_speed: float,
          end_speed: float | None) -> Trajectory:
    """One trajectory from pieces that each start where the previous one ends."""
    if len(parts) == 1:
        tr = parts[0]
        cat = {name: getattr(tr, name) for name in
               ("x", "y", "heading", "curvature", "clearance_obstacles", "clearance_road")}
    else:
        # drop each later piece's first sample: it repeats the previous piece's last
        cat = {name: np.concatenate([getattr(p, name)[(1 if j else 0):]
                                     for j, p in enumerate(parts)])
               for name in ("x", "y", "heading", "curvature", "clearance_obstacles",
                            "clearance_road")}
    xy = np.column_stack((cat["x"], cat["y"]))
    s: FloatArray = np.concatenate(([0.0], np.cumsum(np.hypot(*np.diff(xy, axis=0).T))))
    limit = speed_limit(s, cat["curvature"], tp)
    speed = speed_profile(s, limit, a_max=tp.a_max, b_max=tp.b_max,
                          start_speed=start_speed, end_speed=end_speed)
    stats = IterationStats(*(sum(getattr(p.iterations, f) for p in parts)
                             for f in ("tried", "accepted", "refused", "rounds",
                                       "refinements", "control_points", "doubled")))
    starts = np.cumsum([0] + [len(p.s) - 1 for p in parts[:-1]])
    violations = tuple(replace(v, s=v.s - p.s[0] + s[i])
                       for p, i in zip(parts, starts, strict=True) for v in p.violations)
    return Trajectory(
        _times(s, speed), cat["x"], cat["y"], cat["heading"], speed, cat["curvature"], s,
        np.concatenate([p.control_points for p in parts]),
        parts[0].spline if len(parts) == 1 else None,
        cat["clearance_obstacles"], cat["clearance_road"],
        all(p.feasible for p in parts), stats,
        min(p.min_speed_before for p in parts), min(p.min_speed_after for p in parts),
        parts[0].safety_margin, parts[0].road_margin, violations)
