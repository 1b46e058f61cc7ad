"""Speed profile: forward/backward passes and times."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from splineplan.errors import ParameterError
from splineplan.speed import (
    allowed_speed,
    meeting_distances,
    meeting_profile,
    nearby_curvature,
    speed_profile,
    steering_speed_limit,
    times_from_profile,
    towed_steering,
)


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(1, 300), reach=st.floats(0.0, 12.0))
def test_the_sharpest_curvature_nearby_is_found(seed: int, n: int, reach: float) -> None:
    """:func:`nearby_curvature` gives, at each station, the largest ``|kappa|`` of the
    stations within ``reach`` of it (both ends included), as a plain scan finds it."""
    rng = np.random.default_rng(seed)
    s = np.cumsum(rng.uniform(0.05, 1.0, n))
    kappa = rng.normal(0.0, 0.1, n)
    want = [np.abs(kappa[(s >= x - reach) & (s <= x + reach)]).max() for x in s]
    np.testing.assert_array_equal(nearby_curvature(s, kappa, reach), want)


def test_allowed_speed_equation_1() -> None:
    v = allowed_speed([0.0, 0.1, -0.1, 1.0], mu=0.7, g=9.81, s_max=13.89)
    np.testing.assert_allclose(v, [13.89, np.sqrt(68.67), np.sqrt(68.67), np.sqrt(6.867)])
    # a denormal curvature (a straight curve's rounding) overflows mu g / kappa: s_max, no
    # warning (hypothesis found a curve with kappa = -1.3e-308)
    v = allowed_speed([-1.27512029e-308, 5e-324], mu=0.7, g=9.81, s_max=13.89)
    np.testing.assert_array_equal(v, [13.89, 13.89])


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), v0=st.floats(0.0, 10.0),
       end=st.one_of(st.none(), st.floats(0.0, 8.0)))
def test_profile_respects_every_limit(seed: int, v0: float, end: float | None) -> None:
    rng = np.random.default_rng(seed)
    s = np.concatenate(([0.0], np.cumsum(rng.uniform(0.1, 1.0, 200))))
    limit = rng.uniform(2.0, 14.0, len(s))
    v = speed_profile(s, limit, a_max=2.0, b_max=4.0, start_speed=v0, end_speed=end)
    assert np.all(v <= limit + 1e-9)
    dv2 = np.diff(v**2) / (2 * np.diff(s))
    assert dv2.max() <= 2.0 + 1e-9 and dv2.min() >= -4.0 - 1e-9
    assert v[0] <= v0 + 1e-12
    if end is not None:
        assert v[-1] <= end + 1e-12
    t = times_from_profile(s, v) if np.all(v[:-1] + v[1:] > 0) else None
    if t is not None:
        acc = np.diff(v) / np.diff(t)
        assert acc.max() <= 2.0 + 1e-6 and acc.min() >= -4.0 - 1e-6


def test_constant_acceleration_times_are_exact() -> None:
    s = np.linspace(0.0, 50.0, 101)
    v = np.sqrt(2 * 2.0 * s)
    t = times_from_profile(s, v)
    np.testing.assert_allclose(t, v / 2.0, atol=1e-12)


def test_stop_and_errors() -> None:
    s = np.linspace(0.0, 100.0, 201)
    v = speed_profile(s, np.full(201, 10.0), a_max=2.0, b_max=4.0, end_speed=0.0)
    assert v[-1] == 0.0 and v.max() == pytest.approx(10.0)
    with pytest.raises(ParameterError):
        speed_profile(s, np.ones(3), a_max=2.0, b_max=4.0)
    with pytest.raises(ParameterError):
        speed_profile(s, np.ones(201), a_max=0.0, b_max=4.0)
    with pytest.raises(ParameterError):
        times_from_profile([0.0, 1.0], [0.0, 0.0])


def wheel_angle(kappa: np.ndarray, wheelbase: float) -> np.ndarray:
    """The front-wheel angle of a kinematic single-track car whose centre, half the
    wheelbase ahead of the rear axle, runs on curvature ``kappa``, written here from the
    geometry: the rear axle turns about the same centre on radius sqrt(R^2 - (L/2)^2)."""
    radius = 1.0 / np.maximum(np.abs(kappa), 1e-12)
    rear = np.sqrt(np.maximum(radius**2 - (wheelbase / 2) ** 2, 1e-12))
    return np.sign(kappa) * np.arctan(wheelbase / rear)


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), rate=st.floats(0.1, 1.0), v0=st.floats(0.0, 10.0))
def test_the_wheels_keep_up_with_the_curvature(seed: int, rate: float, v0: float) -> None:
    """Random curvature profiles within the turning limit: driven at the profile's speeds,
    the front wheels turn no faster than the steering rate, and where the curvature does
    not change the speed is the cornering one."""
    from splineplan.speed import steering_speed_limit

    rng = np.random.default_rng(seed)
    s = np.concatenate(([0.0], np.cumsum(rng.uniform(0.2, 1.0, 300))))
    kappa = np.clip(np.cumsum(rng.normal(0.0, 0.02, len(s))), -0.238, 0.238)
    kappa[100:140] = kappa[100]  # a stretch of constant curvature
    limit = np.minimum(allowed_speed(kappa, mu=0.7, g=9.81, s_max=13.89),
                       steering_speed_limit(s, kappa, wheelbase=2.578,
                                            max_steering_rate=rate))
    v = speed_profile(s, limit, a_max=2.0, b_max=4.0, start_speed=v0)
    moving = v[:-1] + v[1:] > 0
    dt = 2 * np.diff(s)[moving] / (v[:-1] + v[1:])[moving]
    turn = np.abs(np.diff(wheel_angle(kappa, 2.578)))[moving]
    assert np.all(turn / dt <= rate * (1 + 1e-9))
    inner = slice(102, 138)
    corner = allowed_speed(kappa[inner], mu=0.7, g=9.81, s_max=13.89)
    assert np.all(limit[inner] == corner)


def towed_by_ode(s: np.ndarray, kappa_of: object, wheelbase: float, slip0: float
                  ) -> np.ndarray:
    """The wheel angle of a kinematic single-track car whose centre follows the curve of
    curvature ``kappa_of(s)``, integrated here in the plane: the rear axle, half the
    wheelbase behind the centre, moves along the body (no sideways slip), so the body's
    heading obeys ``theta' = sin(psi - theta) / (L / 2)`` per metre of the centre's path,
    ``psi`` its direction; the wheels then stand at ``tan(delta) = L theta' / v_rear``."""
    from scipy.integrate import solve_ivp

    half = wheelbase / 2.0

    def rhs(x: float, y: np.ndarray) -> list[float]:
        psi, theta = y
        return [float(kappa_of(x)), np.sin(psi - theta) / half]  # type: ignore[operator]

    sol = solve_ivp(rhs, (s[0], s[-1]), [0.0, -slip0], t_eval=s, rtol=1e-10, atol=1e-12,
                    max_step=0.05)
    psi, theta = sol.y
    beta = psi - theta
    rate = np.sin(beta) / half  # body's turn per metre of the centre's path
    return np.arctan(wheelbase * rate / np.cos(beta))


