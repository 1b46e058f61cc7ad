"""SUMO's SSM device (surrogate safety measures): the options that equip a run's vehicles
with it, and a reader of its output, ``ssm.xml`` (SUMO's own format, read by SUMO's tools).

The device follows each equipped vehicle's encounters with the vehicles within
:data:`RANGE` of it along the lanes and logs a ``<conflict>`` when one of :data:`MEASURES`
passes its threshold (:data:`THRESHOLDS`), with the encounter's smallest time-to-collision
(TTC), largest deceleration rate to avoid a crash (DRAC) and its post-encroachment time
(PET). It is lane-based: leaders and followers on a lane and the conflict areas of
junctions; a vehicle's lateral offset within its lane is not seen. Pure: no SUMO running.
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

#: The output's file name in a run folder.
FILE = "ssm.xml"
#: The measures logged, in the order of :data:`THRESHOLDS`' values on SUMO's command line.
MEASURES = ("TTC", "DRAC", "PET")
#: A conflict is logged where TTC [s] or PET [s] falls below, or DRAC [m/s^2] rises above,
#: these (SUMO's defaults, the values common in the literature).
THRESHOLDS = {"TTC": 3.0, "DRAC": 3.0, "PET": 2.0}
#: Detection range [m]: a vehicle closing in at up to RANGE / THRESHOLDS["TTC"] = 16.7 m/s
#: (60 km/h, above the bundled networks' limits) is followed before its TTC passes 3 s.
RANGE = 50.0
#: SSM's encounter type for two vehicles whose (lane-based) positions overlap.
COLLISION_TYPE = 111


def ssm_options(path: Path, vehicles: Sequence[str] | None = None) -> list[str]:
    """SUMO's command-line options that equip ``vehicles`` (every vehicle where ``None``)
    with the SSM device, all writing to the one file ``path``."""
    equip = (["--device.ssm.probability", "1"] if vehicles is None
             else ["--device.ssm.explicit", ",".join(vehicles)])
    return [*equip, "--device.ssm.measures", " ".join(MEASURES),
            "--device.ssm.thresholds", " ".join(f"{THRESHOLDS[m]:g}" for m in MEASURES),
            "--device.ssm.range", f"{RANGE:g}", "--device.ssm.file", str(path)]


@dataclass(frozen=True)
class _Value:
    """One measure's extreme in one logged conflict: value, time [s], SSM's encounter type
    and position ``(x, y)`` [m]."""

    value: float
    time: float
    type: int | None
    position: tuple[float, float] | None


@dataclass(frozen=True)
class _Conflict:
    """An encounter of two vehicles (ids in order): its time span [s], each measure's
    extreme and whether SSM classed it as a collision."""

    pair: tuple[str, str]
    begin: float
    end: float
    values: dict[str, _Value]
    collision: bool

    def merged(self, other: _Conflict) -> _Conflict:
        """One conflict of the two (the same encounter, logged by each vehicle)."""
        values = dict(self.values)
        for m, v in other.values.items():
            if m not in values or _worse(m, v.value, values[m].value):
                values[m] = v
        return _Conflict(self.pair, min(self.begin, other.begin), max(self.end, other.end),
                         values, self.collision or other.collision)


def read_ssm(path: Path, planned: Iterable[str] = ()) -> dict[str, Any]:
    """SUMO's surrogate safety measures of a run from its ``ssm.xml``.

    A conflict that both vehicles' devices logged (overlapping in time) counts once.
    Returns ``sumo_ssm_min_ttc`` [s], ``sumo_ssm_min_ttc_planned`` (pairs with a
    ``planned`` vehicle), ``sumo_ssm_max_drac`` [m/s^2] and ``sumo_ssm_min_pet`` [s], each
    with its time [s], pair, SSM's encounter type and position (``None`` where no conflict
    has the measure); ``sumo_ssm_conflicts`` (how many), ``sumo_ssm_threshold_conflicts``
    (by measure, those past its threshold: TTC and PET below, DRAC above),
    ``sumo_ssm_collisions`` (conflicts SSM classed as a collision, type
    :data:`COLLISION_TYPE`) and ``sumo_ssm`` (the file and the device's settings).

    Raises
    ------
    OSError, xml.etree.ElementTree.ParseError, ValueError
        The file cannot be read, is not complete XML or holds a malformed number.
    """
    conflicts = _merged(_conflicts(path))
    plan = set(planned)
    with_plan = [c for c in conflicts if plan & set(c.pair)]
    return {
        "sumo_ssm_min_ttc": _extreme(conflicts, "TTC"),
        "sumo_ssm_min_ttc_planned": _extreme(with_plan, "TTC"),
        "sumo_ssm_max_drac": _extreme(conflicts, "DRAC"),
        "sumo_ssm_min_pet": _extreme(conflicts, "PET"),
        "sumo_ssm_conflicts": len(conflicts),
        "sumo_ssm_threshold_conflicts": {
            m: sum(1 for c in conflicts if m in c.values and _past(m, c.values[m].value))
            for m in MEASURES},
        "sumo_ssm_collisions": sum(1 for c in conflicts if c.collision),
        "sumo_ssm": {"file": path.name, "measures": list(MEASURES),
                     "thresholds": dict(THRESHOLDS), "range": RANGE},
    }


def _worse(measure: str, a: float, b: float) -> bool:
    """Whether value ``a`` of ``measure`` is more critical than ``b`` (DRAC: higher)."""
    return a > b if measure == "DRAC" else a < b


def _past(measure: str, value: float) -> bool:
    return _worse(measure, value, THRESHOLDS[measure])


def _conflicts(path: Path) -> list[_Conflict]:
    """Each ``<conflict>`` of the file as the device logged it."""
    tags = {"minTTC": "TTC", "maxDRAC": "DRAC", "PET": "PET"}
    out = []
    for _, el in ET.iterparse(path):
        if el.tag != "conflict":
            continue
        values: dict[str, _Value] = {}
        collision = False
        for child in el:
            measure = tags.get(child.tag)
            if measure is None:
                continue
            kind = _number(child.get("type"))
            collision = collision or kind == COLLISION_TYPE
            value, t = _number(child.get("value")), _number(child.get("time"))
            if value is None or t is None:  # "NA": the measure was not defined
                continue
            pos = child.get("position", "NA")
            xy = tuple(float(p) for p in pos.split(",")[:2]) if pos != "NA" else None
            values[measure] = _Value(value, t, None if kind is None else int(kind),
                                     (xy[0], xy[1]) if xy and len(xy) == 2 else None)
        ego, foe = el.get("ego", ""), el.get("foe", "")
        out.append(_Conflict((min(ego, foe), max(ego, foe)), float(el.get("begin", "nan")),
                             float(el.get("end", "nan")), values, collision))
        el.clear()
    return out


def _number(text: str | None) -> float | None:
    if text is None or text == "NA":
        return None
    value = float(text)
    return value if math.isfinite(value) else None


def _merged(conflicts: list[_Conflict]) -> list[_Conflict]:
    """Conflicts of the same pair that overlap in time as one (each vehicle's device logs
    the encounter, from its own side)."""
    out: list[_Conflict] = []
    for c in sorted(conflicts, key=lambda c: (c.pair, c.begin)):
        if out and out[-1].pair == c.pair and c.begin <= out[-1].end:
            out[-1] = out[-1].merged(c)
        else:
            out.append(c)
    return out


def _extreme(conflicts: list[_Conflict], measure: str) -> dict[str, Any] | None:
    """The most critical value of ``measure`` over ``conflicts``, with when, who and where."""
    best: tuple[_Value, tuple[str, str]] | None = None
    for c in conflicts:
        v = c.values.get(measure)
        if v is None:
            continue
        if best is None or _worse(measure, v.value, best[0].value):
            best = (v, c.pair)
    if best is None:
        return None
    v, pair = best
    return {"value": v.value, "time": v.time, "pair": list(pair), "type": v.type,
            "position": None if v.position is None else list(v.position)}
