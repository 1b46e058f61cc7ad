"""Moving obstacles with a known future: the speed along a fixed path that keeps clear of them.

The paper plans among static obstacles and leaves moving ones to future work; its authors'
later work, and the prioritised scheme it names, treat a vehicle whose motion is known (a
plan published by another planned vehicle, a CommonRoad dynamic obstacle, a prediction of a
SUMO vehicle) as an obstacle in space and time. Here that is done speed first, in the usual
path-velocity decomposition:

1. **Occupancy.** For each obstacle and each time step, the stations of the path at which the
   vehicle's rectangle would come closer than the margin to the obstacle's rectangle
   (:func:`occupancy`: exact rectangle distances for the pairs a k-d tree leaves).
2. **Pass or yield.** A forward pass in time drives as fast as the path's speed limit and the
   acceleration limits allow while staying behind every obstacle it yields to, braking early
   enough to stop behind it at any later time. Obstacles the fastest profile would touch are
   yielded to, earliest touch first, until none is touched; the others are passed in front of
   or never met. With ``pass_from_behind``, one that first touches it from behind (a faster
   vehicle coming up in its lane, whose future is fixed, as a recorded one's) is not yielded
   to: staying behind it would mean stopping in its way.
3. **Conflict.** Where even full braking cannot stay behind an obstacle (it comes towards the
   vehicle, or it is already too close), speed alone cannot keep the margin: the result names
   the obstacle, the time and the station (:class:`Conflict`), and
   :meth:`Conflict.as_static` gives the obstacle's swept rectangles there for level 2 to plan
   a new path around.

All functions are pure; times are absolute [s] (a simulation clock), so plans made at
different times compare.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np
from numba import njit
from numpy.typing import ArrayLike, NDArray

from splineplan import kernels
from splineplan.errors import ParameterError
from splineplan.geometry import FloatArray, kernel_floats, wrap_angle
from splineplan.obstacles import Obstacles
from splineplan.speed import speed_profile
from splineplan.trajectory import Trajectory, TrajectoryParams, _times, speed_limit

#: Time step [s] of the occupancy and of the forward pass.
DT = 0.1
#: Longest time [s] a plan waits or looks ahead before it gives up on an obstacle.
HORIZON = 120.0
#: Largest angle [rad] between an obstacle's heading and the path's at which it drives the
#: path's way (a vehicle coming up from behind, not one crossing or turning into the path).
SAME_WAY = 0.35
#: Time [s] before and after a conflict over which :meth:`Conflict.as_static` sweeps the
#: obstacle.
SWEEP = 1.0


@dataclass(frozen=True, eq=False)
class MovingObstacle:
    """A vehicle whose future is known: its rectangle's centre and heading over time.

    Attributes
    ----------
    id
        Its name (a SUMO vehicle id, a CommonRoad obstacle id).
    t
        ``(n,)`` absolute times [s], strictly increasing.
    xy, heading
        ``(n, 2)`` centre [m] and ``(n,)`` heading [rad] at those times.
    length, width
        Its rectangle [m].
    stays
        Whether it stays at its last pose after ``t[-1]`` (a plan that ends before the
        vehicle leaves); otherwise it is not there before ``t[0]`` nor after ``t[-1]``.
    """

    id: str
    t: FloatArray
    xy: FloatArray
    heading: FloatArray
    length: float
    width: float
    stays: bool = False

    def __post_init__(self) -> None:
        t = np.asarray(self.t, dtype=float).reshape(-1)
        xy = np.asarray(self.xy, dtype=float).reshape(-1, 2)
        head = np.asarray(self.heading, dtype=float).reshape(-1)
        if len(t) == 0 or len(xy) != len(t) or len(head) != len(t):
            raise ParameterError(f"moving obstacle {self.id!r}: t, xy and heading must have "
                                 "the same, non-zero length")
        if not (np.all(np.isfinite(t)) and np.all(np.isfinite(xy))
                and np.all(np.isfinite(head))):
            raise ParameterError(f"moving obstacle {self.id!r} has non-finite values")
        if np.any(np.diff(t) <= 0):
            raise ParameterError(f"moving obstacle {self.id!r}: times must increase")
        if not (self.length > 0 and self.width > 0):
            raise ParameterError(f"moving obstacle {self.id!r}: length and width must be "
                                 "positive")
        object.__setattr__(self, "t", t)
        object.__setattr__(self, "xy", xy)
        object.__setattr__(self, "heading", np.unwrap(head))

    @classmethod
    def constant_velocity(cls, id: str, t0: float, xy: ArrayLike, heading: float,
                          speed: float, length: float, width: float, *,
                          horizon: float = 10.0, dt: float = 0.5) -> MovingObstacle:
        """A vehicle predicted to keep its heading and speed [m/s] for ``horizon`` [s]."""
        t = t0 + np.arange(0.0, horizon + dt / 2, dt)
        d = np.array([math.cos(heading), math.sin(heading)])
        pos = np.asarray(xy, dtype=float) + np.outer((t - t0) * speed, d)
        return cls(id, t, pos, np.full(len(t), heading), length, width)

    def at(self, times: ArrayLike) -> tuple[FloatArray, FloatArray, NDArray[np.bool_]]:
        """Centre ``(m, 2)`` [m], heading ``(m,)`` [rad] and whether it is there, at
        absolute ``times`` ``(m,)`` [s]."""
        tt = np.asarray(times, dtype=float).reshape(-1)
        there = (tt >= self.t[0]) & ((tt <= self.t[-1]) | self.stays)
        x = np.interp(tt, self.t, self.xy[:, 0])
        y = np.interp(tt, self.t, self.xy[:, 1])
        return np.column_stack((x, y)), wrap_angle(np.interp(tt, self.t, self.heading)), there


@dataclass(frozen=True, eq=False)
class Conflict:
    """Where and when speed alone cannot keep the margin from a moving obstacle.

    Attributes
    ----------
    obstacle
        The obstacle's id.
    t, station
        Absolute time [s] and station [m] along the path where the margin is first lost
        even with full braking.
    xy, heading
        The obstacle's centre [m] and heading [rad] then.
    """

    obstacle: MovingObstacle
    t: float
    station: float
    xy: FloatArray
    heading: float

    def as_static(self, sweep: float = SWEEP, step: float = 0.25) -> Obstacles:
        """The obstacle's rectangles from ``sweep`` [s] before to ``sweep`` after the
        conflict, every ``step`` [s], as static obstacles for level 2."""
        times = self.t + np.arange(-sweep, sweep + step / 2, step)
        xy, head, there = self.obstacle.at(times)
        if not there.any():
            xy, head = self.xy[None, :], np.array([self.heading])
            there = np.array([True])
        n = int(there.sum())
        return Obstacles.from_boxes(xy[there], head[there], np.full(n, self.obstacle.length),
                                    np.full(n, self.obstacle.width),
                                    ids=[f"{self.obstacle.id}@{t:.2f}" for t in times[there]])


@dataclass(frozen=True, eq=False)
class SpeedPlan:
    """Result of :func:`speed_among`: the vehicle's progress along the path over time.

    Attributes
    ----------
    t, s, v
        ``(m,)`` absolute times [s] (steps of ``dt``, the last one where the path ends),
        stations [m] (non-decreasing: equal while it waits) and speeds [m/s].
    yielded
        Ids of the obstacles it stays behind.
    passed
        Ids of the obstacles whose occupied stations it crosses before they arrive.
    conflict
        The first obstacle that it cannot keep the margin from by speed alone, or ``None``.
    """

    t: FloatArray
    s: FloatArray
    v: FloatArray
    yielded: tuple[str, ...] = ()
    passed: tuple[str, ...] = ()
    conflict: Conflict | None = None

    @property
    def clear(self) -> bool:
        """Whether the margin is kept from every moving obstacle."""
        return self.conflict is None


@dataclass(frozen=True, eq=False)
class Occupancy:
    """Stations of the path blocked by each obstacle at each time step.

    Attributes
    ----------
    t
        ``(m,)`` absolute times [s].
    lo, hi
        ``(k, m)`` lowest and highest station [m] at which the vehicle would come closer
        than the margin to obstacle ``i`` at time ``t[j]``; ``nan`` where it would not.
    """

    t: FloatArray
    lo: FloatArray
    hi: FloatArray


def occupancy(s: ArrayLike, xy: ArrayLike, heading: ArrayLike, times: ArrayLike,
              moving: Sequence[MovingObstacle], *, length: float, width: float,
              margin: float) -> Occupancy:
    """Where on the path (stations ``s`` ``(n,)`` [m], centres ``xy`` ``(n, 2)``, headings
    ``(n,)``) each obstacle blocks a vehicle of ``length`` x ``width`` [m] at ``times`` [s].

    Conservative by one sample and one time step on each side, so that the vehicle keeps
    the margin between samples as well (the intervals are widened to the neighbouring
    samples and joined over the neighbouring time steps).
    """
    st = np.asarray(s, dtype=float)
    pts = np.asarray(xy, dtype=float).reshape(-1, 2)
    head = np.asarray(heading, dtype=float)
    tt = np.asarray(times, dtype=float)
    k, m, n = len(moving), len(tt), len(st)
    lo = np.full((k, m), np.nan)
    hi = np.full((k, m), np.nan)
    if k == 0 or m == 0 or n == 0:
        return Occupancy(tt, lo, hi)
    pts, head = kernel_floats(pts), kernel_floats(head)
    spacing = float(np.max(np.diff(st))) if n > 1 else 0.0
    ego_r = math.hypot(length, width) / 2.0
    for i, ob in enumerate(moving):
        oxy, ohead, there = ob.at(tt)
        js = np.flatnonzero(there)
        if len(js) == 0:
            continue
        reach = ego_r + math.hypot(ob.length, ob.width) / 2.0 + margin + spacing
        lo_i, hi_i = kernels.blocked_samples(pts, head, float(length), float(width),
                                             kernel_floats(oxy), kernel_floats(ohead), js,
                                             float(ob.length), float(ob.width), reach,
                                             float(margin))
        blocked = hi_i >= 0
        if not blocked.any():
            continue
        # one time step either side, one sample either side
        lo_w = np.minimum(lo_i, np.minimum(np.roll(lo_i, 1), np.roll(lo_i, -1)))
        hi_w = np.maximum(hi_i, np.maximum(np.roll(hi_i, 1), np.roll(hi_i, -1)))
        blocked_w = blocked | np.roll(blocked, 1) | np.roll(blocked, -1)
        if m > 1:  # no wrap-around from the rolls
            lo_w[0] = min(lo_i[0], lo_i[1])
            lo_w[-1] = min(lo_i[-1], lo_i[-2])
            hi_w[0] = max(hi_i[0], hi_i[1])
            hi_w[-1] = max(hi_i[-1], hi_i[-2])
            blocked_w[0] = blocked[0] | blocked[1]
            blocked_w[-1] = blocked[-1] | blocked[-2]
        lo[i, blocked_w] = st[np.clip(lo_w[blocked_w] - 1, 0, n - 1)]
        hi[i, blocked_w] = st[np.clip(hi_w[blocked_w] + 1, 0, n - 1)]
    return Occupancy(tt, lo, hi)


#: (length, width) [m] of rectangles: one for all, or one each.
BoxSize = tuple[float, float] | tuple[FloatArray, FloatArray]


def box_gap(c1: FloatArray, h1: FloatArray, size1: BoxSize, c2: FloatArray,
            h2: FloatArray, size2: BoxSize) -> FloatArray:
    """Distance [m] between oriented rectangles, 0 where they overlap: centres ``(N, 2)``
    [m], headings ``(N,)`` [rad] and (length, width) [m] of each side (one for all, or
    ``(N,)`` each).

    Two disjoint convex polygons are closest at a corner of one of them, so the distance
    is the smallest of the eight corner-to-rectangle distances (each in the rectangle's own
    frame); rectangles that cross without a corner inside the other are caught by the
    separating-axis test.
    """
    n = len(h1)

    def each(a: float | FloatArray) -> FloatArray:
        return kernel_floats(np.broadcast_to(np.asarray(a, dtype=float), (n,)))
    return kernels.box_gaps(kernel_floats(c1), kernel_floats(h1), each(size1[0]),
                            each(size1[1]), kernel_floats(c2), kernel_floats(h2),
                            each(size2[0]), each(size2[1]))


def speed_among(
    s: ArrayLike,
    xy: ArrayLike,
    heading: ArrayLike,
    v_limit: ArrayLike,
    *,
    t0: float,
    v0: float,
    moving: Sequence[MovingObstacle],
    length: float,
    width: float,
    margin: float,
    a_max: float,
    d_max: float,
    end_speed: float | None = None,
    dt: float = DT,
    pass_from_behind: bool = False,
) -> SpeedPlan:
    """Fastest progress along a fixed path that keeps ``margin`` [m] from every moving
    obstacle: pass in front of it where the limits allow, else stay behind it.

    Parameters
    ----------
    s, xy, heading, v_limit
        The path: stations ``(n,)`` [m] from 0, centres ``(n, 2)`` [m], headings [rad] and
        the speed limit [m/s] of its curve (see :func:`splineplan.trajectory.speed_limit`).
    t0, v0
        Absolute time [s] and speed [m/s] at the path's start.
    moving
        The obstacles.
    length, width, margin
        The vehicle's rectangle and the clearance [m] to keep.
    a_max, d_max
        Acceleration and braking limits [m/s^2].
    end_speed
        Speed at the path's end (0 stops there), ``None`` for as fast as allowed.
    dt
        Time step [s].
    pass_from_behind
        Never yield to an obstacle that first meets the vehicle from behind, driving the
        path's way: drive on as fast as allowed, and name it as the conflict where that
        cannot keep ahead of it. For obstacles whose future is fixed (CommonRoad's recorded
        traffic drives into whatever stands in its way); among SUMO's traffic and other
        planned vehicles, which react, it measured no better (benchmarks/RESULTS.md).
    """
    st = np.asarray(s, dtype=float)
    head = np.asarray(heading, dtype=float)
    lim = np.asarray(v_limit, dtype=float)
    if a_max <= 0 or d_max <= 0 or dt <= 0:
        raise ParameterError("a_max, d_max and dt must be positive")
    # the limits and the braking ahead of them; the forward pass brings the acceleration
    cap = speed_profile(st, lim, a_max=1e9, b_max=d_max, start_speed=float(lim[0]),
                        end_speed=end_speed)
    start = min(max(v0, 0.0), float(cap[0]))
    free = _forward(st, cap, t0, start, dt, None, a_max, d_max)
    if not moving:
        return SpeedPlan(*free)
    span = min(max(max(float(o.t[-1]) if not o.stays else t0 + HORIZON for o in moving),
                   float(free[0][-1])), t0 + HORIZON) - t0
    times = t0 + np.arange(0.0, span + dt, dt)
    occ = occupancy(st, xy, heading, times, moving, length=length, width=width,
                    margin=margin)
    yielded: list[int] = []
    behind: list[int] = []  # they come from behind: staying behind them means stopping
    conflict: Conflict | None = None
    plan = free
    for _ in range(len(moving) + 1):
        wall, owner = _walls(occ, yielded, len(times))
        plan = _forward(st, cap, t0, start, dt, wall, a_max, d_max)
        where = _plan_stations(plan[0], plan[1], occ.t)
        conflict = _first_conflict(where, occ, wall, owner, moving)
        touched = _touched(where, occ, exclude=yielded + behind)
        if not touched:
            break
        i = touched[0]
        (behind if pass_from_behind and _from_behind(where, occ, i, moving[i], st, head)
         else yielded).append(i)
    if conflict is None:  # one from behind that the fastest plan cannot keep ahead of
        conflict = _touch_conflict(where, occ, behind, moving)
    ahead = np.any(where[None, :] > occ.hi, axis=1)  # in front of its stations at some time
    passed = [moving[i].id for i in range(len(moving)) if i not in yielded and ahead[i]]
    return SpeedPlan(*plan, tuple(moving[i].id for i in yielded), tuple(passed), conflict)


def _walls(occ: Occupancy, yielded: list[int], m: int
           ) -> tuple[FloatArray, NDArray[np.int64]]:
    """The lowest station of the yielded obstacles at each time step, and whose."""
    wall = np.full(m, np.inf)
    owner = np.full(m, -1, dtype=np.int64)
    for i in yielded:
        lo = np.where(np.isnan(occ.lo[i]), np.inf, occ.lo[i])
        better = lo < wall
        wall[better], owner[better] = lo[better], i
    return wall, owner


def _forward(s: FloatArray, cap: FloatArray, t0: float, v0: float, dt: float,
             wall: FloatArray | None, a_max: float, d_max: float
             ) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Time steps of driving along ``s`` as fast as the speed cap (a profile over the
    stations) allows, staying behind ``wall`` (a station per time step from ``t0``) with
    room to brake behind every later wall (:func:`_drive`). Returns times, stations and
    speeds; once no wall lies ahead, the rest of the cap from the speed reached, timed at
    the path's stations."""
    end = float(s[-1])
    walls = kernel_floats(np.full(1, np.inf) if wall is None else wall)
    # suffix minimum of the walls: a stop before it is safe against all of them
    floor = kernel_floats(np.minimum.accumulate(walls[::-1])[::-1])
    n, st, v = _drive(kernel_floats(s), kernel_floats(cap), walls, floor, float(v0),
                      float(dt), float(a_max), float(d_max))
    t = t0 + dt * np.arange(n + 1)
    pos, vel = float(st[-1]), float(v[-1])
    if pos >= end - 1e-9:
        st[-1] = end
        if n > 0 and st[-2] < end:  # the last step ends at the path's end
            t[-1] = t[-2] + (end - st[-2]) / max(pos - st[-2], 1e-12) * dt
        return t, st, v
    # no wall ahead any more: the cap from here on
    rest = s > pos + 1e-9
    rs = np.concatenate(([pos], s[rest]))
    rv = speed_profile(rs - pos, np.concatenate(([vel], cap[rest])), a_max=a_max,
                       b_max=d_max, start_speed=vel)
    rt = t[-1] + _times(rs, rv)
    ok = np.isfinite(rt)
    return (np.concatenate((t, rt[1:][ok[1:]])), np.concatenate((st, rs[1:][ok[1:]])),
            np.concatenate((v, rv[1:][ok[1:]])))