@pytest.mark.parametrize("slip0", [0.0, 0.1])
def test_the_towed_wheel_angle_is_the_single_track_cars(slip0: float) -> None:
    """A curve whose curvature jumps from straight to a 6 m radius (between two samples
    0.5 m apart), then eases along a ramp back to 0.05 1/m: the wheel angle of
    :func:`towed_steering` agrees with the single-track car's integrated in the plane (an
    ODE solver, its own formulation; the curvature linear between samples) within a
    hundredth of a radian; at the jump the wheels lag the curvature over about half the
    wheelbase, so the steering rate that they ask at a speed stays finite where the steady
    turn's angle (:func:`~splineplan.speed.steering_angle`) jumps; on the arc they settle
    at the steady angle."""
    from splineplan.speed import steering_angle

    wheelbase = 2.578

    def kappa_of(x: np.ndarray | float) -> np.ndarray:
        x = np.asarray(x, dtype=float)
        return np.where(x < 10.0, 0.0, np.where(x < 30.0, 1.0 / 6.0,
                                                np.maximum(1.0 / 6.0 - (x - 30.0) * 0.01,
                                                           0.05)))

    s = np.arange(0.0, 50.0 + 1e-9, 0.5)
    kappa = kappa_of(s)
    towed = towed_steering(s, kappa, wheelbase=wheelbase, slip0=slip0)
    between = lambda x: np.interp(x, s, kappa)  # noqa: E731 - linear between samples
    assert np.max(np.abs(towed - towed_by_ode(s, between, wheelbase, slip0))) < 0.01
    steady = steering_angle(kappa, wheelbase)
    assert np.max(np.abs(np.diff(towed))) < 0.5 * np.max(np.abs(np.diff(steady)))
    settled = (s > 25.0) & (s < 30.0)
    assert np.allclose(towed[settled], steady[settled], atol=0.01)


