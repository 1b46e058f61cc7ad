"""Safety between any two vehicles of a run, from SUMO's FCD output (pure; no SUMO).

For every time step of ``fcd.xml``: the gap between the footprints (oriented rectangles)
of every two vehicles near each other, and their time-to-collision if both kept their
speed and heading (the first time their rectangles would touch, within
:data:`TTC_HORIZON`); the smallest of each over the run, for all pairs and for the pairs
with a planned vehicle, and the pairs with a planned vehicle whose footprints overlapped
(and, for comparison, how many pairs of SUMO's own vehicles did).

The smallest time-to-collision of a run is 0 wherever any two vehicles touch (SUMO's own
vehicles overlap in junctions), so it says little; the time exposed to a time-to-collision
below :data:`TET_THRESHOLD` (TET, Minderhoud and Bovy 2001), summed over pairs and divided
by the vehicles' time in the run, measures how often vehicles come close, and compares
runs of different sizes.
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from collections.abc import Iterable
from pathlib import Path
from typing import Any

import numpy as np
from scipy.spatial import cKDTree

from splineplan import kernels
from splineplan.geometry import heading_from_sumo_angle, kernel_floats
from splineplan.spacetime import box_gap

#: Longest time-to-collision [s] looked for, and its time step [s].
TTC_HORIZON = 5.0
TTC_STEP = 0.1
#: Pairs whose centres are farther apart than this [m] plus the largest diagonal are not
#: measured (at city speeds, their time-to-collision is above a second or two).
REACH = 30.0
#: Time-to-collision [s] below which a pair counts as exposed (the time exposed TTC).
TET_THRESHOLD = 1.5


def pair_safety(fcd: Path, sizes: dict[str, tuple[float, float]],
                planned: Iterable[str]) -> dict[str, Any]:
    """Smallest gap [m] and time-to-collision [s] between any two vehicles of ``fcd``
    (with the time and the pair), over all pairs, over those with a ``planned`` vehicle and
    (the gap) over those of two planned vehicles, and the pairs with a planned vehicle whose
    footprints overlapped (first time), the number of pairs of two vehicles not planned
    whose footprints overlapped (SUMO's drivers see each other by lanes, and their long
    vehicles swing across lane lines in turns and lane changes), and the time exposed to
    a time-to-collision below :data:`TET_THRESHOLD` (pair-seconds per vehicle-hour; all
    pairs and those with a planned vehicle).

    ``sizes``: (length, width) [m] of each vehicle type; a type missing is taken as
    4.5 x 1.8 m.
    """
    plan = set(planned)
    best = {"gap": _Min(), "gap_planned": _Min(), "gap_both": _Min(), "ttc": _Min(),
            "ttc_planned": _Min()}
    overlaps: dict[tuple[str, str], float] = {}
    unplanned: set[tuple[str, str]] = set()
    times: list[float] = []
    exposed = np.zeros(3)  # pair-steps exposed: all, with a planned vehicle; vehicle-steps
    for t, ids, front, head, speed, types in _steps(fcd):
        n = len(ids)
        times.append(t)
        exposed[2] += n
        if n < 2:
            continue
        size = np.array([sizes.get(ty, (4.5, 1.8)) for ty in types], dtype=float)
        u = np.column_stack((np.cos(head), np.sin(head)))
        centre = front - u * (size[:, :1] / 2.0)
        reach = float(np.hypot(size[:, 0], size[:, 1]).max()) + REACH
        pairs = cKDTree(centre).query_pairs(reach, output_type="ndarray")
        if not len(pairs):
            continue
        i, j = pairs[:, 0], pairs[:, 1]
        mine = np.array([v in plan for v in ids])
        with_plan = mine[i] | mine[j]
        gap = _gaps(centre[i], head[i], size[i], centre[j], head[j], size[j])
        ttc = _ttc(centre, head, speed, size, i, j, gap)
        for key, mask in (("gap", slice(None)), ("gap_planned", with_plan),
                          ("gap_both", mine[i] & mine[j])):
            best[key].update(gap[mask], t, ids, i[mask], j[mask])
        for key, mask in (("ttc", slice(None)), ("ttc_planned", with_plan)):
            best[key].update(ttc[mask], t, ids, i[mask], j[mask])
        low = ttc < TET_THRESHOLD
        exposed[:2] += (np.count_nonzero(low), np.count_nonzero(low & with_plan))
        for k in np.flatnonzero(gap <= 0.0):
            a, b = sorted((ids[i[k]], ids[j[k]]))
            if with_plan[k]:
                overlaps.setdefault((a, b), t)
            else:
                unplanned.add((a, b))
    return {
        "min_gap": best["gap"].record(),
        "min_gap_planned": best["gap_planned"].record(),
        "min_gap_between_planned": best["gap_both"].record(),
        "min_ttc": best["ttc"].record(),
        "min_ttc_planned": best["ttc_planned"].record(),
        "ttc_horizon": TTC_HORIZON,
        **_exposure(exposed, times),
        "collision_pairs_planned": [{"pair": list(p), "time": t}
                                    for p, t in sorted(overlaps.items(), key=lambda kv: kv[1])],
        "overlapping_pairs_unplanned": len(unplanned),
    }


def _exposure(counts: np.ndarray, times: list[float]) -> dict[str, Any]:
    """The time exposed to a low time-to-collision per vehicle-hour, from the pair-steps
    exposed (all, with a planned vehicle) and the vehicle-steps ``counts`` over steps at
    ``times`` [s] (``None`` where no vehicle was there)."""
    steps = np.diff(np.asarray(times, dtype=float))
    period = float(np.min(steps[steps > 0])) if (steps > 0).any() else 1.0
    hours = counts[2] * period / 3600.0
    per_hour = [float(c * period / hours) if hours > 0 else None for c in counts[:2]]
    return {"tet_threshold": TET_THRESHOLD, "tet_per_vehicle_hour": per_hour[0],
            "tet_planned_per_vehicle_hour": per_hour[1]}


class _Min:
    """The smallest value seen, with when and between whom."""

    def __init__(self) -> None:
        self.value = math.inf
        self.time = math.nan
        self.pair: tuple[str, str] = ("", "")

    def update(self, values: np.ndarray, t: float, ids: list[str], i: np.ndarray,
               j: np.ndarray) -> None:
        if not len(values):
            return
        k = int(np.argmin(values))
        if values[k] < self.value:
            self.value = float(values[k])
            self.time = t
            self.pair = (ids[i[k]], ids[j[k]])

    def record(self) -> dict[str, Any] | None:
        if not math.isfinite(self.value):
            return None
        return {"value": self.value, "time": self.time, "pair": list(self.pair)}


def _gaps(c1: np.ndarray, h1: np.ndarray, s1: np.ndarray, c2: np.ndarray, h2: np.ndarray,
          s2: np.ndarray) -> np.ndarray:
    """:func:`~splineplan.spacetime.box_gap` for rectangles of several sizes (``s1``,
    ``s2``: ``(N, 2)`` length and width [m] of each)."""
    return box_gap(c1, h1, (s1[:, 0], s1[:, 1]), c2, h2, (s2[:, 0], s2[:, 1]))


def _ttc(centre: np.ndarray, head: np.ndarray, speed: np.ndarray, size: np.ndarray,
         i: np.ndarray, j: np.ndarray, gap: np.ndarray) -> np.ndarray:
    """Time [s] until the rectangles of pairs ``i``, ``j`` touch at constant speed and
    heading (``inf`` beyond :data:`TTC_HORIZON` or never; 0 where they overlap)."""
    out = np.where(gap <= 0.0, 0.0, np.inf)
    vel = np.column_stack((np.cos(head), np.sin(head))) * speed[:, None]
    rel = vel[j] - vel[i]
    d = centre[j] - centre[i]
    closing = -np.sum(d * rel, axis=1) > 0.0  # the centres come nearer
    # cannot touch within the horizon: the gap exceeds what the relative speed covers
    cand = np.flatnonzero((gap > 0.0) & closing
                          & (gap < np.hypot(rel[:, 0], rel[:, 1]) * TTC_HORIZON))
    if not len(cand):
        return out
    ci, cj = i[cand], j[cand]
    taus = np.arange(TTC_STEP, TTC_HORIZON + TTC_STEP / 2, TTC_STEP)
    out[cand] = kernels.first_touch(
        kernel_floats(centre[ci]), kernel_floats(head[ci]), kernel_floats(size[ci, 0]),
        kernel_floats(size[ci, 1]), kernel_floats(vel[ci]), kernel_floats(centre[cj]),
        kernel_floats(head[cj]), kernel_floats(size[cj, 0]), kernel_floats(size[cj, 1]),
        kernel_floats(vel[cj]), taus)
    return out


def _steps(fcd: Path) -> Iterable[tuple[float, list[str], np.ndarray, np.ndarray, np.ndarray,
                                        list[str]]]:
    """Each time step of an FCD file: time, ids, front bumpers ``(n, 2)``, headings,
    speeds and types."""
    for _, el in ET.iterparse(fcd):
        if el.tag != "timestep":
            continue
        vs = [v for v in el if v.tag == "vehicle"]
        if vs:
            ids = [v.get("id", "") for v in vs]
            front = np.array([(float(v.get("x", 0)), float(v.get("y", 0))) for v in vs])
            head = np.asarray(heading_from_sumo_angle(
                [float(v.get("angle", 0)) for v in vs]), dtype=float)
            speed = np.array([float(v.get("speed", 0)) for v in vs])
            types = [v.get("type", "") for v in vs]
            yield float(el.get("time", 0)), ids, front, head, speed, types
        el.clear()
