"""Lane keeping for planned vehicles among SUMO's traffic (pure; no SUMO).

SUMO puts a vehicle moved with ``moveToXY`` on one lane only: the part of it that reaches
into the neighbouring lane is not seen by that lane's drivers (they drive into it), nor by
SUMO's collision check. Level 2 left alone centres a vehicle in the free road, which on a
road of two lanes one way is the line between them. :func:`lane_band` bounds the centre of
the vehicle to one lane on each edge of the window (the corridor's keep offsets, which the
roadmap honours), so that its footprint stays within the lane SUMO has it on; where the
route needs another lane before a junction (the corridor's own keep offsets), the band
gives way to those some metres before, and a lane blocked by a stopped vehicle or an
obstacle falls back to the whole road (the roadmap's own rule for keep offsets).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np

from splineplan.corridor import UNBOUNDED, Corridor
from splineplan.geometry import FloatArray

#: ``leads_to(k, lane)`` of :func:`lane_band`.
LeadsTo = Callable[[int, int], "int | None"]

#: Stations [m] before a needed change of lane from which the band holds the lane the
#: route needs (the room for the change).
CHANGE_ROOM = 30.0
#: Least half width [m] of the band for the centre.
MIN_SLACK = 0.2


def lane_band(window: Corridor, station: float, lateral: float, *, lane_width: float,
              half_width: float, leads_to: LeadsTo | None = None,
              arrive: int | None = None) -> Corridor:
    """``window`` with its keep offsets narrowed to one lane on each edge.

    Parameters
    ----------
    window
        The corridor the vehicle plans on (stations from 0).
    station, lateral
        The vehicle's centre on ``window`` [m]: its lane on the current edge (in a
        junction, on the edge it comes out on) is the one this lies in, counted from the
        right boundary in lanes of ``lane_width`` [m].
    leads_to
        ``leads_to(k, lane)``: the lane of the window's edge ``k + 1`` that lane ``lane``
        of its edge ``k`` leads to (SUMO's connections: a left turn into a street of two
        lanes comes out on the left one, beside a right turn coming out on the right one),
        ``None`` if not known; without it, or where it does not know, the lane of the
        same index (or the leftmost, on fewer lanes).
    arrive
        In a junction: the lane of the edge it comes out on that its connection leads to
        (instead of the one its centre lies in).
    half_width
        Half the vehicle's width [m]: the centre keeps ``lane_width / 2 - half_width``
        (at least :data:`MIN_SLACK`) from the lane's centre line.

    Junction stretches keep the window's own keep offsets. From :data:`CHANGE_ROOM`
    before the first station where the lane of the band does not lead on (the window's
    keep offsets before a junction), the band holds the lane that does: the vehicle
    changes lanes there rather than drift across both.
    """
    if lane_width <= 0.0:
        return window
    s = window.s
    right, left = window.bounds_at(s)
    k_lo, k_hi = window.keep_at(s)
    lanes = np.maximum(np.rint((left - right) / lane_width), 1.0)
    gaps = (list(zip(window.edge_ends[:-1].tolist(), window.edge_starts[1:].tolist(),
                     strict=True)) if len(window.edge_ends) else [])  # the junctions
    at = station
    inside = False
    for end, nxt in gaps:
        if end < station < nxt:  # in a junction: the lane it comes out on
            at, inside = nxt, True
    r0, l0 = window.bounds_at(at)
    here = int(np.clip(math.floor((lateral - float(r0)) / lane_width), 0,
                       max(round((float(l0) - float(r0)) / lane_width), 1) - 1))
    if inside and arrive is not None:
        here = arrive
    index = np.minimum(_lanes_along(window, at, here, leads_to), lanes - 1.0)
    slack = max(0.5 * lane_width - half_width, MIN_SLACK)
    centre = right + (index + 0.5) * lane_width
    b_lo, b_hi = centre - slack, centre + slack
    band = np.ones(len(s), dtype=bool)
    for end, nxt in gaps:
        band &= ~((s > end) & (s < nxt))
    new_lo, new_hi = np.maximum(k_lo, b_lo), np.minimum(k_hi, b_hi)
    apart = band & (new_lo > new_hi)  # the route needs another lane here
    if apart.any():
        # from CHANGE_ROOM before, the lane the route needs (where the window's keep
        # offsets leave room for one): change lanes there, not stand across two
        first = int(np.argmax(apart))
        mid = 0.5 * (max(float(k_lo[first]), float(right[first]))
                     + min(float(k_hi[first]), float(left[first])))
        target = np.clip(math.floor((mid - float(right[first])) / lane_width), 0,
                         lanes - 1.0)
        change = band & (s >= float(s[first]) - CHANGE_ROOM)
        t_centre = right + (target + 0.5) * lane_width
        t_lo = np.maximum(k_lo, t_centre - slack)
        t_hi = np.minimum(k_hi, t_centre + slack)
        new_lo = np.where(change, t_lo, new_lo)
        new_hi = np.where(change, t_hi, new_hi)
        band &= new_lo <= new_hi
    new_lo = np.where(band, new_lo, k_lo)
    new_hi = np.where(band, new_hi, k_hi)
    if not band.any():
        return window
    return replace(window, keep_left=np.minimum(new_hi, UNBOUNDED),
                   keep_right=np.maximum(new_lo, -UNBOUNDED))


def _lanes_along(window: Corridor, at: float, here: int, leads_to: LeadsTo | None
                 ) -> FloatArray:
    """The lane index at each station of ``window``: ``here`` on the edge at station
    ``at`` and before it, and on each edge after it the lane the one before leads to
    (``leads_to``; the same index where that is not known)."""
    s = window.s
    out = np.full(len(s), float(here))
    starts = window.edge_starts
    if leads_to is None or len(starts) < 2:
        return out
    k0 = max(int(np.searchsorted(starts, at, side="right")) - 1, 0)
    lane = here
    for k in range(k0, len(starts) - 1):
        nxt = leads_to(k, lane)
        lane = lane if nxt is None else nxt
        out[s >= starts[k + 1]] = float(lane)
    return out


#: How far [m] a vehicle's centre outside the corridor may be moved back onto it to plan
#: from there, and how far [m] inside the boundary it is put.
ONTO_ROAD = 0.5
ONTO_INSET = 0.05


def onto_road(window: Corridor, xy: tuple[float, float]) -> tuple[float, float] | None:
    """A start for level 2 on ``window`` near the vehicle's centre ``xy`` [m] that lies
    outside its boundaries: the point at the same station, :data:`ONTO_INSET` inside the
    nearer boundary, if within :data:`ONTO_ROAD` of ``xy``; ``None`` otherwise (also where
    ``xy`` is inside).

    A vehicle that drifted out of the corridor (a crawl through a tight turn) could
    otherwise plan no more and stand there for good; SUMO puts it on the new start at the
    next step.
    """
    s, lat = (float(v) for v in window.to_sl(np.asarray([xy], dtype=float))[0])
    if not 0.0 <= s <= window.length:
        return None
    right, left = (float(v) for v in window.bounds_at(s))
    if right <= lat <= left or left - right <= 2.0 * ONTO_INSET:
        return None
    new = min(max(lat, right + ONTO_INSET), left - ONTO_INSET)
    if abs(new - lat) > ONTO_ROAD:
        return None
    x, y = (float(v) for v in window.to_xy(np.array([s]), np.array([new]))[0])
    return x, y


@dataclass(frozen=True)
class LaneChange:
    """Where a plan first reaches into the next lane: the plan's station ``at`` [m], that
    lane's index ``lane`` counted from the right among the lanes the vehicle may use, the
    lanes' ``width`` [m], the lane's SUMO id, and the station ``end`` [m] where its
    footprint is inside one lane again (``inf``: not before the next junction)."""

    at: float
    lane: int
    width: float
    lane_id: str
    end: float = float("inf")


#: Slack [m] by which a footprint may reach over a lane line before it counts as in the
#: next lane.
LINE_SLACK = 0.1


def lane_entry(lateral: FloatArray, right: FloatArray, reach: FloatArray, *,
               lane_width: float) -> tuple[int, int, int] | None:
    """Where a path first reaches into another lane: the index of the first of its samples
    (centre offsets ``lateral`` [m], road's right boundary ``right`` [m] at each, along one
    edge) whose footprint, reaching ``reach`` [m] to each side of its centre, reaches
    over a line of the lane its first sample's centre is in (by more than
    :data:`LINE_SLACK`), that lane's index (counted from the right, in lanes of
    ``lane_width`` [m]), and the index of the first sample after it whose footprint is
    inside one lane again (the number of samples if none is); ``None`` if it stays in its
    lane."""
    if not len(lateral) or lane_width <= 0.0:
        return None
    rel = np.asarray(lateral, dtype=float) - np.asarray(right, dtype=float)
    here = math.floor(float(rel[0]) / lane_width)
    lo, hi = here * lane_width, (here + 1) * lane_width
    out_left = rel + reach > hi + LINE_SLACK
    out_right = rel - reach < lo - LINE_SLACK
    out = out_left | out_right
    if not out.any():
        return None
    k = int(np.argmax(out))
    lane = np.floor(rel / lane_width)
    inside = ((rel + reach <= (lane + 1) * lane_width + LINE_SLACK)
              & (rel - reach >= lane * lane_width - LINE_SLACK))
    inside[:k] = False
    end = int(np.argmax(inside)) if inside.any() else len(rel)
    return k, here + 1 if out_left[k] else here - 1, end


def side_reach(relative_heading: FloatArray, half_length: float, half_width: float
               ) -> FloatArray:
    """How far [m] a rectangle's footprint reaches to each side of its centre across a
    line it heads ``relative_heading`` [rad] away from."""
    a = np.abs(np.sin(relative_heading))
    return half_width * np.sqrt(1.0 - a * a) + half_length * a