@njit(cache=True)
def _drive(s: FloatArray, cap: FloatArray, walls: FloatArray, floor: FloatArray, v0: float,
           dt: float, a_max: float, d_max: float) -> tuple[int, FloatArray, FloatArray]:
    """The forward pass in time while a wall lies ahead: each step takes the highest of a
    few accelerations (full, half, none, a quarter, half and all of the braking limit)
    within the cap from which full braking stays behind every later wall
    (:func:`_safe_speed`), or brakes fully where none does. Returns the steps taken and the
    stations and speeds at steps ``0 .. n``."""
    m = walls.shape[0]
    end = s[-1]
    pos_out = np.empty(m + 1)
    vel_out = np.empty(m + 1)
    pos, vel = 0.0, v0
    pos_out[0], vel_out[0] = pos, vel
    window = int(np.max(cap) / (d_max * dt)) + 2  # steps to stop from the highest speed
    j = 0
    while j < m and floor[j] < np.inf and pos < end - 1e-9:
        j += 1
        vmax = max(np.interp(pos, s, cap), 0.0)
        # the highest of a few accelerations from which full braking stays behind every
        # later wall; full braking where none does (the conflict then shows)
        nv, step = vel, 0.0
        for k in range(6):
            acc = (a_max, 0.5 * a_max, 0.0, -0.25 * d_max, -0.5 * d_max, -d_max)[k]
            nv = min(max(vel + acc * dt, 0.0), vmax)
            if acc < 0.0 and vel + acc * dt < 0.0:  # stops within the step
                step = vel * vel / (-2.0 * acc)
            else:
                step = 0.5 * (vel + nv) * dt
            if j >= m or nv <= _safe_speed(pos + step, walls, floor, j, window, dt, d_max):
                break
        pos += step
        vel = nv
        pos_out[j], vel_out[j] = pos, vel
    return j, pos_out[:j + 1].copy(), vel_out[:j + 1].copy()


