"""Speed profile along a curve: cornering, steering-rate, speed-limit, acceleration and
braking limits.

Beyond the paper (which only states the cornering speed, equation 1): where the curvature
changes, the front wheels must turn, and a car turns them at a limited rate, so the speed
is bounded there too (:func:`towed_speed_limit`: the wheels of a car whose rear axle is
towed behind the curve; :func:`steering_speed_limit`: those of a steady turn); a forward
pass bounds the speed by the acceleration limit, ``v_j^2 <= v_{j-1}^2 + 2 a_max ds``, and a
backward pass by the braking limit, ``v_j^2 <= v_{j+1}^2 + 2 b_max ds``. Time follows from
the speeds.
"""

from __future__ import annotations

import logging
import math

import numpy as np
from numpy.typing import ArrayLike

from splineplan import kernels
from splineplan.errors import ParameterError
from splineplan.geometry import FloatArray, kernel_floats

log = logging.getLogger(__name__)


def allowed_speed(kappa: ArrayLike, *, mu: float, g: float, s_max: float) -> FloatArray:
    """Equation (1): ``min(sqrt(mu g / |kappa|), s_max)`` [m/s] at curvatures ``kappa`` [1/m]."""
    k = np.abs(np.asarray(kappa, dtype=float))
    with np.errstate(divide="ignore", over="ignore"):  # straight: zero or denormal kappa
        v = np.sqrt(mu * g / k)
    return np.asarray(np.minimum(v, s_max))


def nearby_curvature(s: ArrayLike, kappa: ArrayLike, reach: float) -> FloatArray:
    """The largest ``|kappa|`` [1/m] within ``reach`` [m] of each station of ``s`` ``(n,)``
    [m] (increasing)."""
    st = np.asarray(s, dtype=float)
    k = np.abs(np.asarray(kappa, dtype=float))
    lo = np.searchsorted(st, st - reach, side="left")
    hi = np.searchsorted(st, st + reach, side="right")
    if len(k) == 0:
        return k
    # a sparse table of maxima over windows of 2^j samples answers each [lo, hi) at once
    table = [k]
    width = 1
    while 2 * width <= len(k):
        prev = table[-1]
        table.append(np.maximum(prev[:-width], prev[width:]))
        width *= 2
    n = hi - lo
    level = np.floor(np.log2(np.maximum(n, 1))).astype(int)
    out = np.empty(len(k))
    for j in np.unique(level):
        m = level == j
        w = 1 << int(j)
        out[m] = np.maximum(table[j][lo[m]], table[j][hi[m] - w])
    return out


def steering_angle(kappa: ArrayLike, wheelbase: float) -> FloatArray:
    """Front-wheel angle [rad] of a kinematic single-track car whose centre, half the
    ``wheelbase`` [m] ahead of the rear axle, runs on curvature ``kappa`` [1/m]: the rear
    axle then turns on radius ``sqrt(R^2 - (wheelbase / 2)^2)`` for the centre's radius R,
    and ``tan(angle) = wheelbase / that``."""
    k = np.asarray(kappa, dtype=float)
    half = wheelbase / 2.0
    return np.asarray(np.arctan(wheelbase * k / np.sqrt(np.clip(1.0 - (half * k) ** 2,
                                                                1e-12, None))))


def steering_speed_limit(s: ArrayLike, kappa: ArrayLike, *, wheelbase: float,
                         max_steering_rate: float) -> FloatArray:
    """Speed limit ``(n,)`` [m/s] at stations ``s`` ``(n,)`` [m] that lets the front wheels
    follow the curvature ``kappa`` ``(n,)`` [1/m] at most ``max_steering_rate`` [rad/s].

    A step of ``ds`` over which the wheel angle changes by ``d`` takes ``2 ds / (v_0 + v_1)``
    (see :func:`times_from_profile`), so its mean speed may be at most
    ``max_steering_rate * ds / |d|``; both its ends get that limit (``inf`` where the
    curvature does not change).
    """
    return angle_rate_limit(s, steering_angle(kappa, wheelbase),
                            max_steering_rate=max_steering_rate)


def angle_rate_limit(s: ArrayLike, angle: ArrayLike, *, max_steering_rate: float
                     ) -> FloatArray:
    """Speed limit ``(n,)`` [m/s] at stations ``s`` ``(n,)`` [m] that lets the front wheels
    take the angles ``angle`` ``(n,)`` [rad] there at most ``max_steering_rate`` [rad/s]
    (see :func:`steering_speed_limit`)."""
    st = np.asarray(s, dtype=float)
    turn = np.abs(np.diff(np.asarray(angle, dtype=float)))
    with np.errstate(divide="ignore"):
        step = np.where(turn > 0, max_steering_rate * np.diff(st) / turn, np.inf)
    out = np.full(len(st), np.inf)
    if len(step):
        out[:-1] = step
        out[1:] = np.minimum(out[1:], step)
    return out


