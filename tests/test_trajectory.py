"""Level 3: spline, curvature, optimisation, feasibility (checked with shapely), errors."""

from __future__ import annotations

import itertools
from dataclasses import replace

import numpy as np
import pytest
from conftest import winding_line
from hypothesis import given, settings
from hypothesis import strategies as st
from shapely import affinity
from shapely.geometry import LineString, Polygon, box
from test_speed import towed_by_ode

from splineplan.corridor import Corridor
from splineplan.errors import ParameterError, RoadBlockedError, TrajectoryError
from splineplan.obstacles import Obstacles
from splineplan.planner import elongate_for_roadmap, plan_corridor
from splineplan.roadmap import Roadmap, RoadmapParams, plan_roadmap
from splineplan.speed import allowed_speed
from splineplan.trajectory import (
    SLOW_START,
    Trajectory,
    TrajectoryParams,
    curvature_discrete,
    curvature_from_derivatives,
    plan_trajectory,
)

TP = TrajectoryParams()


def straight_road(length: float = 120.0, width: float = 9.6) -> Corridor:
    ref = np.column_stack((np.linspace(0.0, length, 3), np.zeros(3)))
    return Corridor.from_reference(ref, np.full(3, width / 2), np.full(3, -width / 2))


def make_roadmap(xy: np.ndarray, corridor: Corridor, params: RoadmapParams | None = None,
                 start_xy: np.ndarray | None = None) -> Roadmap:
    """A Roadmap whose chosen path is the polyline ``xy`` (a stand-in for level 2)."""
    params = params or RoadmapParams()
    xy = np.asarray(xy, dtype=float)
    sl = corridor.to_sl(xy)
    m = len(xy)
    w = np.ones(m)
    return Roadmap(
        xy=xy, s=sl[:, 0], l=sl[:, 1], width=w, bottleneck_width=1.0, bottleneck_index=0,
        length=float(np.hypot(*np.diff(xy, axis=0).T).sum()), graph_xy=xy,
        graph_s=sl[:, 0], graph_l=sl[:, 1], graph_width=w, graph_line=np.arange(m),
        graph_lo=sl[:, 1] - 0.5, graph_hi=sl[:, 1] + 0.5,
        arcs=np.column_stack((np.arange(m - 1), np.arange(1, m))), path=np.arange(m),
        start_xy=xy[0] if start_xy is None else np.asarray(start_xy, dtype=float),
        params=params)


def sine_path(length: float = 120.0, amp: float = 2.4, wave: float = 30.0) -> np.ndarray:
    """S-bends every ``wave / 2`` [m], sampled every metre like a level-2 roadmap."""
    xs = np.arange(0.0, length + 0.5, 1.0)
    return np.column_stack((xs, -amp * np.cos(2 * np.pi * xs / wave)))


#: Obstacles beside the S-bends' lobes, 2.1 m from the vehicle's side: flattening is limited.
LOBE_OBSTACLES = np.array([[30.0, 1.5], [45.0, -1.5], [60.0, 1.5], [75.0, -1.5], [90.0, 1.5]])


def slalom() -> tuple[Corridor, Obstacles, Roadmap]:
    """Cars alternating between the two lanes of a 7 m road, and level 2's roadmap."""
    road = straight_road(150.0, 7.0)
    obstacles = Obstacles.from_boxes(
        np.array([[30.0, -1.6], [50.0, 1.6], [70.0, -1.6], [90.0, 1.6]]), 0.0, 4.5, 1.8)
    rp = RoadmapParams()
    return road, obstacles, plan_roadmap(road, elongate_for_roadmap(road, obstacles, rp),
                                         np.array([1.0, -1.75]), rp)


def footprints(tr: Trajectory, rp: RoadmapParams) -> list[Polygon]:
    """The vehicle rectangle at each sample, built by shapely."""
    base = box(-rp.vehicle_length / 2, -rp.vehicle_width / 2,
               rp.vehicle_length / 2, rp.vehicle_width / 2)
    return [affinity.translate(affinity.rotate(base, h, origin=(0, 0), use_radians=True), x, y)
            for x, y, h in zip(tr.x, tr.y, tr.heading, strict=True)]


def shapely_violations(tr: Trajectory, corridor: Corridor, obstacles: Obstacles,
                       rp: RoadmapParams, tol: float = 1e-6) -> tuple[int, int]:
    """Samples whose footprint touches an obstacle grown by the safety margin, and samples
    off the road shrunk by the trajectory's road margin."""
    grown = [Polygon(p).buffer(rp.safety_margin - tol) for p in obstacles.polygons()]
    # straight roads along +x only; the planner extends the road past its ends
    ref = corridor.reference
    road = box(ref[0, 0] - 10.0, float(corridor.right.max()), ref[-1, 0] + 10.0,
               float(corridor.left.min())).buffer(-(tr.road_margin - tol), join_style=2)
    hits = off = 0
    for fp in footprints(tr, rp):
        hits += any(fp.intersects(g) for g in grown)
        off += not road.contains(fp)
    return hits, off


# ---- curvature -------------------------------------------------------------------------
@pytest.mark.parametrize("radius", [5.0, 28.0, 200.0])
def test_curvature_forms_agree_on_a_circle(radius: float) -> None:
    h = 0.25
    ang = np.arange(0.0, 2.0, h / radius)
    pts = radius * np.column_stack((np.cos(ang), np.sin(ang)))
    # chord h' between samples; equation (2) uses the arc-length spacing h
    k_disc = curvature_discrete(pts, h)
    d1 = radius * np.column_stack((-np.sin(ang), np.cos(ang)))
    d2 = radius * np.column_stack((-np.cos(ang), -np.sin(ang)))
    k_der = curvature_from_derivatives(d1, d2)
    np.testing.assert_allclose(k_der, 1.0 / radius, rtol=1e-12)  # counter-clockwise: > 0
    np.testing.assert_allclose(k_disc, 1.0 / radius, rtol=1e-3)
    np.testing.assert_allclose(curvature_from_derivatives(d1, -d2), -1.0 / radius, rtol=1e-12)