@njit(cache=True)
def _safe_speed(pos: float, walls: FloatArray, floor: FloatArray, j: int, window: int,
                dt: float, d_max: float) -> float:
    """Highest speed [m/s] at station ``pos`` at step ``j`` from which full braking stays
    behind ``walls`` at every later step; -1 where ``pos`` is not behind the wall now.

    Braking from ``v`` covers ``v tau - d tau^2 / 2`` in ``tau`` until it stops after
    ``v / d``, ``v^2 / (2 d)`` in all: behind a wall ``w`` ahead at ``tau`` exactly when
    ``v < sqrt(2 d w)`` if that stops by ``tau``, else ``v < w / tau + d tau / 2``. After
    ``window`` steps every speed has stopped: the lowest later wall bounds the rest.
    """
    m = walls.shape[0]
    if walls[j] - pos <= 0.0:
        return -1.0
    best = np.inf
    last = min(m, j + window)
    for i in range(j + 1, last):
        w = walls[i] - pos
        if w == np.inf:
            continue
        if w <= 0.0:
            return -1.0
        tau = (i - j) * dt
        stop = np.sqrt(2.0 * d_max * w)
        best = min(best, stop if stop <= d_max * tau else w / tau + 0.5 * d_max * tau)
    if last < m and floor[last] < np.inf:
        w = floor[last] - pos
        if w <= 0.0:
            return -1.0
        best = min(best, np.sqrt(2.0 * d_max * w))
    return best