def steady_slip(kappa: float, wheelbase: float) -> float:
    """Slip angle [rad] of the centre's path against the body in a steady turn of
    curvature ``kappa`` [1/m] (``sin beta = kappa L / 2``, centre half the ``wheelbase``
    [m] ahead of the rear axle)."""
    return math.asin(min(max(kappa * wheelbase / 2.0, -1.0), 1.0))


def towed_steering(s: ArrayLike, kappa: ArrayLike, *, wheelbase: float, slip0: float
                   ) -> FloatArray:
    """Front-wheel angle ``(n,)`` [rad] at stations ``s`` ``(n,)`` [m] of a kinematic
    single-track car whose centre, half the ``wheelbase`` [m] ahead of the rear axle,
    follows the curvature ``kappa`` ``(n,)`` [1/m], with slip angle ``slip0`` [rad] (the
    centre's direction against the body's) at the start.

    The rear axle is towed without slipping sideways, so the slip angle ``beta`` obeys
    ``d beta / ds = kappa - (2 / L) sin(beta)`` and the wheels stand at
    ``tan(delta) = 2 tan(beta)``: they lag the path's curvature over about ``L / 2`` of
    it, so a change of curvature asks less of the steering than
    :func:`steering_angle`'s steady turn does. The curvature runs linearly between samples
    (:func:`splineplan.kernels.towed_slip` integrates it)."""
    beta = kernels.towed_slip(kernel_floats(s), kernel_floats(kappa), wheelbase / 2.0,
                              float(slip0))
    return np.asarray(np.arctan(2.0 * np.tan(beta)))


def towed_speed_limit(s: ArrayLike, kappa: ArrayLike, *, wheelbase: float,
                      max_steering_rate: float, slip0: float | None = None) -> FloatArray:
    """Speed limit ``(n,)`` [m/s] at stations ``s`` ``(n,)`` [m] that lets the front wheels
    take :func:`towed_steering`'s angles for the curvature ``kappa`` ``(n,)`` [1/m] at
    most ``max_steering_rate`` [rad/s] (:func:`angle_rate_limit`), from the slip angle
    ``slip0`` [rad] at the start (``None``: :func:`steady_slip` of the start's
    curvature)."""
    k = np.asarray(kappa, dtype=float)
    if slip0 is None:
        slip0 = steady_slip(float(k[0]), wheelbase) if len(k) else 0.0
    return angle_rate_limit(s, towed_steering(s, k, wheelbase=wheelbase, slip0=slip0),
                            max_steering_rate=max_steering_rate)


def speed_profile(
    s: ArrayLike,
    limit: ArrayLike,
    *,
    a_max: float,
    b_max: float,
    start_speed: float = 0.0,
    end_speed: float | None = None,
) -> FloatArray:
    """Fastest speeds ``(n,)`` [m/s] at stations ``s`` ``(n,)`` [m] within the limits.

    Parameters
    ----------
    s
        Increasing stations [m].
    limit
        Speed limit ``(n,)`` [m/s] at each station (cornering and ``s_max``).
    a_max, b_max
        Acceleration and braking limits [m/s^2], positive.
    start_speed
        Speed [m/s] at the first station. If it exceeds the limit there, or the curve ahead
        cannot be taken from it within ``b_max``, the profile starts lower (logged at
        debug level: segment joins meet this routinely).
    end_speed
        Speed [m/s] at the last station (0 stops there); ``None`` keeps going as fast as
        the limits allow.
    """
    st = np.asarray(s, dtype=float)
    lim = np.asarray(limit, dtype=float)
    if st.shape != lim.shape or st.ndim != 1 or len(st) == 0:
        raise ParameterError("stations and limits must be 1-d arrays of the same length")
    if a_max <= 0 or b_max <= 0:
        raise ParameterError("a_max and b_max must be positive")
    if start_speed < 0 or (end_speed is not None and end_speed < 0):
        raise ParameterError("start and end speeds must be >= 0")
    ds = np.diff(st)
    v2 = np.square(lim)
    v2[0] = min(v2[0], start_speed**2)
    if end_speed is not None:
        v2[-1] = min(v2[-1], end_speed**2)
    # The passes are min-plus recurrences, v_j^2 = min(lim_j^2, v_{j-1}^2 + 2 a ds): in
    # closed form v_j^2 = C_j + min_{i <= j} (lim_i^2 - C_i) with C the cumulated 2 a ds
    # (and backwards likewise), so both run as cumulative sums and running minima.
    acc = np.concatenate(([0.0], np.cumsum(2.0 * a_max * ds)))
    fwd = acc + np.minimum.accumulate(v2 - acc)
    brk = np.concatenate(([0.0], np.cumsum(2.0 * b_max * ds)))
    out = np.minimum.accumulate((fwd + brk)[::-1])[::-1] - brk
    out = np.clip(np.minimum(out, v2), 0.0, None)
    v = np.sqrt(np.asarray(out))
    if v[0] < start_speed - 1e-9:
        log.debug("start speed %.2f m/s exceeds what the curve allows (%.2f m/s)",
                  start_speed, v[0])
    return v