@settings(deadline=None)  # the first example compiles the loop
@given(seed=st.integers(0, 2**32 - 1))
def test_the_compiled_limits_are_the_array_code(seed: int) -> None:
    """Level 3's steering smoothing judges its moves with a compiled twin of equation (1)
    and the steering rate's limit (``kernels.allowed_speeds``, from a curve's positions and
    parameter derivatives): on a random curve it gives what ``allowed_speed`` and
    ``steering_speed_limit`` give from the same curvatures and chord lengths."""
    from splineplan import kernels
    from splineplan.curvature import curvature_from_derivatives

    rng = np.random.default_rng(seed)
    m = 60
    d1 = np.column_stack((rng.uniform(0.5, 2.0, m), rng.uniform(-1.0, 1.0, m)))
    d2 = rng.uniform(-0.3, 0.3, (m, 2))
    pos = np.cumsum(np.column_stack((rng.uniform(0.2, 1.0, m), rng.uniform(-0.3, 0.3, m))),
                    axis=0)
    kappa = curvature_from_derivatives(d1, d2)
    corner, steer = kernels.allowed_speeds(pos, d1, d2, 0, m, 2.578, 0.4, 0.7 * 9.81, 15.0)
    chords = np.concatenate(([0.0], np.cumsum(np.hypot(*np.diff(pos, axis=0).T))))
    np.testing.assert_allclose(corner, allowed_speed(kappa, mu=0.7, g=9.81, s_max=15.0),
                               rtol=1e-12)
    np.testing.assert_allclose(
        steer, steering_speed_limit(chords, kappa, wheelbase=2.578, max_steering_rate=0.4),
        rtol=1e-9)


@settings(max_examples=80, deadline=None)
@given(st.floats(0, 30), st.floats(0, 30), st.floats(0.5, 10), st.floats(1, 10),
       st.floats(1, 10), st.floats(0, 1))
def test_a_meeting_profile_ends_where_its_distance_says(v0: float, v_end: float,
                                                        t_end: float, a_up: float,
                                                        a_down: float, frac: float) -> None:
    """Any cruise speed the distances call feasible gives a profile from ``v0`` that ends at
    ``t_end`` with ``v_end`` after that distance, never faster than its limits change speed
    and never backwards; the distance grows with the cruise speed."""
    grid = np.linspace(0.0, 40.0, 400)
    d = meeting_distances(v0, t_end, v_end, a_up=a_up, a_down=a_down, cruise=grid)
    ok = np.flatnonzero(np.isfinite(d))
    if not len(ok):
        # even the straightest change of speed takes longer than t_end
        assert abs(v_end - v0) / (a_up if v_end > v0 else a_down) > t_end - 1e-6
        return
    assert np.all(np.diff(d[ok]) >= -1e-9)
    c = float(grid[ok[int(frac * (len(ok) - 1))]])
    t = np.linspace(0.0, t_end, 2001)
    s, v = meeting_profile(v0, c, t_end, v_end, t, a_up=a_up, a_down=a_down)
    assert s[0] == 0.0 and v[0] == pytest.approx(v0)
    assert v[-1] == pytest.approx(v_end, abs=1e-6)
    assert s[-1] == pytest.approx(float(np.interp(c, grid, d)), rel=1e-6, abs=1e-6)
    assert np.all(v >= 0.0) and np.all(np.diff(s) >= -1e-9)
    acc = np.diff(v) / np.diff(t)
    assert np.all((acc <= a_up + 1e-6) & (acc >= -a_down - 1e-6))
    # the distance is the integral of the speed
    area = float(np.sum((v[1:] + v[:-1]) / 2.0 * np.diff(t)))
    assert s[-1] == pytest.approx(area, abs=1e-3 * max(1.0, s[-1]))