def _touched(where: FloatArray, occ: Occupancy, exclude: list[int]) -> list[int]:
    """Obstacles whose blocked stations the plan (its station ``where`` at each time
    step) is on at some time step, earliest first."""
    inside = (where[None, :] >= occ.lo) & (where[None, :] <= occ.hi)
    hit = [int(i) for i in np.flatnonzero(inside.any(axis=1)) if int(i) not in exclude]
    return sorted(hit, key=lambda i: int(np.argmax(inside[i])))


def _from_behind(where: FloatArray, occ: Occupancy, i: int, ob: MovingObstacle,
                 s: FloatArray, heading: FloatArray) -> bool:
    """Whether obstacle ``i`` first meets the plan (its station ``where`` at each time
    step) from behind: the stations it blocks then lie mostly behind the vehicle's, and it
    drove the path's way (within :data:`SAME_WAY`) when it first came onto the path (not a
    vehicle that turns into the path, as at a junction's merge)."""
    inside = (where >= occ.lo[i]) & (where <= occ.hi[i])
    j = int(np.argmax(inside))
    if (occ.lo[i, j] + occ.hi[i, j]) / 2.0 >= where[j]:
        return False
    j0 = int(np.argmax(np.isfinite(occ.hi[i])))  # when it first blocks some station
    _, oh, _ = ob.at([occ.t[j0]])
    on = (occ.lo[i, j0] + occ.hi[i, j0]) / 2.0
    path = float(np.interp(on, s, np.unwrap(heading)))
    return bool(abs(float(wrap_angle(oh[0] - path))) < SAME_WAY)


