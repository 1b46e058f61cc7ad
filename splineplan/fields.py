"""Seeded obstacle fields of stopped vehicles on multi-lane roads, for the scenario bench.

Pure Python and numpy, no SUMO: a field is a list of stopped vehicles (edge, lane, position
along the lane), written by :func:`routes_xml` as a SUMO route file and by
:func:`scenario_dict` as a scenario mapping (:func:`splineplan.scenario.scenario_from_dict`).
The same road, tier and seed give the same field.

Difficulty tiers (:data:`TIERS`):

- ``empty``: no obstacle;
- ``sparse``, ``medium``, ``dense``: rows of stopped cars, vans and trucks at increasing
  density; each row blocks one lane or all lanes but one, and the rows stand far enough
  apart that a lane-based driver can change lanes between them;
- ``blocked``: rows that put a stopped vehicle in *every* lane at staggered stations: a car
  in one outer lane and narrow two-wheelers in the others. No lane is free, so a lane-based
  driver cannot pass; but the two-wheelers leave a gap between them, across a lane boundary,
  that a car fits through; consecutive rows put the gap on alternate sides, so the passage
  weaves.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any
from xml.sax.saxutils import quoteattr

import numpy as np

from splineplan.errors import ParameterError


@dataclass(frozen=True)
class VehicleType:
    """A SUMO vehicle type of the stopped vehicles: id, length and width [m], class."""

    id: str
    length: float
    width: float
    vclass: str


#: The stopped vehicles' types.
VEHICLE_TYPES: dict[str, VehicleType] = {
    "car": VehicleType("car", 4.5, 1.8, "passenger"),
    "van": VehicleType("van", 6.0, 2.1, "delivery"),
    "truck": VehicleType("truck", 10.0, 2.5, "truck"),
    "scooter": VehicleType("scooter", 1.8, 0.6, "moped"),
}


@dataclass(frozen=True)
class Tier:
    """A difficulty tier.

    Attributes
    ----------
    name
        Tier name.
    density
        Stopped vehicles per 100 m of road (all lanes together) [1/(100 m)].
    blocked
        Whether rows block every lane (see the module's docstring).
    """

    name: str
    density: float
    blocked: bool = False


#: Tiers in order of difficulty.
TIERS: dict[str, Tier] = {
    "empty": Tier("empty", 0.0),
    "sparse": Tier("sparse", 1.5),
    "medium": Tier("medium", 3.0),
    "dense": Tier("dense", 4.5),
    "blocked": Tier("blocked", 4.5, blocked=True),
}


@dataclass(frozen=True)
class RoadSpec:
    """A multi-lane road on a bundled SUMO network, the stretch a field is put on.

    Attributes
    ----------
    name
        Short name (``straight``, ``curved``).
    network
        Path of the ``.net.xml`` file (written into the scenario as given).
    edges
        The road's edges in driving order; every edge has ``lanes`` lanes.
    edge_lengths
        Length [m] of each edge's lanes.
    lanes
        Lanes per edge.
    start_pos
        The ego's start on the first edge [m] (front bumper).
    field_start, field_end
        Obstacles stand between these distances [m] along the road from its start.
    """

    name: str
    network: str
    edges: tuple[str, ...]
    edge_lengths: tuple[float, ...]
    lanes: int
    start_pos: float = 20.0
    field_start: float = 60.0
    field_end: float = 0.0

    def __post_init__(self) -> None:
        if not self.edges or len(self.edges) != len(self.edge_lengths):
            raise ParameterError("RoadSpec needs one length per edge")
        if self.lanes < 2:
            raise ParameterError(f"RoadSpec.lanes must be >= 2, got {self.lanes}")
        end = self.field_end or (self.length - 40.0)
        if not (self.start_pos < self.field_start < end <= self.length):
            raise ParameterError(f"RoadSpec {self.name}: need start_pos < field_start < "
                                 f"field_end <= length ({self.length:.1f} m)")
        object.__setattr__(self, "field_end", float(end))

    @property
    def length(self) -> float:
        """Length [m] of the road."""
        return float(sum(self.edge_lengths))

    def locate(self, s: float) -> tuple[str, float]:
        """Edge id and position [m] on it of distance ``s`` [m] from the road's start."""
        for edge, ln in zip(self.edges, self.edge_lengths, strict=True):
            if s <= ln:
                return edge, float(s)
            s -= ln
        return self.edges[-1], float(self.edge_lengths[-1])


@dataclass(frozen=True)
class StoppedVehicle:
    """A vehicle that stands still for the whole run.

    Attributes
    ----------
    id
        SUMO vehicle id.
    vtype
        Key of :data:`VEHICLE_TYPES`.
    edge, lane
        Where it stands (lane index, 0 = rightmost).
    pos
        Position [m] of its front bumper along the lane.
    station
        The same position as distance [m] from the road's start.
    """

    id: str
    vtype: str
    edge: str
    lane: int
    pos: float
    station: float


@dataclass(frozen=True)
class Field:
    """A generated obstacle field: the road, its tier, the seed and the stopped vehicles."""

    road: RoadSpec
    tier: Tier
    seed: int
    vehicles: tuple[StoppedVehicle, ...]

    @property
    def name(self) -> str:
        """``<road>_<tier>_s<seed>``."""
        return f"{self.road.name}_{self.tier.name}_s{self.seed}"

    @property
    def density(self) -> float:
        """Stopped vehicles per 100 m of the field's stretch [1/(100 m)]."""
        span = self.road.field_end - self.road.field_start
        return 100.0 * len(self.vehicles) / span if span > 0 else 0.0


#: Spacing [m] between rows of the non-blocking tiers: room for a lane change between them.
_MIN_ROW_GAP = 25.0
#: Spacing [m] between the rows of the blocked tier.
_BLOCKED_ROW_GAP = 45.0
#: Station offset [m] between neighbouring vehicles of a blocking row.
_STAGGER = 3.0
#: Distance [m] kept between a stopped vehicle and an edge's ends (junctions).
_EDGE_CLEARANCE = 12.0


def generate_field(road: RoadSpec, tier: str | Tier, *, seed: int) -> Field:
    """A field of stopped vehicles on ``road`` of difficulty ``tier``, from ``seed``.

    Raises
    ------
    ParameterError
        Unknown tier, or a road too short for its rows.
    """
    t = _tier(tier)
    rng = np.random.default_rng([int(seed), _stable_hash(road.name), _stable_hash(t.name)])
    if t.density <= 0:
        rows: list[list[tuple[float, int, str]]] = []
    elif t.blocked:
        rows = _blocked_rows(road, rng)
    else:
        rows = _open_rows(road, t.density, rng)
    vehicles: list[StoppedVehicle] = []
    for row in rows:
        for s, lane, vtype in row:
            edge, pos = road.locate(s)
            vehicles.append(StoppedVehicle(f"obst{len(vehicles)}", vtype, edge, lane,
                                           round(pos, 2), round(s, 2)))
    return Field(road, t, int(seed), tuple(vehicles))


def _tier(tier: str | Tier) -> Tier:
    if isinstance(tier, Tier):
        return tier
    if tier not in TIERS:
        raise ParameterError(f"unknown tier {tier!r}; known: {', '.join(TIERS)}")
    return TIERS[tier]


def _stable_hash(text: str) -> int:
    """A hash of ``text`` that does not change between processes (unlike ``hash``)."""
    return int.from_bytes(text.encode()[:8].ljust(8, b"\0"), "little") % (2**32)


def _stations(road: RoadSpec, n_rows: int, gap: float, rng: np.random.Generator) -> list[float]:
    """``n_rows`` row stations [m] at least ``gap`` apart, away from the edges' ends."""
    span = road.field_end - road.field_start
    if n_rows * gap > span + 1e-9:
        raise ParameterError(f"{n_rows} rows {gap} m apart do not fit on {span:.0f} m of "
                             f"road {road.name}")
    slack = span - n_rows * gap
    # sorted uniform slack split: rows keep >= gap between them
    cuts = np.sort(rng.uniform(0.0, slack, n_rows))
    out = []
    for i, c in enumerate(cuts):
        s = road.field_start + gap / 2.0 + i * gap + float(c)
        out.append(_off_junction(road, s))
    return out


def _off_junction(road: RoadSpec, s: float) -> float:
    """``s`` [m] moved off the ends of its edge, so a stopped vehicle stands on one edge."""
    start = 0.0
    for ln in road.edge_lengths:
        if s <= start + ln:
            lo, hi = start + _EDGE_CLEARANCE, start + ln - 2.0
            return float(min(max(s, lo), hi))
        start += ln
    return s


def _open_rows(road: RoadSpec, density: float,
               rng: np.random.Generator) -> list[list[tuple[float, int, str]]]:
    span = road.field_end - road.field_start
    n_vehicles = max(round(density * span / 100.0), 1)
    per_row_max = road.lanes - 1
    n_rows = int(np.ceil(n_vehicles / (1.0 + 0.5 * (per_row_max - 1))))
    n_rows = min(max(n_rows, 1), int(span // _MIN_ROW_GAP))
    counts = np.ones(n_rows, dtype=int)
    extra = min(n_vehicles - n_rows, n_rows * (per_row_max - 1))
    if extra > 0:
        add = rng.choice(n_rows * (per_row_max - 1), size=extra, replace=False) % n_rows
        np.add.at(counts, add, 1)
    rows = []
    kinds = ("car", "car", "car", "van", "truck")
    for s, c in zip(_stations(road, n_rows, _MIN_ROW_GAP, rng), counts, strict=True):
        lanes = rng.choice(road.lanes, size=int(min(c, per_row_max)), replace=False)
        rows.append([(s + float(rng.uniform(-1.0, 1.0)), int(lane),
                      str(kinds[int(rng.integers(len(kinds)))])) for lane in sorted(lanes)])
    return rows


def _blocked_rows(road: RoadSpec, rng: np.random.Generator) -> list[list[tuple[float, int, str]]]:
    span = road.field_end - road.field_start
    n_rows = max(min(int(span // _BLOCKED_ROW_GAP), 4), 1)
    rows = []
    side = int(rng.integers(2))
    for s in _stations(road, n_rows, _BLOCKED_ROW_GAP, rng):
        # the car stands in an outer lane; the gap between two-wheelers is on the other side
        car_lane = 0 if side == 0 else road.lanes - 1
        order = range(road.lanes) if side == 0 else range(road.lanes - 1, -1, -1)
        row = []
        for k, lane in enumerate(order):
            row.append((s + k * _STAGGER, lane, "car" if lane == car_lane else "scooter"))
        rows.append(row)
        side = 1 - side
    return rows


def routes_xml(field: Field, *, types: Mapping[str, VehicleType] = VEHICLE_TYPES) -> str:
    """A SUMO route file that puts the field's vehicles on their lanes, stopped for good."""
    lines = ['<?xml version="1.0" encoding="UTF-8"?>',
             f"<!-- {field.name}: {len(field.vehicles)} stopped vehicles, tier "
             f"{field.tier.name}, seed {field.seed} (generated by splineplan.fields) -->",
             "<routes>"]
    used = sorted({v.vtype for v in field.vehicles})
    for key in used:
        t = types[key]
        lines.append(f'    <vType id="{t.id}" length="{t.length:g}" width="{t.width:g}" '
                     f'vClass="{t.vclass}"/>')
    for v in field.vehicles:
        route = " ".join(field.road.edges[field.road.edges.index(v.edge):])
        lines.append(
            f'    <vehicle id="{v.id}" type="{types[v.vtype].id}" depart="0" '
            f'departPos="{v.pos:.2f}" departLane="{v.lane}" departSpeed="0">\n'
            f"        <route edges={quoteattr(route)}/>\n"
            f'        <stop lane="{v.edge}_{v.lane}" endPos="{v.pos:.2f}" '
            f'duration="100000"/>\n'
            "    </vehicle>")
    lines.append("</routes>")
    return "\n".join(lines) + "\n"


def scenario_dict(
    field: Field,
    *,
    network: str,
    routes: Sequence[str],
    duration: float = 90.0,
    safety_margin: float = 0.25,
) -> dict[str, Any]:
    """The scenario mapping of a field (:func:`splineplan.scenario.scenario_from_dict`).

    ``network`` and ``routes`` are written as given (relative to the scenario file's
    folder). The ego starts on the rightmost lane at the road's start and is to reach the
    road's end.
    """
    road = field.road
    return {
        "name": field.name,
        "description": (f"{road.name} road, tier {field.tier.name}: "
                        f"{len(field.vehicles)} stopped vehicles (seed {field.seed})"),
        "network": network,
        "routes": list(routes),
        "ego": {"start_edge": road.edges[0], "start_pos": road.start_pos, "start_lane": 0,
                "goal_edge": road.edges[-1]},
        "sim": {"duration": float(duration), "seed": int(field.seed), "lookahead": 100.0},
        "roadmap": {"d": 2.0, "wmax": 3.5, "safety_margin": float(safety_margin)},
    }


def toml_text(data: Mapping[str, Any]) -> str:
    """A TOML text of a scenario mapping (strings, numbers, lists of strings, one level of
    tables): enough for :func:`scenario_dict`'s output."""
    head, tables = [], []
    for key, value in data.items():
        if isinstance(value, Mapping):
            body = [f"{k} = {_toml_value(v)}" for k, v in value.items()]
            tables.append("\n".join([f"[{key}]", *body]))
        else:
            head.append(f"{key} = {_toml_value(value)}")
    return "\n\n".join(["\n".join(head), *tables]) + "\n"


def _toml_value(value: Any) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int | float):
        return repr(float(value)) if isinstance(value, float) else str(value)
    if isinstance(value, str):
        return '"' + value.replace("\\", "\\\\").replace('"', '\\"') + '"'
    if isinstance(value, list | tuple):
        return "[" + ", ".join(_toml_value(v) for v in value) + "]"
    raise ParameterError(f"cannot write {value!r} as TOML")
