"""Where the bodies of long vehicles will sweep through a junction (pure; no SUMO).

SUMO moves a vehicle's front along its lanes' centre lines and turns the vehicle to the
direction from its back, its length behind the front along its lanes, to its front; its
body is the rectangle of its length behind the front in that direction (as SUMO reports
and draws it, and as the run's collision check counts it). Through a junction turn a bus's
body cuts across the inside of the curve (a 12 m bus on a turn of 10 m radius lies about
1.7 m inside its lane's centre line at its middle), over lanes whose drivers SUMO lets go
on (their connections are no foes), and its rear reaches out past its back on the lanes
(up to 3.5 m for a 12 m bus round a square corner), over the lane beside the one it turns
from. A planned vehicle sees the bus and gives way: it predicts
the body along the bus's lanes for a few seconds, a slow one until it has left the
junction, at its speed, or speeding up where it is in the junction already
(:func:`body_path`, :func:`bodies_along`), and finds where and when that body meets its own
path (:func:`meeting`, :func:`meetings` for several bodies at once).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from splineplan.geometry import (
    FloatArray,
    dedupe_polyline,
    kernel_floats,
    kernel_ints,
    polyline_stations,
)
from splineplan.kernels import body_meetings

#: Vehicles at least this long [m] have their bodies predicted through junctions (a car's
#: body keeps to its lane within a few centimetres).
LONG_VEHICLE = 7.0
#: Prediction horizon [s] and step [s].
HORIZON = 6.0
#: The longest horizon [s] of a slow vehicle, followed until its body has left the
#: junction.
SLOW_HORIZON = 30.0
STEP = 0.25
#: A long vehicle slower than this [m/s] is standing: its body stays where it is (the
#: time-gap control sees it there). A bus creeping into a junction at 0.4 m/s is not.
MOVING = 0.1
#: A long vehicle inside a junction drives on out of it: its body is predicted speeding up
#: at this rate [m/s²] (SUMO's default of a bus) to this speed [m/s].
JUNCTION_ACCEL = 1.2
JUNCTION_TOP = 8.0


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
    return BodyPath(xy, polyline_stations(xy), np.array(starts), np.array(scales))


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
                 accel: float = 0.0, top: float = 0.0, horizon: float = HORIZON,
                 step: float = STEP) -> tuple[FloatArray, FloatArray, FloatArray]:
    """The body of a vehicle of ``length`` [m] whose front is at station ``at`` [m] of
    ``path``, driving on along it at ``speed`` [m/s] (speeding up at ``accel`` [m/s²] to
    ``top`` [m/s] where that is faster): times ``(k,)`` [s] from now, and its centres
    ``(k, 2)`` [m] and headings ``(k,)`` [rad] then (SUMO's rectangle: ``length`` behind
    the front, headed from the back on its lanes to the front)."""
    t = np.arange(0.0, horizon + 1e-9, step)
    front = at + speed * t
    if accel > 0.0 and top > speed:
        up = np.minimum(t, (top - speed) / accel)  # time spent speeding up
        front += 0.5 * accel * up * up + accel * up * (t - up)
    pf, _ = points_at(path, front)
    pb, _ = points_at(path, front - length)
    d = pf - pb
    head = np.arctan2(d[:, 1], d[:, 0])
    u = np.column_stack((np.cos(head), np.sin(head)))
    return t, pf - 0.5 * length * u, head


def meeting(times: FloatArray, centres: FloatArray, heads: FloatArray,
            size: tuple[float, float], path_s: FloatArray, path_xy: FloatArray,
            path_h: FloatArray, ego: tuple[float, float], margin: float
            ) -> tuple[float, float, float, float] | None:
    """Where and when a predicted body (``times``, ``centres``, ``heads`` of
    :func:`bodies_along`, ``size`` its length and width [m]) comes within ``margin`` [m]
    of the ego's footprint (``ego``: length, width [m]) on its path (centre stations
    ``path_s``, points ``path_xy``, headings ``path_h``): the first and last station [m]
    of the path so met, and the first and last time [s] of the body that meets it;
    ``None`` if it never does (:func:`meetings` of one body)."""
    k = len(times)
    met = meetings(np.zeros(k, dtype=np.int64), 1, np.asarray(times, dtype=float),
                   np.asarray(centres, dtype=float), np.asarray(heads, dtype=float),
                   np.full(k, size[0]), np.full(k, size[1]), np.full(k, margin),
                   path_s, path_xy, path_h, ego)
    if np.isnan(met[0, 0]):
        return None
    return (float(met[0, 0]), float(met[0, 1]), float(met[0, 2]), float(met[0, 3]))


def meetings(body: NDArray[np.int64], n_bodies: int, times: FloatArray, centres: FloatArray,
             heads: FloatArray, lengths: FloatArray, widths: FloatArray, margins: FloatArray,
             path_s: FloatArray, path_xy: FloatArray, path_h: FloatArray,
             ego: tuple[float, float]) -> FloatArray:
    """:func:`meeting` of several bodies at once: rows of predicted rectangles (``body``
    index, time [s], centre, heading, length, width [m], and the margin [m] of each),
    ``(n_bodies, 4)`` first and last path station [m] met and first and last time [s]
    meeting for each body, NaN for a body that never meets the path."""
    return body_meetings(kernel_ints(body), n_bodies, kernel_floats(times),
                         kernel_floats(centres), kernel_floats(heads), kernel_floats(lengths),
                         kernel_floats(widths), kernel_floats(margins), kernel_floats(path_s),
                         kernel_floats(path_xy), kernel_floats(path_h), float(ego[0]),
                         float(ego[1]))