def _touch_conflict(where: FloatArray, occ: Occupancy, among: list[int],
                    moving: Sequence[MovingObstacle]) -> Conflict | None:
    """The first time step at which the plan is on stations that one of ``among`` blocks."""
    best: tuple[int, int] | None = None
    for i in among:
        inside = (where >= occ.lo[i]) & (where <= occ.hi[i])
        if inside.any() and (best is None or int(np.argmax(inside)) < best[0]):
            best = (int(np.argmax(inside)), i)
    if best is None:
        return None
    j, i = best
    return _conflict_at(moving[i], float(occ.t[j]), float(where[j]))


def _first_conflict(where: FloatArray, occ: Occupancy, wall: FloatArray,
                    owner: NDArray[np.int64], moving: Sequence[MovingObstacle]
                    ) -> Conflict | None:
    """The first time step at which the plan (its station ``where`` at each time step)
    reaches a wall it yields to."""
    bad = (where > wall + 1e-6) & (owner >= 0)
    if not bad.any():
        return None
    j = int(np.argmax(bad))
    return _conflict_at(moving[int(owner[j])], float(occ.t[j]), float(where[j]))


def _conflict_at(ob: MovingObstacle, t: float, station: float) -> Conflict:
    """The conflict with ``ob`` at time ``t`` [s] and the vehicle's ``station`` [m]."""
    xy, head, _ = ob.at([t])
    return Conflict(ob, t, station, xy[0], float(head[0]))