def test_discrete_curvature_of_the_planned_spline_matches_derivatives() -> None:
    # equation (2) is a finite difference: samples 2 cm apart, finer than the first curve's
    # changes of curvature (it turns from 0.23 to 0 1/m within 0.3 m after the lead-in)
    road = straight_road()
    tr = plan_trajectory(make_roadmap(sine_path(), road), road, Obstacles.empty(),
                         TrajectoryParams(max_iterations=0, sample_spacing=0.02), 0.0)
    h = float(np.diff(tr.s).mean())
    away = (tr.s > 3.0) & (tr.s < tr.length - 3.0)  # clamped ends: fewer neighbours
    k_disc = curvature_discrete(tr.xy, h)[away]
    np.testing.assert_allclose(k_disc, np.abs(tr.curvature)[away], rtol=0.02, atol=2e-3)


# ---- straight road ---------------------------------------------------------------------
def test_straight_empty_road_reaches_s_max_and_stays_straight() -> None:
    road = straight_road()
    xs = np.arange(0.0, 120.5, 1.0)
    rm = make_roadmap(np.column_stack((xs, np.full_like(xs, -1.6))), road)
    tr = plan_trajectory(rm, road, Obstacles.empty(), None, 0.0)
    assert tr.feasible
    assert tr.iterations.tried == 0
    np.testing.assert_allclose(tr.y, -1.6, atol=1e-9)
    np.testing.assert_allclose(tr.heading, 0.0, atol=1e-9)
    accel_dist = TP.s_max**2 / (2 * TP.a_max)
    assert tr.speed[0] == 0.0
    np.testing.assert_allclose(tr.speed[tr.s > accel_dist + TP.sample_spacing], TP.s_max)
    assert tr.min_speed_before == tr.min_speed_after == TP.s_max
    assert tr.length == pytest.approx(120.0, abs=1e-6)


# ---- optimisation ----------------------------------------------------------------------
def test_slalom_optimisation_raises_min_speed_and_stays_feasible() -> None:
    road, obstacles, rm = slalom()
    rp = rm.params
    tr = plan_trajectory(rm, road, obstacles, None, 0.0)
    assert tr.min_speed_after > tr.min_speed_before + 5.0
    assert tr.iterations.accepted > 0
    assert tr.iterations.tried == tr.iterations.accepted + tr.iterations.refused
    assert tr.feasible
    assert shapely_violations(tr, road, obstacles, rp) == (0, 0)
    # first, heading and last control points stay put
    np.testing.assert_allclose(tr.control_points[[0, -1]], [rm.start_xy, rm.xy[-1]])
    assert tr.control_points[1, 1] == pytest.approx(rm.start_xy[1])


def test_slalom_every_round_keeps_the_footprint_clear() -> None:
    """Every intermediate curve that reports itself feasible is clear (shapely); rounds
    never sharpen the worst bend; the final curve is feasible."""
    road, obstacles, rm = slalom()
    # one placement of the vertices (the midpoints): a roadmap with bands may fall back to
    # the midpoints where it ends infeasible, and that changes with the moves allowed
    rm = rm.at_midpoints()
    worst = np.inf
    for cap in (0, 1, 3, 10, 30, 100, 1000):
        tr = plan_trajectory(rm, road, obstacles, TrajectoryParams(max_iterations=cap), 0.0)
        assert tr.iterations.tried <= cap
        if tr.feasible:
            assert shapely_violations(tr, road, obstacles, rm.params) == (0, 0)
        assert tr.min_speed_after >= tr.min_speed_before - 1e-9
        kmax = float(np.abs(tr.curvature).max())
        assert kmax <= worst + 1e-6
        worst = kmax
    assert tr.feasible


def test_empty_road_off_centre_start_changes_lane_smoothly() -> None:
    """Level 2's first vertex is on the centre line, 3.2 m beside the vehicle."""
    road = straight_road(300.0, 9.6)
    rm = plan_roadmap(road, Obstacles.empty(), np.array([1.0, -3.2]))
    tr = plan_trajectory(rm, road, Obstacles.empty(), None, 0.0)
    assert tr.feasible
    assert tr.iterations.control_points < 30  # simplified: not one per sweep line
    assert tr.y[0] == pytest.approx(-3.2) and tr.heading[0] == pytest.approx(0.0)
    assert np.all(np.diff(tr.y) >= -1e-9)  # one monotone lane change
    assert tr.min_speed_after == pytest.approx(TP.s_max)
    assert tr.speed.max() == pytest.approx(TP.s_max)
    assert shapely_violations(tr, road, Obstacles.empty(), rm.params) == (0, 0)


def bend_ahead(width: float, radius: float, straight: float) -> Corridor:
    """A road of ``width`` [m]: ``straight`` [m] along +x, a left bend of ``radius`` [m]
    by 90 degrees, 40 m on."""
    run = np.column_stack((np.arange(0.0, straight + 0.25, 0.5), np.zeros(int(straight * 2) + 1)))
    th = np.linspace(0.0, np.pi / 2.0, 60)[1:]
    arc = np.column_stack((straight + radius * np.sin(th), radius * (1.0 - np.cos(th))))
    up = np.column_stack((np.full(40, straight + radius), radius + np.arange(1.0, 41.0)))
    ref = np.vstack((run, arc, up))
    return Corridor.from_reference(ref, np.full(len(ref), width / 2.0),
                                   np.full(len(ref), -width / 2.0))


@pytest.mark.parametrize(("width", "straight", "lateral", "speed"),
                         [(3.2, 40.0, 0.3, 13.89), (3.2, 70.0, 0.3, 10.0),
                          (6.4, 40.0, 0.6, 13.89)])
def test_a_plan_at_speed_beside_level_2s_path_starts_at_that_speed(
        width: float, straight: float, lateral: float, speed: float) -> None:
    """A vehicle at speed a little beside level 2's path, a sharp bend ahead (a closed
    loop's replan at its horizon): the curve leaves the vehicle's offset gently enough
    for the wheels to follow at that speed, instead of swinging onto the path within a
    few metres and asking the vehicle to start at a third of its speed (before: 4.0-6.5
    m/s). The bend ahead is driven within the turning limit."""
    road = bend_ahead(width, 8.0, straight)
    rm = plan_roadmap(road, Obstacles.empty(), np.array([2.0, lateral]))
    tr = plan_trajectory(rm, road, Obstacles.empty(), TP, 0.0, start_speed=speed)
    assert tr.feasible
    assert tr.speed[0] == pytest.approx(speed)
    assert_wheels_keep_up(tr)
    assert np.abs(tr.curvature).max() <= TP.kappa_max + 1e-9


