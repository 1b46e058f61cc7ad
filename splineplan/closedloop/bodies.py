"""Where the bodies of long vehicles will sweep through a junction (pure; no SUMO).

SUMO moves a vehicle along its lanes' centre lines: its body is the rectangle from its back,
its length behind the front along its lanes, to its front. Through a junction turn a bus's
body cuts across the inside of the curve (a 12 m bus on a turn of 10 m radius lies 2 m
inside its lane's centre line at its middle), over lanes whose drivers SUMO lets go on
(their connections are no foes). A planned vehicle sees the bus and gives way: it predicts
the body at constant speed along the bus's lanes for a few seconds (:func:`body_path`,
:func:`bodies_along`) and finds where and when that body meets its own path
(:func:`meeting`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from splineplan.geometry import FloatArray, dedupe_polyline, polyline_stations
from splineplan.spacetime import box_gap

#: Vehicles at least this long [m] have their bodies predicted through junctions (a car's
#: body keeps to its lane within a few centimetres).
LONG_VEHICLE = 7.0
#: Prediction horizon [s] and step [s].
HORIZON = 6.0
STEP = 0.25
#: A body whose path turns less than this [rad] keeps to its lanes within a few
#: decimetres (a bus through a straight connection): the time-gap control sees it.
BODY_TURN = 0.3
#: A long vehicle slower than this [m/s] is standing: its body stays where it is (the
#: time-gap control sees it there).
MOVING = 0.5


@dataclass(frozen=True)
class BodyPath:
    """The centre line ``xy`` ``(n, 2)`` [m] a vehicle's front follows through some lanes,
    with its stations ``s`` ``(n,)`` [m], the station where each lane begins ``starts``
    and each lane's shape length over its SUMO length ``scales`` (SUMO's lane positions
    run along a lane's length, which may differ from its shape's)."""

    xy: FloatArray
    s: FloatArray
    starts: FloatArray
    scales: FloatArray
    #: how far [rad] its heading turns from end to end (with every bend)
    turn: float = 0.0

    def station(self, index: int, pos: float) -> float:
        """Station [m] of lane position ``pos`` [m] on lane ``index``."""
        return float(self.starts[index]) + max(pos, 0.0) * float(self.scales[index])


def body_path(lanes: list[tuple[FloatArray, float]]) -> BodyPath:
    """The centre line through ``lanes`` (each its shape ``(k, 2)`` [m] and SUMO length
    [m], in driving order)."""
    parts, starts, scales, at = [], [], [], 0.0
    for shape, length in lanes:
        shape = np.asarray(shape, dtype=float)
        geo = float(polyline_stations(shape)[-1]) if len(shape) > 1 else 0.0
        starts.append(at)
        scales.append(geo / length if length > 0 else 1.0)
        at += geo
        parts.append(shape)
    xy = dedupe_polyline(np.concatenate(parts))
    d = np.diff(xy, axis=0)
    heads = np.unwrap(np.arctan2(d[:, 1], d[:, 0])) if len(d) else np.zeros(1)
    return BodyPath(xy, polyline_stations(xy), np.array(starts), np.array(scales),
                    float(np.ptp(heads)))


def points_at(path: BodyPath, stations: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Points ``(k, 2)`` [m] and headings ``(k,)`` [rad] at ``stations`` [m] of ``path``,
    straight on beyond its ends."""
    s, xy = path.s, path.xy
    st = np.asarray(stations, dtype=float)
    seg = np.clip(np.searchsorted(s, st, side="right") - 1, 0, len(s) - 2)
    d = xy[seg + 1] - xy[seg]
    ln = s[seg + 1] - s[seg]
    f = (st - s[seg]) / ln
    return xy[seg] + f[:, None] * d, np.arctan2(d[:, 1], d[:, 0])


def bodies_along(path: BodyPath, at: float, speed: float, length: float, *,
                 horizon: float = HORIZON, step: float = STEP
                 ) -> tuple[FloatArray, FloatArray, FloatArray]:
    """The body of a vehicle of ``length`` [m] whose front is at station ``at`` [m] of
    ``path``, driving on along it at ``speed`` [m/s]: times ``(k,)`` [s] from now, and its
    centres ``(k, 2)`` [m] and headings ``(k,)`` [rad] then (the rectangle from its back to
    its front, as SUMO draws it)."""
    t = np.arange(0.0, horizon + 1e-9, step)
    front = at + speed * t
    pf, _ = points_at(path, front)
    pb, _ = points_at(path, front - length)
    d = pf - pb
    head = np.arctan2(d[:, 1], d[:, 0])
    return t, 0.5 * (pf + pb), head


def meeting(times: FloatArray, centres: FloatArray, heads: FloatArray,
            size: tuple[float, float], path_s: FloatArray, path_xy: FloatArray,
            path_h: FloatArray, ego: tuple[float, float], margin: float
            ) -> tuple[float, float, float, float] | None:
    """Where and when a predicted body (``times``, ``centres``, ``heads`` of
    :func:`bodies_along`, ``size`` its length and width [m]) comes within ``margin`` [m]
    of the ego's footprint (``ego``: length, width [m]) on its path (centre stations
    ``path_s``, points ``path_xy``, headings ``path_h``): the first and last station [m]
    of the path so met, and the first and last time [s] of the body that meets it;
    ``None`` if it never does."""
    k, n = len(times), len(path_s)
    if not k or not n:
        return None
    reach = 0.5 * (math.hypot(*size) + math.hypot(*ego)) + margin
    # only path samples within reach of some body
    d2 = ((path_xy[None, :, :] - centres[:, None, :]) ** 2).sum(axis=2)  # (k, n)
    near = d2 <= reach * reach
    if not near.any():
        return None
    ki, ni = np.nonzero(near)
    gap = box_gap(centres[ki], heads[ki], size, path_xy[ni], path_h[ni], ego)
    hit = gap <= margin
    if not hit.any():
        return None
    ki, ni = ki[hit], ni[hit]
    return (float(path_s[ni].min()), float(path_s[ni].max()), float(times[ki].min()),
            float(times[ki].max()))