def _plan_stations(t: FloatArray, s: FloatArray, times: FloatArray) -> FloatArray:
    """The plan's station at ``times`` (``inf`` once it has left the path)."""
    out = np.interp(times, t, s)
    return np.where(times > t[-1], np.inf, out)


# ---- trajectories ----------------------------------------------------------------------------
def retime(trajectory: Trajectory, moving: Sequence[MovingObstacle], params: TrajectoryParams,
           *, t0: float, length: float, width: float, margin: float,
           end_speed: float | None = None, v_limit: FloatArray | None = None,
           pass_from_behind: bool = False, path_limit: FloatArray | None = None
           ) -> tuple[Trajectory, SpeedPlan]:
    """The same path with the speed of :func:`speed_among`, from the trajectory's start
    speed to at most ``end_speed`` (default: its own end speed). ``v_limit`` ``(n,)`` [m/s]
    at the trajectory's samples lowers the path's own speed limit (a cap that times the
    arrival at a goal). The result's times are from ``t0`` like the trajectory's own (from
    0); a wait is two samples at one station. ``pass_from_behind``: see
    :func:`speed_among`. ``path_limit`` ``(n,)`` [m/s]: the path's own speed limit, where
    it is known better than :func:`~splineplan.trajectory.speed_limit` of its curvature
    (default)."""
    tr = trajectory
    lim = speed_limit(tr.s, tr.curvature, params) if path_limit is None else path_limit
    if v_limit is not None:
        lim = np.minimum(lim, v_limit)
    plan = speed_among(tr.s, tr.xy, tr.heading, lim, t0=t0, v0=float(tr.speed[0]),
                       moving=moving, length=length, width=width, margin=margin,
                       pass_from_behind=pass_from_behind,
                       a_max=params.a_max, d_max=params.b_max,
                       end_speed=float(tr.speed[-1]) if end_speed is None else end_speed)
    return _with_plan(tr, plan, t0), plan


