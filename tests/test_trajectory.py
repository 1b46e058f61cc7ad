"""Level 3: spline, curvature, optimisation, feasibility (checked with shapely), errors."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from shapely import affinity
from shapely.geometry import Polygon, box

from splineplan.corridor import Corridor
from splineplan.errors import ParameterError, TrajectoryError
from splineplan.obstacles import Obstacles
from splineplan.roadmap import Roadmap, RoadmapParams, plan_roadmap
from splineplan.speed import allowed_speed
from splineplan.trajectory import (
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
    return road, obstacles, plan_roadmap(road, obstacles, np.array([1.0, -1.75]))


def footprints(tr: Trajectory, rp: RoadmapParams) -> list[Polygon]:
    """The vehicle rectangle at each sample, built by shapely."""
    base = box(-rp.vehicle_length / 2, -rp.vehicle_width / 2,
               rp.vehicle_length / 2, rp.vehicle_width / 2)
    return [affinity.translate(affinity.rotate(base, h, origin=(0, 0), use_radians=True), x, y)
            for x, y, h in zip(tr.x, tr.y, tr.heading, strict=True)]


def shapely_violations(tr: Trajectory, corridor: Corridor, obstacles: Obstacles,
                       rp: RoadmapParams, tol: float = 1e-6) -> tuple[int, int]:
    """Samples whose footprint touches a grown obstacle, and samples off the shrunk road."""
    grown = [Polygon(p).buffer(rp.safety_margin - tol) for p in obstacles.polygons()]
    # straight roads along +x only; the planner extends the road past its ends
    ref = corridor.reference
    road = box(ref[0, 0] - 10.0, float(corridor.right.max()), ref[-1, 0] + 10.0,
               float(corridor.left.min())).buffer(-(rp.safety_margin - tol), join_style=2)
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
    road = straight_road()
    tr = plan_trajectory(make_roadmap(sine_path(), road), road, Obstacles.empty(),
                         TrajectoryParams(max_iterations=0, sample_spacing=0.1), 0.0)
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
    """The first curve is too sharp (curvature above the turning limit) but clear of the
    obstacles; every round keeps the footprint clear and never sharpens the worst bend."""
    road, obstacles, rm = slalom()
    worst = np.inf
    for cap in (0, 1, 3, 10, 30, 100, 1000):
        tr = plan_trajectory(rm, road, obstacles, TrajectoryParams(max_iterations=cap), 0.0)
        assert tr.iterations.tried <= cap
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


def test_one_obstacle_real_roadmap() -> None:
    road = straight_road(150.0, 9.6)
    obstacles = Obstacles.from_boxes(np.array([[60.0, -3.0]]), 0.0, 4.5, 1.8)
    rm = plan_roadmap(road, obstacles, np.array([1.0, -3.2]))
    tr = plan_trajectory(rm, road, obstacles, None, 0.0)
    assert tr.feasible
    assert tr.min_speed_after > tr.min_speed_before + 5.0
    assert shapely_violations(tr, road, obstacles, rm.params) == (0, 0)


def test_every_accepted_move_keeps_the_curve_feasible() -> None:
    """Step the cap: each intermediate curve (after any number of moves) is feasible."""
    road = straight_road()
    obstacles = Obstacles.from_boxes(LOBE_OBSTACLES[:3], 0.0, 4.5, 1.8)
    rp = RoadmapParams()
    rm = make_roadmap(sine_path(), road, rp)
    for cap in (0, 1, 3, 10, 30, 100, 300):
        tr = plan_trajectory(rm, road, obstacles, TrajectoryParams(max_iterations=cap), 0.0)
        assert tr.iterations.tried <= cap
        assert tr.feasible
        assert shapely_violations(tr, road, obstacles, rp) == (0, 0)
        assert tr.min_speed_after >= tr.min_speed_before - 1e-9


def test_infeasible_start_is_reported_not_hidden() -> None:
    """Walls force a 6 m lateral jump within 2 m: no curve of radius >= 5 m does it."""
    road = straight_road()
    xs = np.arange(0.0, 60.5, 1.0)
    lat = np.where(xs < 30, -3.0, 3.0)
    obstacles = Obstacles.from_boxes(np.array([[26.5, 2.0], [33.5, -2.0]]), 0.0, 5.0, 4.0)
    tr = plan_trajectory(make_roadmap(np.column_stack((xs, lat)), road), road, obstacles,
                         TrajectoryParams(max_iterations=0), 0.0)
    assert not tr.feasible
    assert (np.abs(tr.curvature).max() > TP.kappa_max
            or tr.min_clearance < RoadmapParams().safety_margin)


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
    {"degree": 2.5}, {"max_iterations": -1}, {"g": 0.0},
])
def test_bad_params(kwargs: dict[str, float]) -> None:
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