def times_from_profile(s: ArrayLike, v: ArrayLike) -> FloatArray:
    """Time ``(n,)`` [s] at each station, from 0, for speeds ``v`` [m/s].

    Each step takes ``2 ds / (v_{j-1} + v_j)``, exact under constant acceleration; a step
    between two zero speeds cannot be driven and raises :class:`ParameterError`.
    """
    st = np.asarray(s, dtype=float)
    vel = np.asarray(v, dtype=float)
    ds = np.diff(st)
    vsum = vel[:-1] + vel[1:]
    if np.any((vsum <= 0) & (ds > 0)):
        j = int(np.argmax((vsum <= 0) & (ds > 0)))
        raise ParameterError(f"speed is zero on both ends of the step at station {st[j]:.1f} m")
    dt = np.where(ds > 0, 2.0 * ds / np.where(vsum > 0, vsum, 1.0), 0.0)
    return np.concatenate(([0.0], np.cumsum(dt)))


def meeting_distances(v0: float, t_end: float, v_end: float, *, a_up: float, a_down: float,
                      cruise: ArrayLike) -> FloatArray:
    """Distance [m] covered in ``t_end`` [s] from speed ``v0`` to ``v_end`` [m/s] by the
    three-phase profiles of :func:`meeting_profile`, one per ``cruise`` speed [m/s]; ``nan``
    where the two speed changes take longer than ``t_end``. The distance grows with the
    cruise speed, so a grid of cruise speeds gives every station reachable at that time
    with that speed."""
    vc = np.asarray(cruise, dtype=float)
    t1 = np.where(vc >= v0, vc - v0, v0 - vc) / np.where(vc >= v0, a_up, a_down)
    t3 = np.where(v_end >= vc, v_end - vc, vc - v_end) / np.where(v_end >= vc, a_up, a_down)
    tc = t_end - t1 - t3
    d = (v0 + vc) / 2.0 * t1 + vc * tc + (vc + v_end) / 2.0 * t3
    return np.where(tc >= -1e-9, d, np.nan)


def meeting_profile(v0: float, cruise: float, t_end: float, v_end: float, times: ArrayLike,
                    *, a_up: float, a_down: float) -> tuple[FloatArray, FloatArray]:
    """Distance [m] and speed [m/s] at ``times`` [s] (from 0 to ``t_end``) of the profile
    that changes from ``v0`` to ``cruise`` at the acceleration or braking limit, holds it
    (standing still if it is 0) and changes to ``v_end`` so as to end there at ``t_end``:
    the profile that meets a station at a time with a speed (a goal region with a time
    window), where driving as fast as allowed arrives too early or too fast."""
    t = np.clip(np.asarray(times, dtype=float), 0.0, t_end)
    r1 = a_up if cruise >= v0 else -a_down
    r3 = a_up if v_end >= cruise else -a_down
    t1 = (cruise - v0) / r1 if cruise != v0 else 0.0
    t3 = (v_end - cruise) / r3 if v_end != cruise else 0.0
    tb = t_end - t3  # the last phase's start
    u1 = np.minimum(t, t1)
    uc = np.clip(t - t1, 0.0, max(tb - t1, 0.0))
    u3 = np.clip(t - tb, 0.0, t3)
    s = (v0 * u1 + r1 * u1**2 / 2.0 + cruise * uc + cruise * u3 + r3 * u3**2 / 2.0)
    v = np.where(t < t1, v0 + r1 * u1, np.where(t < tb, cruise, cruise + r3 * u3))
    return s, np.maximum(v, 0.0)