def test_one_obstacle_real_roadmap() -> None:
    road = straight_road(150.0, 9.6)
    obstacles = Obstacles.from_boxes(np.array([[60.0, -3.0]]), 0.0, 4.5, 1.8)
    rm = plan_roadmap(road, obstacles, np.array([1.0, -3.2]))
    tr = plan_trajectory(rm, road, obstacles, None, 0.0)
    assert tr.feasible
    assert tr.min_speed_after == pytest.approx(TP.s_max)
    assert tr.iterations.control_points < 15
    assert shapely_violations(tr, road, obstacles, rm.params) == (0, 0)


def test_every_accepted_move_keeps_the_curve_feasible() -> None:
    """Step the cap: each intermediate curve that reports itself feasible is clear."""
    road = straight_road()
    obstacles = Obstacles.from_boxes(LOBE_OBSTACLES[:3], 0.0, 4.5, 1.8)
    rp = RoadmapParams()
    rm = make_roadmap(sine_path(), road, rp)
    for cap in (0, 1, 3, 10, 30, 100, 300):
        tr = plan_trajectory(rm, road, obstacles, TrajectoryParams(max_iterations=cap), 0.0)
        assert tr.iterations.tried <= cap
        if tr.feasible:
            assert shapely_violations(tr, road, obstacles, rp) == (0, 0)
        assert tr.min_speed_after >= tr.min_speed_before - 1e-9
    assert tr.feasible


def test_infeasible_start_is_reported_not_hidden() -> None:
    """Walls force a 6 m lateral jump within 2 m: no curve within the turning radius does
    it."""
    road = straight_road()
    xs = np.arange(0.0, 60.5, 1.0)
    lat = np.where(xs < 30, -3.0, 3.0)
    obstacles = Obstacles.from_boxes(np.array([[26.5, 2.0], [33.5, -2.0]]), 0.0, 5.0, 4.0)
    tr = plan_trajectory(make_roadmap(np.column_stack((xs, lat)), road), road, obstacles,
                         TrajectoryParams(max_iterations=0), 0.0)
    assert not tr.feasible
    assert (np.abs(tr.curvature).max() > TP.kappa_max
            or tr.clearance_obstacles.min() < tr.safety_margin
            or tr.clearance_road.min() < tr.road_margin)
    assert_violations_say_why(tr, road, obstacles)


def assert_wheels_keep_up(tr: Trajectory, params: TrajectoryParams = TP) -> None:
    """Driven at its speeds, the trajectory turns the front wheels of the kinematic
    single-track car (centre half the wheelbase ahead of the rear axle, which is towed
    without slipping sideways) no faster than the steering rate: the car integrated in the
    plane along the curve (curvature linear between samples, the body in the steady turn
    of the start's curvature, as the speed tests write it), its wheel angle's change over
    each step of the trajectory's times, to within the two integrations' 0.2 %."""
    s = np.asarray(tr.s, dtype=float)
    kappa = np.asarray(tr.curvature, dtype=float)
    slip0 = float(np.arcsin(np.clip(kappa[0] * params.wheelbase / 2.0, -1.0, 1.0)))
    angle = towed_by_ode(s, lambda x: np.interp(x, s, kappa), params.wheelbase, slip0)
    dt = np.diff(tr.t)
    ok = np.isfinite(dt) & (dt > 0)
    rate = np.abs(np.diff(angle))[ok] / dt[ok]
    assert rate.max(initial=0.0) <= params.max_steering_rate * 1.002


def assert_violations_say_why(tr: Trajectory, corridor: Corridor, obstacles: Obstacles,
                              rp: RoadmapParams | None = None) -> None:
    """``violations`` is empty exactly when the trajectory is feasible, and each one is
    true of the curve where it says: its point lies on the curve at its arc length, and
    there the footprint by shapely comes within the margin it names (to within the
    curve's change over a sample), or the curvature is beyond the limit."""
    rp = rp or RoadmapParams()
    assert tr.feasible == (not tr.violations)
    base = box(-rp.vehicle_length / 2, -rp.vehicle_width / 2,
               rp.vehicle_length / 2, rp.vehicle_width / 2)
    for v in tr.violations:
        assert 0.0 <= v.s <= tr.length + 1e-6
        x, y, h, _ = tr.at_station(v.s)
        assert np.hypot(x - v.x, y - v.y) < 0.05
        fp = affinity.translate(affinity.rotate(base, float(h), origin=(0, 0),
                                                use_radians=True), float(x), float(y))
        if v.kind == "obstacle":
            assert v.value < v.limit == tr.safety_margin
            dist = min(fp.distance(Polygon(p)) for p in obstacles.polygons())
            assert dist < v.limit + 0.05
        elif v.kind == "road":
            assert v.value < v.limit == tr.road_margin
            road = Polygon(corridor.polygon())
            assert fp.difference(road.buffer(-v.limit)).area > 0 or \
                road.exterior.distance(fp) < v.limit + 0.05
        else:
            assert v.kind == "curvature" and v.value > v.limit == TP.kappa_max
            # the curve itself, densely: a turn tighter than the limit within 0.5 m
            # (the optimiser's samples can catch a peak between the trajectory's)
            assert tr.spline is not None
            u = np.linspace(0.0, 1.0, 20001)
            near = np.hypot(*(tr.spline(u) - [v.x, v.y]).T) < 0.5
            kappa = np.abs(curvature_from_derivatives(tr.spline(u[near], 1),
                                                      tr.spline(u[near], 2)))
            assert kappa.max() > v.limit
        text = v.describe(corridor)
        assert f"{v.s:.1f} m along" in text and "station" in text


