"""Moving obstacles with a known future: pass or yield by speed, conflict where speed cannot.

Every clearance is judged by shapely on the two rectangles at a fine time step, independent
of the module's own rectangle distance and occupancy.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
import shapely
from hypothesis import given, settings
from hypothesis import strategies as st

from splineplan.corridor import Corridor
from splineplan.geometry import box_corners
from splineplan.kernels import box_gap_one
from splineplan.planner import plan_corridor
from splineplan.roadmap import RoadmapParams
from splineplan.spacetime import MovingObstacle, box_gap, published, retime, speed_among
from splineplan.speed import speed_profile
from splineplan.trajectory import Trajectory, TrajectoryParams, speed_limit

L, W, MARGIN = 4.5, 1.8, 0.5
TP = TrajectoryParams(s_max=13.0)


def straight(length: float = 120.0) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    s = np.arange(0.0, length + 0.01, 0.5)
    return s, np.column_stack((s, np.zeros_like(s))), np.zeros_like(s), np.full_like(s, 13.0)


def boxes(xy: np.ndarray, heading: np.ndarray, length: float, width: float) -> np.ndarray:
    c = box_corners(np.atleast_2d(xy), np.atleast_1d(heading), np.full(len(np.atleast_1d(
        heading)), length), np.full(len(np.atleast_1d(heading)), width))
    return shapely.polygons(c)


def closest_approach(t: np.ndarray, s: np.ndarray, path_xy: np.ndarray, path_s: np.ndarray,
                     path_h: np.ndarray, ob: MovingObstacle, dt: float = 0.02) -> float:
    """Smallest shapely distance between the vehicle on the plan and the obstacle."""
    times = np.arange(max(t[0], ob.t[0]), min(t[-1], ob.t[-1]), dt)
    if len(times) == 0:
        return math.inf
    where = np.interp(times, t, s)
    x = np.interp(where, path_s, path_xy[:, 0])
    y = np.interp(where, path_s, path_xy[:, 1])
    h = np.interp(where, path_s, path_h)
    oxy, oh, there = ob.at(times)
    ego = boxes(np.column_stack((x, y))[there], h[there], L, W)
    other = boxes(oxy[there], oh[there], ob.length, ob.width)
    return float(np.min(shapely.distance(ego, other))) if len(ego) else math.inf


def plan_against(ob: MovingObstacle, v0: float = 10.0):  # type: ignore[no-untyped-def]
    s, xy, h, lim = straight()
    return speed_among(s, xy, h, lim, t0=0.0, v0=v0, moving=[ob], length=L, width=W,
                       margin=MARGIN, a_max=2.0, d_max=4.0)


@settings(max_examples=60, deadline=None)
@given(st.floats(-8, 8), st.floats(-8, 8), st.floats(-math.pi, math.pi),
       st.floats(-math.pi, math.pi), st.floats(1, 6), st.floats(0.5, 3))
def test_box_gap_is_shapelys_distance(x: float, y: float, h1: float, h2: float,
                                      ln: float, wd: float) -> None:
    want = shapely.distance(boxes(np.array([0.0, 0.0]), h1, L, W)[0],
                            boxes(np.array([x, y]), h2, ln, wd)[0])
    got = box_gap(np.array([[0.0, 0.0]]), np.array([h1]), (L, W), np.array([[x, y]]),
                  np.array([h2]), (ln, wd))
    assert got[0] == pytest.approx(want, abs=1e-9)
    one = box_gap_one(0.0, 0.0, h1, L, W, x, y, h2, ln, wd)  # the compiled form
    assert one == pytest.approx(want, abs=1e-9)


def test_a_crossing_car_that_comes_first_is_yielded_to_with_the_margin() -> None:
    s, xy, h, _ = straight()
    # crosses the path at x = 50 at t = 4 s; at 10-13 m/s the vehicle would meet it there
    ob = MovingObstacle.constant_velocity("crossing", 0.0, (50.0, -32.0), math.pi / 2, 8.0,
                                          L, W, horizon=10.0)
    free = plan_against(MovingObstacle("far", np.array([0.0, 1.0]),
                                       np.array([[0, 500.0], [0, 501.0]]), np.zeros(2), L, W))
    assert closest_approach(free.t, free.s, xy, s, h, ob) < MARGIN  # a real conflict
    plan = plan_against(ob)
    assert plan.yielded == ("crossing",) and plan.conflict is None
    assert closest_approach(plan.t, plan.s, xy, s, h, ob) >= MARGIN - 0.02
    assert plan.t[-1] > free.t[-1]  # it lost time, not the margin
    acc = np.diff(plan.v) / np.diff(plan.t)
    assert np.all((acc >= -4.0 - 1e-6) & (acc <= 2.0 + 1e-6))  # within the limits


def test_a_crossing_car_that_comes_late_is_passed_in_front_of() -> None:
    s, xy, h, _ = straight()
    ob = MovingObstacle.constant_velocity("late", 0.0, (50.0, -60.0), math.pi / 2, 8.0,
                                          L, W, horizon=12.0)
    plan = plan_against(ob)
    assert plan.passed == ("late",) and not plan.yielded
    assert closest_approach(plan.t, plan.s, xy, s, h, ob) >= MARGIN - 0.02


def test_a_slower_car_ahead_is_followed_at_its_speed() -> None:
    s, xy, h, _ = straight(200.0)
    ob = MovingObstacle.constant_velocity("lead", 0.0, (20.0, 0.0), 0.0, 5.0, L, W,
                                          horizon=40.0)
    lim = np.full_like(s, 13.0)
    plan = speed_among(s, xy, h, lim, t0=0.0, v0=10.0, moving=[ob], length=L, width=W,
                       margin=MARGIN, a_max=2.0, d_max=4.0)
    assert plan.yielded == ("lead",) and plan.conflict is None
    assert closest_approach(plan.t, plan.s, xy, s, h, ob) >= MARGIN - 0.02
    late = plan.t > 15.0
    assert np.median(plan.v[late]) == pytest.approx(5.0, abs=0.5)


def test_an_oncoming_car_on_the_path_is_a_conflict_for_level_2() -> None:
    straight()
    ob = MovingObstacle.constant_velocity("oncoming", 0.0, (90.0, 0.0), math.pi, 10.0, L, W,
                                          horizon=20.0)
    plan = plan_against(ob)
    assert plan.conflict is not None and plan.conflict.obstacle.id == "oncoming"
    # where it is lost, the vehicle has no way out by speed: the obstacle is on the path
    static = plan.conflict.as_static()
    assert len(static) > 1
    assert np.min(static.distance(np.array([[plan.conflict.station, 0.0]]))) < L


def test_a_faster_car_from_behind_is_not_stopped_for() -> None:
    """A car comes up from behind in the lane faster than the vehicle may drive: staying
    behind it would mean stopping in its way (the rear-end collisions of recorded
    CommonRoad traffic). With ``pass_from_behind`` the plan drives on as fast as allowed
    and names it as the conflict for level 2; a slower car behind is never met."""
    s, xy, h, lim = straight()
    fast = MovingObstacle.constant_velocity("fast", 0.0, (-10.0, 0.0), 0.0, 16.0, L, W,
                                            horizon=15.0)

    def plan_against(ob: MovingObstacle):  # type: ignore[no-untyped-def]
        return speed_among(s, xy, h, lim, t0=0.0, v0=10.0, moving=[ob], length=L, width=W,
                           margin=MARGIN, a_max=2.0, d_max=4.0, pass_from_behind=True)

    stop = speed_among(s, xy, h, lim, t0=0.0, v0=10.0, moving=[fast], length=L, width=W,
                       margin=MARGIN, a_max=2.0, d_max=4.0)
    assert "fast" in stop.yielded and stop.v.min() < 5.0  # the default brakes in its way
    plan = plan_against(fast)
    assert "fast" not in plan.yielded
    assert plan.conflict is not None and plan.conflict.obstacle.id == "fast"
    assert np.all(np.diff(plan.v) >= -1e-9)  # it never brakes for it
    assert plan.v[-1] == pytest.approx(13.0, abs=0.01)
    slow = MovingObstacle.constant_velocity("slow", 0.0, (-10.0, 0.0), 0.0, 8.0, L, W,
                                            horizon=15.0)
    plan = plan_against(slow)
    assert not plan.yielded and plan.conflict is None
    assert closest_approach(plan.t, plan.s, xy, s, h, slow) >= MARGIN


def test_a_car_in_the_next_lane_does_not_slow_the_vehicle() -> None:
    s, xy, h, lim = straight()
    ob = MovingObstacle.constant_velocity("beside", 0.0, (5.0, 3.2), 0.0, 10.0, L, W,
                                          horizon=20.0)
    alone = speed_among(s, xy, h, lim, t0=0.0, v0=10.0, moving=[], length=L, width=W,
                        margin=MARGIN, a_max=2.0, d_max=4.0)
    plan = plan_against(ob)
    assert not plan.yielded and plan.conflict is None
    assert plan.t[-1] == pytest.approx(alone.t[-1], abs=0.15)


@settings(max_examples=40, deadline=None)
@given(st.floats(20, 100), st.floats(-2.6, -0.5), st.floats(3, 14), st.floats(0, 8),
       st.floats(3, 13))
def test_the_margin_is_kept_or_the_conflict_reported(x: float, angle: float, speed: float,
                                                     arrive: float, v0: float) -> None:
    """A car crossing the path at ``x`` [m] at a random angle, speed and time: the plan
    keeps the margin from it at every time, or says that speed alone cannot."""
    s, xy, h, _ = straight()
    heading = -angle  # from the right side of the path, going left-forward or left-back
    d = np.array([math.cos(heading), math.sin(heading)])
    start = np.array([x, 0.0]) - d * speed * arrive
    ob = MovingObstacle.constant_velocity("c", 0.0, start, heading, speed, L, W,
                                          horizon=arrive + 8.0)
    plan = plan_against(ob, v0)
    if plan.conflict is None:
        assert closest_approach(plan.t, plan.s, xy, s, h, ob) >= MARGIN - 0.05
    assert np.all(np.diff(plan.s) >= -1e-9)


def corridor_plan() -> Trajectory:
    ref = np.column_stack((np.linspace(0, 150, 151), np.zeros(151)))
    cor = Corridor.from_reference(ref, np.full(151, 3.5), np.full(151, -3.5))
    return plan_corridor(cor, None, (2.0, 0.0), 0.0, roadmap_params=RoadmapParams(),
                         params=TP, start_speed=8.0).trajectory


def test_retime_waits_at_a_station_and_publishes_what_others_see() -> None:
    tr = corridor_plan()
    # a car stands across the path at x = 60 m from 1 s to 9 s, then drives off
    ob = MovingObstacle("crossing", np.array([11.0, 19.0, 21.0]),
                        np.array([[60.0, 0.0], [60.0, 0.0], [60.0, 12.0]]),
                        np.full(3, math.pi / 2), L, W)
    new, plan = retime(tr, [ob], TP, t0=10.0, length=L, width=W, margin=MARGIN)
    assert plan.yielded == ("crossing",) and plan.conflict is None
    stop = np.flatnonzero(np.diff(new.s) == 0)  # a wait: samples at one station
    assert len(stop) and np.all(np.diff(stop) == 1)  # one wait, without creeping
    assert new.t[stop[-1] + 1] - new.t[stop[0]] > 1.0
    assert new.s[stop[0]] + 2.0 < 60.0 - L / 2 - W / 2 - MARGIN  # the path starts at x = 2
    assert np.all(np.diff(new.t) >= 0) and np.all(np.diff(new.s) >= 0)
    assert new.feasible == tr.feasible
    # the trajectory says what the plan says: the station at the plan's times
    assert np.allclose(np.interp(plan.t - 10.0, new.t, new.s), plan.s, atol=0.3)
    assert closest_approach(new.t + 10.0, new.s, tr.xy, tr.s, tr.heading, ob) >= MARGIN - 0.05
    # the path is the same path
    x, y, _, _ = tr.at_station(new.s)
    assert np.allclose(x, new.x, atol=1e-6) and np.allclose(y, new.y, atol=1e-6)
    seen = published(new, id="ego", t0=10.0, length=L, width=W)
    times = np.linspace(10.5, 10.0 + new.t[-1] - 0.5, 50)
    px, py, _, _ = new.at_time(times - 10.0)
    oxy, _, there = seen.at(times)
    assert there.all() and np.allclose(oxy, np.column_stack((px, py)), atol=1e-6)


def test_without_obstacles_retime_keeps_the_trajectorys_own_profile() -> None:
    """Two implementations of the same limits (speed.py's passes over the stations and the
    forward pass in time here) agree."""
    tr = corridor_plan()
    for start in (0.0, 8.0):
        base = replace(tr, speed=speed_profile(tr.s, speed_limit(tr.s, tr.curvature, TP),
                                               a_max=TP.a_max, b_max=TP.b_max,
                                               start_speed=start, end_speed=0.0))
        new, plan = retime(base, [], TP, t0=3.0, length=L, width=W, margin=MARGIN)
        assert plan.clear and not plan.yielded
        _, _, _, v_base = base.at_station(new.s)
        assert np.allclose(new.speed, v_base, atol=0.05)
        assert new.t[-1] == pytest.approx(float(np.sum(2 * np.diff(base.s) / np.maximum(
            base.speed[:-1] + base.speed[1:], 1e-9))), rel=0.01)


def test_bad_moving_obstacles_are_refused() -> None:
    from splineplan.errors import SplineplanError

    with pytest.raises(SplineplanError, match="times must increase"):
        MovingObstacle("x", np.array([0.0, 0.0]), np.zeros((2, 2)), np.zeros(2), L, W)
    with pytest.raises(SplineplanError, match="length and width"):
        MovingObstacle("x", np.array([0.0]), np.zeros((1, 2)), np.zeros(1), 0.0, W)


def test_retime_keeps_under_a_given_speed_limit() -> None:
    """``v_limit`` lowers the path's own limit (CommonRoad's goal timing caps the speed):
    the car never exceeds it, and among the same obstacle arrives later than without it."""
    tr = corridor_plan()
    ob = MovingObstacle("far", np.array([0.0, 30.0]), np.array([[500.0, 50.0], [510.0, 50.0]]),
                        np.zeros(2), L, W)
    free, _ = retime(tr, [ob], TP, t0=0.0, length=L, width=W, margin=MARGIN)
    cap = np.full(len(tr.s), 6.0)
    slow, _ = retime(tr, [ob], TP, t0=0.0, length=L, width=W, margin=MARGIN, v_limit=cap)
    assert slow.speed.max() <= 6.0 + 1e-6 < free.speed.max()
    assert slow.t[-1] > free.t[-1] + 1.0