def _with_plan(tr: Trajectory, plan: SpeedPlan, t0: float) -> Trajectory:
    """``tr`` at the plan's steps and at its own stations, with the plan's times and speeds
    (a wait is samples at one station; a trajectory the plan leaves unfinished ends
    there)."""
    t, s, v = plan.t - t0, plan.s, plan.v
    # each of the trajectory's own stations within reach, at the time the plan passes it
    own = tr.s[(tr.s > s[0]) & (tr.s < s[-1])]
    k = np.clip(np.searchsorted(s, own, side="left"), 1, len(s) - 1)
    ds = s[k] - s[k - 1]
    frac = np.where(ds > 0, (own - s[k - 1]) / np.where(ds > 0, ds, 1.0), 1.0)
    t_own = t[k - 1] + frac * (t[k] - t[k - 1])
    v_own = v[k - 1] + frac * (v[k] - v[k - 1])
    times = np.concatenate((t, t_own))
    order = np.argsort(times, kind="stable")
    times, stations = times[order], np.concatenate((s, own))[order]
    speeds = np.concatenate((v, v_own))[order]
    keep = np.concatenate(([True], np.diff(times) > 1e-9))
    times, stations, speeds = times[keep], np.maximum.accumulate(stations[keep]), speeds[keep]
    head = np.unwrap(tr.heading)

    def at(a: FloatArray) -> FloatArray:
        return np.asarray(np.interp(stations, tr.s, a))

    return replace(
        tr, t=times, x=at(tr.x), y=at(tr.y), heading=wrap_angle(at(head)), speed=speeds,
        curvature=at(tr.curvature), s=stations, clearance_obstacles=at(tr.clearance_obstacles),
        clearance_road=at(tr.clearance_road))


def published(trajectory: Trajectory, *, id: str, t0: float, length: float, width: float,
              stays: bool = False) -> MovingObstacle:
    """A planned vehicle's trajectory (times from ``t0`` [s]) as others see it."""
    t = t0 + np.asarray(trajectory.t, dtype=float)
    ok = np.isfinite(t)
    t, xy, head = t[ok], trajectory.xy[ok], trajectory.heading[ok]
    keep = np.concatenate(([True], np.diff(t) > 1e-9))
    return MovingObstacle(id, t[keep], xy[keep], head[keep], length, width, stays)