def kinked_lane(angle_deg: float, width: float = 3.2) -> tuple[Corridor, Polygon]:
    """One lane of ``width`` [m] whose centre line turns by ``angle_deg`` 60 m in, with
    mitred edges as SUMO draws lane shapes (polylines, not rounded): the corridor between
    its edges around a smoothed centre line, as for a route, and the lane by shapely."""
    from scipy.ndimage import gaussian_filter1d

    a = np.deg2rad(angle_deg)
    centre = LineString([(0.0, 0.0), (60.0, 0.0), (60.0 + 60.0 * np.cos(a), 60.0 * np.sin(a))])
    left = np.asarray(centre.offset_curve(width / 2.0, join_style="mitre").coords)
    right = np.asarray(centre.offset_curve(-width / 2.0, join_style="mitre").coords)
    dense = np.array([centre.interpolate(d).coords[0]
                      for d in np.arange(0.0, centre.length + 0.25, 0.5)])
    smooth = gaussian_filter1d(dense, 4.0, axis=0, mode="nearest")
    smooth[0], smooth[-1] = dense[0], dense[-1]
    lane = centre.buffer(width / 2.0, cap_style="flat", join_style="mitre")
    return Corridor.from_boundaries(left, right, reference=smooth), lane


def lane_clearance(tr: Trajectory, corridor: Corridor, lane: Polygon, rp: RoadmapParams
                   ) -> float:
    """Smallest distance [m] by shapely from the footprint to the lane's edges (negative:
    off the lane), away from the lane's ends."""
    st = corridor.to_sl(tr.xy)[:, 0]
    inner = (st > rp.vehicle_length) & (st < corridor.length - rp.vehicle_length)
    return min(lane.exterior.distance(fp) if lane.contains(fp) else -fp.difference(lane).area
               for fp, ok in zip(footprints(tr, rp), inner, strict=True) if ok)


def test_curve_cutting_a_lane_corner_is_pushed_back_into_the_lane() -> None:
    """A 42 degree corner of one 3.1 m lane, with a road margin of 0.3 m: the first curve
    cuts it to 0.25 m of the edge; the repair moves it sideways until the footprint keeps
    the margin (shapely), and without repair the curve stays infeasible."""
    corridor, lane = kinked_lane(42.0, 3.1)
    rp = RoadmapParams(road_margin=0.3)
    tp = TrajectoryParams(road_margin=0.3)
    rm = plan_roadmap(corridor, Obstacles.empty(), np.array([0.0, 0.0]), rp)
    raw = plan_trajectory(rm, corridor, Obstacles.empty(), replace(tp, repair_rounds=0), 0.0)
    assert not raw.feasible
    assert lane_clearance(raw, corridor, lane, rp) < tp.road_margin - 0.03
    tr = plan_trajectory(rm, corridor, Obstacles.empty(), tp, 0.0)
    assert tr.feasible and tr.iterations.refinements >= 1
    assert lane_clearance(tr, corridor, lane, rp) >= tp.road_margin - 1e-6


def test_road_margin_lets_a_bend_use_the_whole_lane() -> None:
    """A 55 degree corner of one 3.2 m lane: no curve within the turning limit keeps 0.3 m
    from the lane's edges (a 1.8 m car leaves 0.4 m of play in the lane); on the lane itself
    (the default road margin, none) the curve is feasible because it uses that room: its
    footprint comes well inside 0.3 m of an edge (by more than the 0.05 m the corridor's
    rounding of the corner can account for) and stays inside the lane by shapely (to within
    those 0.05 m)."""
    corridor, lane = kinked_lane(55.0, 3.2)
    rp = RoadmapParams()
    rm = plan_roadmap(corridor, Obstacles.empty(), np.array([0.0, 0.0]), rp)
    strict = plan_trajectory(rm, corridor, Obstacles.empty(),
                             TrajectoryParams(road_margin=0.3), 0.0)
    assert not strict.feasible
    tr = plan_trajectory(rm, corridor, Obstacles.empty(), None, 0.0)
    assert tr.road_margin == 0.0 and tr.feasible
    assert tr.clearance_road.min() < 0.3 - 0.05
    assert lane_clearance(tr, corridor, lane, rp) >= -0.05
    assert np.abs(tr.curvature).max() <= TrajectoryParams().kappa_max * (1 + 1e-6)


def test_where_no_curve_is_feasible_the_one_on_the_road_is_kept() -> None:
    """An 80 degree kink of one 3.0 m lane, too sharp for the car: the least-bending
    polygon's curve leaves the lane, other curves stay on it but turn tighter than the
    vehicle can. All are infeasible; the one kept is on the road (footprint before
    curvature)."""
    from splineplan.trajectory import _plan_once

    corridor, _ = kinked_lane(80.0, 3.0)
    rm = plan_roadmap(corridor, Obstacles.empty(), np.array([0.0, 0.0]), RoadmapParams())
    tp = TrajectoryParams()
    smooth = _plan_once(rm, corridor, Obstacles.empty(), tp, 0.0, 0.0, None, True)
    assert float(np.min(smooth.clearance_road)) < -0.03
    tr = plan_trajectory(rm, corridor, Obstacles.empty(), tp, 0.0)
    assert not tr.feasible
    assert float(np.min(tr.clearance_road)) >= tr.road_margin - 1e-6
    assert float(np.max(np.abs(tr.curvature))) > tp.kappa_max


@settings(max_examples=15, deadline=None)
@given(angle=st.floats(5.0, 80.0), left=st.booleans(), width=st.floats(3.0, 3.6),
       start=st.floats(-0.3, 0.3), road_margin=st.sampled_from([0.0, 0.15, 0.3]))
def test_lane_corners_feasible_only_when_clear(angle: float, left: bool, width: float,
                                              start: float, road_margin: float) -> None:
    """Random corners of one lane: a curve reported feasible keeps the road margin from
    the lane's edges by shapely, to within 0.05 m (the corridor holds the edges' offsets
    every 0.5 m of its smoothed reference, which rounds a mitred corner off a little); an
    infeasible one says which limit it breaks, and where, truly."""
    corridor, lane = kinked_lane(angle if left else -angle, width)
    rp = RoadmapParams()
    rm = plan_roadmap(corridor, Obstacles.empty(), np.array([0.0, start]), rp)
    tr = plan_trajectory(rm, corridor, Obstacles.empty(),
                         TrajectoryParams(road_margin=road_margin), 0.0)
    if tr.feasible:
        assert lane_clearance(tr, corridor, lane, rp) >= road_margin - 0.05
    assert_violations_say_why(tr, corridor, Obstacles.empty(), rp)
    assert_wheels_keep_up(tr)


