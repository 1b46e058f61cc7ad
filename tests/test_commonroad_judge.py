"""CommonRoad's drivability checker as an independent judge of level 3's trajectories.

``trajectory_feasibility`` with the kinematic single-track model of the BMW 320i (CommonRoad's
vehicle type 2, steering rate at most 0.4 rad/s) reconstructs, between every two states
0.1 s apart, an input (steering rate, acceleration) within the car's limits that reaches
the next state. The planner's centre (half the wheelbase ahead of the rear axle, on the
path's tangent turned by the slip angle) is converted to CommonRoad's state by
:func:`splineplan.commonroad.ks_states`: the rear axle plus ``b`` along the body, the
body's heading, the rear axle's speed and the wheel angle.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from test_trajectory import kinked_lane, random_field, real_plan

from splineplan.obstacles import Obstacles
from splineplan.roadmap import RoadmapParams, plan_roadmap
from splineplan.trajectory import Trajectory, TrajectoryParams, plan_trajectory

feasibility = pytest.importorskip("commonroad_dc.feasibility.feasibility_checker",
                                  reason="commonroad-drivability-checker is a test extra")
DT = 0.1
#: How far [rad] the reached wheel angle may be off the next state's (the reconstruction
#: differentiates the body's heading).
STEERING_TOLERANCE = 0.01


def commonroad_states(tr: Trajectory, params: TrajectoryParams) -> list:
    """The trajectory every :data:`DT` seconds as CommonRoad's KS states of the BMW 320i
    (:func:`splineplan.commonroad.ks_states`) with the planner's wheelbase."""
    from dataclasses import replace

    from splineplan.commonroad import ks_states, vehicle

    return ks_states(tr, replace(vehicle(2), wheelbase=params.wheelbase), DT)


def judge(tr: Trajectory, params: TrajectoryParams | None = None) -> bool:
    from commonroad.scenario.trajectory import Trajectory as CRTrajectory
    from commonroad_dc.feasibility.vehicle_dynamics import VehicleDynamics, VehicleType

    params = params or TrajectoryParams()
    states = commonroad_states(tr, params)
    ok, _ = feasibility.trajectory_feasibility(
        CRTrajectory(0, states), VehicleDynamics.KS(VehicleType.BMW_320i), DT,
        objective=_reach_steering, criteria=_with_steering)
    return bool(ok)


def _reach_steering(u: np.ndarray, x0: np.ndarray, x1: np.ndarray, dt: float,
                    vehicle_dynamics: object, ftol: float, e: np.ndarray) -> float:
    """CommonRoad's objective (position, speed and orientation) with the wheel angle's
    miss added: the input sought reaches the next state's wheel angle too."""
    cost = feasibility.position_orientation_objective(u, x0, x1, dt, vehicle_dynamics,
                                                      ftol, e)
    sim = vehicle_dynamics.forward_simulation(x0, u, dt, throw=False)  # type: ignore[attr-defined]
    return float(cost if sim is None else math.hypot(cost, x1[2] - sim[2]))


def _with_steering(x: np.ndarray, x_sim: np.ndarray, vehicle_dynamics: object,
                   e: np.ndarray, d: int) -> bool:
    """CommonRoad's criteria (position and orientation reached), and the wheel angle too:
    its own compare only the pose, so that each step could start from any wheel angle and
    the steering rate would go unchecked."""
    return bool(feasibility.position_orientation_feasibility_criteria(
        x, x_sim, vehicle_dynamics, e, d) and abs(x[2] - x_sim[2]) < STEERING_TOLERANCE)



@pytest.mark.parametrize("angle", [45.0, 60.0, -60.0])
def test_lane_corners_are_drivable_by_commonroads_car(angle: float) -> None:
    """A bend of one 3.5 m lane, planned with the defaults (the BMW's steering rate)."""
    corridor, _ = kinked_lane(angle, 3.5)
    rm = plan_roadmap(corridor, Obstacles.empty(), np.array([0.0, 0.0]), RoadmapParams())
    tr = plan_trajectory(rm, corridor, Obstacles.empty(), None, 0.0, start_speed=8.0)
    assert tr.feasible
    assert judge(tr)


@pytest.mark.parametrize("seed", [1, 4])
def test_obstacle_fields_are_drivable_by_commonroads_car(seed: int) -> None:
    rng = np.random.default_rng(seed)
    cor, obs, start = random_field(rng, bool(seed % 2), 5, gap=3.0)
    _, tr = real_plan(cor, obs, start, float(cor.heading_at(1.0)))
    assert tr.feasible
    assert judge(tr)


def test_the_judge_refuses_what_the_steering_rate_forbids() -> None:
    """A 60 degree bend of the lane planned for a car that could turn its wheels at once:
    its speed through the bend's ends is higher, and CommonRoad's car cannot follow (the
    judge sees the steering rate; planned with the BMW's rate, the same bend passes
    above). The 45 degree bend no longer tells: its curve's towed wheels turn slowly
    enough at the speed that the cornering allows."""
    corridor, _ = kinked_lane(60.0, 3.5)
    rm = plan_roadmap(corridor, Obstacles.empty(), np.array([0.0, 0.0]), RoadmapParams())
    instant = TrajectoryParams(max_steering_rate=100.0)
    tr = plan_trajectory(rm, corridor, Obstacles.empty(), instant, 0.0, start_speed=8.0)
    assert tr.feasible
    assert not judge(tr)