@settings(max_examples=30, deadline=None)
@given(st.lists(st.tuples(st.floats(5.0, 35.0), st.floats(-3.0, 3.0),
                          st.floats(-0.5, 0.5)), min_size=1, max_size=10))
def test_footprint_side_clearances_match_shapely(poses: list[tuple[float, float, float]]
                                                 ) -> None:
    """The footprint's distances to the left and to the right road edge equal shapely's,
    and the nearer of them is the road clearance."""
    from splineplan.footprint import _Checker

    road = straight_road(40.0)
    rp = RoadmapParams()
    xy = np.array([(x, y) for x, y, _ in poses])
    heading = np.array([h for _, _, h in poses])
    checker = _Checker.build(road, Obstacles.empty(), rp, xy, 0.0)
    cl, cr = checker.road(xy, heading, None, sides=True)
    clear, _ = checker.road(xy, heading)
    np.testing.assert_array_equal(np.minimum(cl, cr), clear)
    hl, hw = rp.vehicle_length / 2.0, rp.vehicle_width / 2.0
    left, right = LineString(road.left_xy()), LineString(road.right_xy())
    for j, (x, y, h) in enumerate(poses):
        foot = affinity.translate(affinity.rotate(box(-hl, -hw, hl, hw), h, use_radians=True,
                                                  origin=(0, 0)), x, y)
        inside = Polygon(road.polygon()).contains(foot)
        if inside:
            assert cl[j] == pytest.approx(foot.distance(left), abs=1e-9)
            assert cr[j] == pytest.approx(foot.distance(right), abs=1e-9)
        else:
            assert min(cl[j], cr[j]) <= 1e-9


@settings(max_examples=12, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(1, 8))
def test_random_fields_footprint_never_touches_grown_obstacles(seed: int, n: int) -> None:
    rng = np.random.default_rng(seed)
    road = straight_road()
    rp = RoadmapParams()
    path = sine_path(amp=rng.uniform(0.5, 2.5), wave=rng.uniform(30.0, 60.0))
    # obstacles anywhere on the road that the initial curve's footprint clears
    xs = rng.uniform(15.0, 110.0, 40)
    ls = rng.uniform(-4.0, 4.0, 40)
    tr0 = plan_trajectory(make_roadmap(path, road, rp), road, Obstacles.empty(),
                          TrajectoryParams(max_iterations=0), 0.0)
    dist = np.hypot(xs[:, None] - tr0.x[None], ls[:, None] - tr0.y[None]).min(axis=1)
    keep = dist > 4.2
    if not keep.any():
        return
    pos = np.column_stack((xs, ls))[keep][:n]
    obstacles = Obstacles.from_boxes(pos, rng.uniform(-0.5, 0.5, len(pos)), 3.0, 1.5)
    tr = plan_trajectory(make_roadmap(path, road, rp), road, obstacles, None, 0.0)
    assert tr.min_speed_after >= tr.min_speed_before - 1e-9
    if tr.feasible:
        assert shapely_violations(tr, road, obstacles, rp) == (0, 0)
    else:  # only a start that was infeasible may end infeasible
        tr_start = plan_trajectory(make_roadmap(path, road, rp), road, obstacles,
                                   TrajectoryParams(max_iterations=0), 0.0)
        assert not tr_start.feasible


# ---- speed profile on the trajectory ---------------------------------------------------
@pytest.mark.parametrize("end_speed", [None, 0.0, 5.0])
def test_speed_profile_within_limits(end_speed: float | None) -> None:
    road = straight_road()
    tr = plan_trajectory(make_roadmap(sine_path(), road), road, Obstacles.empty(), None, 0.0,
                         start_speed=3.0, end_speed=end_speed)
    limit = allowed_speed(tr.curvature, mu=TP.mu, g=TP.g, s_max=TP.s_max)
    assert np.all(tr.speed <= limit + 1e-9)
    assert np.all(tr.speed <= TP.s_max + 1e-9)
    assert tr.speed[0] == pytest.approx(3.0)
    if end_speed is not None:
        assert tr.speed[-1] == pytest.approx(end_speed)
    # accelerations from the time-parametrised result, by finite differences
    acc = np.diff(tr.speed) / np.diff(tr.t)
    assert acc.max() <= TP.a_max + 1e-6
    assert acc.min() >= -TP.b_max - 1e-6
    assert np.all(np.diff(tr.t) > 0)


def test_resample_and_at_time() -> None:
    road = straight_road()
    tr = plan_trajectory(make_roadmap(sine_path(), road), road, Obstacles.empty(), None, 0.0,
                         end_speed=0.0)
    sim = tr.resample(0.1)
    assert sim.t[0] == 0.0 and sim.t[-1] == pytest.approx(tr.duration)
    np.testing.assert_allclose(np.diff(sim.t)[:-1], 0.1)
    x, _y, h, v = tr.at_time(tr.duration / 2)
    k = int(np.searchsorted(tr.t, tr.duration / 2))
    assert abs(float(x) - tr.x[k]) < 1.0 and abs(float(v) - tr.speed[k]) < 0.5
    assert abs(float(h) - tr.heading[k]) < 0.1
    # driving the resampled poses covers the curve: step lengths match speed * dt
    steps = np.hypot(np.diff(sim.x), np.diff(sim.y))
    mean_v = (sim.speed[:-1] + sim.speed[1:]) / 2
    later = (sim.t[:-2] > 2.0) & (sim.t[:-2] < tr.duration - 2.0)  # coarse at low speed
    np.testing.assert_allclose(steps[:-1][later], mean_v[:-1][later] * 0.1, atol=0.02)


# ---- errors ----------------------------------------------------------------------------
def test_too_few_points() -> None:
    road = straight_road()
    rm = make_roadmap(np.array([[1.0, 0.0], [2.0, 0.0]]), road)
    object.__setattr__(rm, "xy", np.array([[1.0, 0.0]]))
    with pytest.raises(TrajectoryError, match="at least 2"):
        plan_trajectory(rm, road, Obstacles.empty())


def test_off_road_start() -> None:
    road = straight_road()
    rm = make_roadmap(sine_path(), road, start_xy=np.array([5.0, 7.0]))
    with pytest.raises(TrajectoryError, match="off the road"):
        plan_trajectory(rm, road, Obstacles.empty())


@pytest.mark.parametrize("kwargs", [
    {"mu": 0.0}, {"mu": -1.0}, {"s_max": float("nan")}, {"a_max": 0.0}, {"b_max": -4.0},
    {"sample_spacing": 0.0}, {"min_turn_radius": float("inf")}, {"degree": 1},
    {"degree": 2.5}, {"max_iterations": -1}, {"g": 0.0}, {"patience": -1}, {"patience": 1.5},
    {"mu": True}, {"s_max": "13"}, {"lead_in_time": -0.1}, {"detour_rate": float("nan")},
    {"wheelbase": 0.0}, {"wheelbase": 9.0}, {"max_steering_rate": 0.0},
    {"max_steering_rate": float("inf")},
])
def test_bad_params(kwargs: dict[str, float]) -> None:
    """Each bad value is refused on creation (a wheelbase of twice the turning radius or
    more cannot turn the car's centre that tightly)."""
    with pytest.raises(ParameterError):
        TrajectoryParams(**kwargs)  # type: ignore[arg-type]


@pytest.mark.parametrize("degree", [2, 3, 4, 5])
def test_degrees(degree: int) -> None:
    road = straight_road()
    tr = plan_trajectory(make_roadmap(sine_path(), road), road, Obstacles.empty(),
                         TrajectoryParams(degree=degree), 0.0)
    assert tr.spline is not None and tr.spline.k == degree
    assert tr.min_speed_after >= tr.min_speed_before
    assert np.hypot(tr.x[0] - 0.0, tr.y[0] + 2.4) < 1e-9


def test_start_heading_is_followed() -> None:
    road = straight_road()
    for h in (-0.3, 0.0, 0.4):
        tr = plan_trajectory(make_roadmap(sine_path(), road), road, Obstacles.empty(),
                             TrajectoryParams(max_iterations=0), h)
        assert tr.heading[0] == pytest.approx(h, abs=1e-9)


@pytest.mark.parametrize(("ahead", "speed"), [(20.0, 13.0), (25.0, 20.0)])
def test_a_car_parked_just_ahead_is_passed_without_crawling(ahead: float, speed: float
                                                            ) -> None:
    """A car parked in the vehicle's lane of a two-lane road 20-25 m ahead, the vehicle at
    13-20 m/s: leaving the lane takes a lateral offset of about 2 m over 20 m, a curvature
    of about 0.02 1/m, which allows some 18 m/s. The curve must not hold the start's
    heading so long that its bend past the car is sharp (it crawled past at about 1 m/s):
    it starts at the vehicle's speed and passes at at least half of it, clear by shapely."""
    road = straight_road(200.0, 7.0)
    obstacles = Obstacles.from_boxes(np.array([[ahead, -1.75]]), 0.0, 4.5, 1.8)
    tp = TrajectoryParams(s_max=20.0)
    plan = plan_corridor(road, obstacles, (0.0, -1.75), 0.0, params=tp, start_speed=speed,
                         end_speed=None)
    tr = plan.trajectory
    assert tr.feasible
    assert shapely_violations(tr, road, obstacles, plan.roadmaps[0].params) == (0, 0)
    assert tr.speed[0] >= speed - SLOW_START
    passing = tr.s <= ahead + 10.0
    assert float(np.min(tr.speed[passing])) >= 0.5 * speed


@settings(max_examples=40, deadline=None)
@given(st.lists(st.tuples(st.floats(-7.0, 7.0), st.floats(-7.0, 7.0),
                          st.floats(-np.pi, np.pi)), min_size=1, max_size=12))
def test_footprint_obstacle_distance_matches_shapely(poses: list[tuple[float, float, float]]
                                                     ) -> None:
    """The footprint-to-obstacle distance equals shapely's (0 on overlap) for a box, a
    non-convex polygon and a polygon large enough to hold the footprint, at poses apart
    from, touching, crossing and inside them."""
    from splineplan.footprint import _Checker

    polys = [np.array([[1.0, 1.0], [3.0, 1.5], [2.5, 3.0], [0.5, 2.5]]),
             np.array([[-4, -4], [0, -4], [0, -3], [-3, -3], [-3, 0], [-4, 0]], float),
             np.array([[4.0, -6.0], [9.0, -6.0], [9.0, 0.0], [4.0, 0.0]])]
    obstacles = Obstacles.from_polygons(polys)
    rp = RoadmapParams()
    xy = np.array([(x, y) for x, y, _ in poses])
    heading = np.array([h for _, _, h in poses])
    checker = _Checker.build(straight_road(40.0), obstacles, rp, xy, 0.0)
    got = checker.obstacles(xy, heading, horizon=50.0)
    hl, hw = rp.vehicle_length / 2.0, rp.vehicle_width / 2.0
    shapes = [Polygon(p) for p in polys]
    for j, (x, y, h) in enumerate(poses):
        foot = affinity.translate(affinity.rotate(box(-hl, -hw, hl, hw), h, use_radians=True,
                                                  origin=(0, 0)), x, y)
        assert got[j] == pytest.approx(min(foot.distance(s) for s in shapes), abs=1e-9)


# ---- band simplification and obstacle fields (real level 2) -------------------------------
def shapely_check_corridor(tr: Trajectory, corridor: Corridor, obstacles: Obstacles,
                           rp: RoadmapParams, tol: float = 1e-6) -> tuple[int, int]:
    """Footprints touching obstacles grown by the margin, and off the road shrunk by it
    (away from the road's ends, where the footprint overhangs)."""
    grown = [Polygon(p).buffer(rp.safety_margin - tol) for p in obstacles.polygons()]
    road = Polygon(corridor.polygon()).buffer(-(tr.road_margin - tol), join_style=2)
    st = corridor.to_sl(tr.xy)[:, 0]
    inner = (st > rp.vehicle_length) & (st < corridor.length - rp.vehicle_length)
    hits = off = 0
    for fp, ok in zip(footprints(tr, rp), inner, strict=True):
        hits += any(fp.intersects(g) for g in grown)
        off += bool(ok) and not road.contains(fp)
    return hits, off


def real_plan(corridor: Corridor, obstacles: Obstacles, start: np.ndarray,
              heading: float | None = 0.0) -> tuple[Roadmap, Trajectory]:
    rp = RoadmapParams()
    rm = plan_roadmap(corridor, elongate_for_roadmap(corridor, obstacles, rp), start, rp)
    return rm, plan_trajectory(rm, corridor, obstacles, None, heading)


@pytest.mark.parametrize("rho", [0.0, 0.5, 0.8, 1.0])
def test_band_simplification_keeps_every_segment_in_the_bands(rho: float) -> None:
    """Independent check with shapely: each kept segment meets every skipped sweep line's
    band (a LineString across the road), and the kept vertices are far fewer than all."""
    from benchmarks.fields import obstacle_field
    from splineplan.control_polygon import band_simplify

    corridor, obstacles, start = obstacle_field(300, 20, 9.6, 1)
    rp = RoadmapParams()
    rm = plan_roadmap(corridor, elongate_for_roadmap(corridor, obstacles, rp), start, rp)
    lo, hi = rm.graph_lo[rm.path], rm.graph_hi[rm.path]
    half = rho * (hi - lo) / 2
    h = corridor.heading_at(rm.s)
    tangent = np.column_stack((np.cos(h), np.sin(h)))
    normal = np.column_stack((-tangent[:, 1], tangent[:, 0]))
    origin = corridor.to_xy(rm.s, np.zeros_like(rm.s))
    kept = band_simplify(rm.xy, origin, tangent, normal, rm.l, half)
    assert kept[0] == 0 and kept[-1] == len(rm.xy) - 1 and np.all(np.diff(kept) > 0)
    if rho >= 0.5:
        assert len(kept) < len(rm.xy) / 3
    for a, b in itertools.pairwise(kept):
        seg = LineString([rm.xy[a], rm.xy[b]])
        for k in range(a + 1, b):
            band = LineString(corridor.to_xy(np.full(2, rm.s[k]),
                                             rm.l[k] + np.array([-1, 1]) * (half[k] + 1e-6)))
            assert seg.intersects(band), (a, b, k)


@pytest.mark.parametrize(("n_obs", "seed"), [(20, s) for s in range(5)]
                         + [(40, s) for s in range(8)])
def test_benchmark_fields_are_feasible(n_obs: int, seed: int) -> None:
    """The benchmark's fields (each keeps a drivable passage for the car) end feasible."""
    from benchmarks.fields import obstacle_field

    corridor, obstacles, start = obstacle_field(300, n_obs, 9.6, seed)
    rm, tr = real_plan(corridor, obstacles, start)
    assert tr.feasible
    # far fewer than one per sweep line (300); level 2's bands keep 90 % of each vertex's
    # separation, so more are kept than the 80 % bands around the midpoints kept (< 60)
    assert tr.iterations.control_points < 120
    assert shapely_check_corridor(tr, corridor, obstacles, rm.params) == (0, 0)


def test_detour_where_level_2_zigzags_across_lanes() -> None:
    """Seed 6: level 2's widest path crosses two lanes within a 6 m gap between rows, which
    no curve within the turning limit follows; the detour through the same graph does."""
    from benchmarks.fields import obstacle_field
    from splineplan.control_polygon import detour_roadmap

    corridor, obstacles, start = obstacle_field(300, 40, 9.6, 6)
    rm, tr = real_plan(corridor, obstacles, start)
    assert tr.feasible
    direct = plan_trajectory(rm, corridor, obstacles,
                             TrajectoryParams(detour_rate=0.0, bend_rounds=0), 0.0)
    assert not direct.feasible
    jumps = np.abs(np.diff(rm.l)) / np.diff(rm.s)
    assert jumps.max() > 2.0
    detour = detour_roadmap(rm, corridor, 0.4)
    assert detour is not None
    assert np.abs(np.diff(detour.l)).max() <= 0.4 * rm.params.d + 1e-9
    # the detour runs through the graph: its vertices, their intervals, and its arcs
    assert np.all(detour.l >= rm.graph_lo[detour.path] - 1e-9)
    assert np.all(detour.l <= rm.graph_hi[detour.path] + 1e-9)
    arcs = {tuple(a) for a in rm.arcs.tolist()}
    assert all((int(a), int(b)) in arcs for a, b in zip(detour.path[:-1], detour.path[1:],
                                                         strict=True))
    assert shapely_check_corridor(tr, corridor, obstacles, rm.params) == (0, 0)


def random_field(rng: np.random.Generator, curved: bool, n: int, gap: float
                 ) -> tuple[Corridor, Obstacles, np.ndarray]:
    """Cars on a 9.6 m road (straight or an arc of radius 150 m), each leaving at least
    ``gap`` [m] free beside it on one side."""
    length = 150.0
    if curved:
        th = np.linspace(0.0, length / 150.0, 200)
        ref = np.column_stack((150.0 * np.sin(th), 150.0 * (1.0 - np.cos(th))))
        cor = Corridor.from_reference(ref, np.full(200, 4.8), np.full(200, -4.8))
    else:
        cor = straight_road(length, 9.6)
    st = np.sort(rng.uniform(25.0, length - 15.0, n))
    st = st[np.concatenate(([True], np.diff(st) > 12.0))]  # rows apart: a passage exists
    side = rng.choice([-1.0, 1.0], len(st))
    lat = side * (4.8 - 0.9 - rng.uniform(0.0, 9.6 - 1.8 - gap, len(st)))
    obs = Obstacles.from_boxes(cor.to_xy(st, lat), cor.heading_at(st)
                               + rng.uniform(-0.1, 0.1, len(st)), 4.5, 1.8)
    return cor, obs, cor.to_xy(np.array([1.0]), np.array([rng.uniform(-3.0, 3.0)]))[0]


def _random_fields(seed: int, n: int, curved: bool) -> bool | None:
    rng = np.random.default_rng(seed)
    cor, obs, start = random_field(rng, curved, n, gap=3.5)
    try:
        rm, tr = real_plan(cor, obs, start, float(cor.heading_at(1.0)))
    except RoadBlockedError:
        return None
    if tr.feasible:
        assert shapely_check_corridor(tr, cor, obs, rm.params) == (0, 0)
    assert_violations_say_why(tr, cor, obs, rm.params)
    assert_wheels_keep_up(tr)
    assert tr.min_speed_after >= tr.min_speed_before - 1e-9
    return tr.feasible


def _eased_and_stiff(seed: int) -> tuple[Trajectory, Trajectory, Corridor, Obstacles,
                                          RoadmapParams]:
    """The benchmark's field ``seed`` (300 m, 40 cars, 9.6 m) planned without the detour,
    with the bends that equation (3) leaves too sharp eased and without (``bend_rounds=0``).
    """
    from benchmarks.fields import obstacle_field

    cor, obs, start = obstacle_field(300, 40, 9.6, seed)
    rp = RoadmapParams()
    rm = plan_roadmap(cor, elongate_for_roadmap(cor, obs, rp), start, rp)
    eased = plan_trajectory(rm, cor, obs, TrajectoryParams(detour_rate=0.0), 0.0)
    stiff = plan_trajectory(rm, cor, obs, TrajectoryParams(detour_rate=0.0, bend_rounds=0),
                            0.0)
    return eased, stiff, cor, obs, rp


def _inside(tr: Trajectory) -> float:
    """How far [m] the footprint comes inside its margins (0: clear)."""
    return max(tr.safety_margin - float(np.min(tr.clearance_obstacles)),
               tr.road_margin - float(np.min(tr.clearance_road)), 0.0)


@pytest.mark.parametrize("seed", [6, 13, 17, 37, 57])
def test_easing_the_bends_mends_a_zigzag_without_the_detour(seed: int) -> None:
    """Fields whose level-2 path crosses lanes between rows of cars faster than the car
    turns: without the detour, equation (3) leaves the curve too sharp, and moving the
    control points round those bends together mends it. Feasible, and truly: shapely
    finds the footprint clear of the grown obstacles and on the road, and the curve within
    the turning limit."""
    eased, stiff, cor, obs, rp = _eased_and_stiff(seed)
    assert not stiff.feasible
    assert any(v.kind == "curvature" for v in stiff.violations)
    assert eased.feasible, eased.violations
    assert shapely_check_corridor(eased, cor, obs, rp) == (0, 0)
    assert np.abs(eased.curvature).max() <= TrajectoryParams().kappa_max + 1e-9
    assert_wheels_keep_up(eased)


@settings(max_examples=10, deadline=None)
@given(seed=st.integers(0, 2**32 - 1))
def test_easing_bends_keeps_feasible_curves_and_gives_away_no_room(seed: int) -> None:
    """A curve feasible without the easing is the same curve with it; otherwise the eased
    one's footprint comes no further inside its margins, and where it is feasible, shapely
    finds it clear."""
    eased, stiff, cor, obs, rp = _eased_and_stiff(seed)
    if stiff.feasible:
        assert np.array_equal(eased.x, stiff.x) and np.array_equal(eased.y, stiff.y)
        return
    assert _inside(eased) <= _inside(stiff) + 1e-9
    if eased.feasible:
        assert shapely_check_corridor(eased, cor, obs, rp) == (0, 0)


@settings(max_examples=15, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(1, 8), curved=st.booleans())
def test_random_obstacle_fields_real_roadmap(seed: int, n: int, curved: bool) -> None:
    _random_fields(seed, n, curved)


def test_random_obstacle_fields_mostly_feasible() -> None:
    """Fields with a passage 3.5 m wide (1.7 m wider than the car): at least 90 % feasible."""
    outcomes = [_random_fields(seed, 1 + seed % 8, bool(seed % 2)) for seed in range(30)]
    done = [o for o in outcomes if o is not None]
    assert len(done) >= 20
    assert np.mean(done) >= 0.9, f"{np.mean(done):.2f} of {len(done)} feasible"


@pytest.mark.slow
@settings(max_examples=200, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(1, 12), curved=st.booleans())
def test_random_obstacle_fields_real_roadmap_slow(seed: int, n: int, curved: bool) -> None:
    _random_fields(seed, n, curved)


@settings(max_examples=25, deadline=None)
@given(st.integers(0, 2**32 - 1), st.integers(3, 60), st.sampled_from([0.0, 1e-4, 0.1]))
def test_min_bending_offsets_solves_its_least_squares_problem(seed: int, m: int,
                                                               weight: float) -> None:
    """The banded active-set solver reaches the optimum of the bounded least-squares
    problem it states, as scipy's general solver finds it (random lines, bands, fixed
    points)."""
    import scipy.sparse as sp
    from scipy.optimize import lsq_linear

    from splineplan.control_polygon import min_bending_offsets

    rng = np.random.default_rng(seed)
    origin, normal, centre = winding_line(rng, m)
    lo, hi = centre - rng.uniform(0.0, 2.0, m), centre + rng.uniform(0.0, 2.0, m)
    fixed = rng.random(m) < 0.1
    lo[fixed] = hi[fixed] = centre[fixed]
    got = min_bending_offsets(origin, normal, lo, hi, centre, weight)
    assert np.all(got >= lo - 1e-9) and np.all(got <= hi + 1e-9)
    # the same objective, written out: second differences for uneven spacing
    h = np.hypot(*np.diff(origin, axis=0).T)
    rows = []
    for r in range(m - 2):
        w = np.sqrt(2.0 / (h[r] + h[r + 1]))
        row = np.zeros(m)
        row[r:r + 3] = w * np.array([1 / h[r], -(1 / h[r] + 1 / h[r + 1]), 1 / h[r + 1]])
        rows.append(row)
    d = np.array(rows)
    a = np.vstack((d * normal[:, 0], d * normal[:, 1], np.sqrt(weight) * np.eye(m)))
    b = np.concatenate((-(d @ origin[:, 0]), -(d @ origin[:, 1]), np.sqrt(weight) * centre))
    ref = lsq_linear(sp.csr_matrix(a), b, bounds=(lo, np.where(fixed, hi + 1e-12, hi)),
                     tol=1e-12).x

    def cost(x: np.ndarray) -> float:
        return float(np.sum((a @ x - b) ** 2))

    assert cost(got) <= cost(ref) + 1e-6 * (1.0 + cost(ref))
