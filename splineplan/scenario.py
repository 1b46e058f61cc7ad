"""Scenarios: one TOML file per closed-loop experiment, read into frozen dataclasses.

A scenario names a SUMO network, SUMO's own route and additional files for the other
traffic and the obstacles (stopped or parked vehicles), the ego vehicle, the planner's
parameters and the simulation's. Paths are relative to the scenario file. An unknown key,
a missing file or a bad value is a :class:`~splineplan.errors.ScenarioError` that names it.

Example::

    name = "one_obstacle"
    network = "../sumo_nets/straight.net.xml"
    routes = ["one_obstacle.rou.xml"]

    [ego]
    start_edge = "e0"
    start_pos = 20.0
    goal_edge = "e2"

    [sim]
    duration = 90.0
    seed = 1

    [roadmap]
    d = 1.0

    [trajectory]
    s_max = 13.0
"""

from __future__ import annotations

import dataclasses
import tomllib
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from splineplan.errors import (
    ParameterError,
    ScenarioError,
    SplineplanError,
    require_non_negative,
    require_positive,
)
from splineplan.roadmap import D_RANGE, RoadmapParams

#: Keys of the ``[roadmap]`` section that come from the ``[ego]`` section instead.
_EGO_DIMENSIONS = ("vehicle_length", "vehicle_width")


@dataclass(frozen=True)
class EgoSpec:
    """The ego vehicle of a scenario.

    Attributes
    ----------
    start_edge, goal_edge
        SUMO edge ids where the ego starts and where it is to arrive.
    start_pos
        Position [m] of the ego's front bumper along the start edge.
    start_lane
        Lane index on the start edge (0 = rightmost).
    goal_pos
        Position [m] along the goal edge that the front bumper is to reach; ``None``: the
        edge's end less ``goal_margin``.
    depart
        Simulation time [s] at which the ego enters.
    vclass
        SUMO vehicle class (lane permissions, routing).
    length, width
        Dimensions [m].
    max_speed
        Top speed [m/s]; the trajectory's ``s_max`` is capped at it.
    id
        SUMO vehicle id.
    """

    start_edge: str
    goal_edge: str
    start_pos: float = 10.0
    start_lane: int = 0
    goal_pos: float | None = None
    depart: float = 0.0
    vclass: str = "passenger"
    length: float = 4.5
    width: float = 1.8
    max_speed: float = 13.89
    id: str = "ego"

    def __post_init__(self) -> None:
        for name in ("start_edge", "goal_edge", "vclass", "id"):
            if not isinstance(getattr(self, name), str) or not getattr(self, name):
                raise ParameterError(f"ego.{name} must be a non-empty string, "
                                     f"got {getattr(self, name)!r}")
        from splineplan.network import check_vclass

        try:
            check_vclass(self.vclass)
        except SplineplanError as err:
            raise ParameterError(f"ego.vclass: {err}") from err
        for name in ("length", "width", "max_speed"):
            require_positive(f"ego.{name}", getattr(self, name))
        for name in ("start_pos", "depart"):
            require_non_negative(f"ego.{name}", getattr(self, name))
        if self.goal_pos is not None:
            require_non_negative("ego.goal_pos", self.goal_pos)
        if (isinstance(self.start_lane, bool) or not isinstance(self.start_lane, int)
                or self.start_lane < 0):
            raise ParameterError(f"ego.start_lane must be an integer >= 0, got {self.start_lane!r}")


@dataclass(frozen=True)
class SimParams:
    """Parameters of the closed loop.

    Attributes
    ----------
    duration
        Simulated time [s] after which a run that has not arrived stops.
    step_length
        SUMO's time step [s].
    seed
        SUMO's random seed (recorded in the outputs).
    lookahead
        How far ahead [m] along the route stopped vehicles count as obstacles, and the length
        of each planning window.
    replan_distance
        Replan when less than this [m] of the current trajectory is left ahead.
    deviation_tolerance
        Replan when SUMO places the ego farther than this [m] from the plan.
    time_gap
        Time gap [s] kept to a moving vehicle ahead in the ego's path.
    min_gap
        Distance [m] kept to a moving vehicle ahead when both stand.
    stopped_speed
        A vehicle slower than this [m/s] with a stop state counts as stopped.
    goal_margin
        Default goal: this far [m] before the goal edge's end.
    """

    duration: float = 120.0
    step_length: float = 0.1
    seed: int = 42
    lookahead: float = 100.0
    replan_distance: float = 40.0
    deviation_tolerance: float = 0.5
    time_gap: float = 1.5
    min_gap: float = 2.5
    stopped_speed: float = 0.1
    goal_margin: float = 1.0

    def __post_init__(self) -> None:
        for name in ("duration", "step_length", "lookahead", "replan_distance",
                     "deviation_tolerance", "time_gap", "min_gap", "stopped_speed"):
            require_positive(f"sim.{name}", getattr(self, name))
        require_non_negative("sim.goal_margin", self.goal_margin)
        if isinstance(self.seed, bool) or not isinstance(self.seed, int) or not (
                0 <= self.seed < 2**31):
            raise ParameterError(f"sim.seed must be an integer in 0..{2**31 - 1}, "
                                 f"got {self.seed!r}")
        if self.replan_distance >= self.lookahead:
            raise ParameterError("sim.replan_distance must be below sim.lookahead")


@dataclass(frozen=True)
class Scenario:
    """A closed-loop experiment.

    Attributes
    ----------
    name
        Short name (the file's stem unless given).
    network
        SUMO network file (``.net.xml`` or ``.net.xml.gz``).
    routes, additional
        SUMO route files (other traffic, stopped vehicles) and additional files (polygons,
        parking areas), in load order.
    ego
        The ego vehicle.
    sim
        Closed-loop parameters.
    roadmap
        Level-2 parameters; vehicle dimensions are the ego's.
    trajectory
        Level-3 parameters (:class:`splineplan.trajectory.TrajectoryParams`).
    description
        Free text.
    path
        The scenario file, if read from one.
    egos
        Every planned vehicle (one ``[[ego]]`` table each); the first is always ``ego``
        (replace ``ego`` to change it).
    sumo_config
        A SUMO configuration (``.sumocfg``) run as it is (with its own options), when the
        scenario came from one (:func:`sumo_scenario`).
    from_sumo
        Made by :func:`sumo_scenario`: no planned vehicle of its own (``ego`` is only a
        placeholder); they are chosen among SUMO's.
    sim_step_given
        The configuration sets SUMO's step length (else the run passes
        ``--step-length`` of ``sim``, 0.1 s: SUMO's default of 1 s is too coarse to plan).
    """

    name: str
    network: Path
    ego: EgoSpec
    routes: tuple[Path, ...] = ()
    additional: tuple[Path, ...] = ()
    sim: SimParams = field(default_factory=SimParams)
    roadmap: RoadmapParams = field(default_factory=RoadmapParams)
    trajectory: Any = None
    description: str = ""
    path: Path | None = None
    egos: tuple[EgoSpec, ...] = ()
    sumo_config: Path | None = None
    from_sumo: bool = False
    sim_step_given: bool = False

    def __post_init__(self) -> None:
        if self.trajectory is None:
            from splineplan.trajectory import TrajectoryParams

            object.__setattr__(self, "trajectory", TrajectoryParams())
        if self.from_sumo:
            object.__setattr__(self, "egos", ())
        elif not self.egos:
            object.__setattr__(self, "egos", (self.ego,))
        elif self.egos[0] != self.ego:  # ``ego`` is the first (dataclasses.replace(ego=...))
            object.__setattr__(self, "egos", (self.ego, *self.egos[1:]))
        ids = [e.id for e in self.egos]
        dup = sorted({i for i in ids if ids.count(i) > 1})
        if dup:
            raise ScenarioError(f"{self.name}: two planned vehicles with id {dup[0]!r}; give "
                                "each [[ego]] its own id")

    def for_vehicle(self, ego: EgoSpec) -> Scenario:
        """The scenario as one planned vehicle sees it: ``ego`` its own, the roadmap's
        footprint its dimensions, ``trajectory.s_max`` at most its top speed."""
        roadmap = dataclasses.replace(self.roadmap, vehicle_length=ego.length,
                                      vehicle_width=ego.width)
        traj = self.trajectory
        if hasattr(traj, "s_max") and traj.s_max > ego.max_speed:
            traj = dataclasses.replace(traj, s_max=ego.max_speed)
        return dataclasses.replace(self, ego=ego, egos=(ego,), roadmap=roadmap,
                                   trajectory=traj, from_sumo=False)

    def with_seed(self, seed: int) -> Scenario:
        """The same scenario with another SUMO seed."""
        return dataclasses.replace(self, sim=dataclasses.replace(self.sim, seed=int(seed)))


_TOP_KEYS = {"name", "description", "network", "routes", "additional",
             "ego", "sim", "roadmap", "trajectory"}


def load_scenario(path: str | Path) -> Scenario:
    """Read a scenario file.

    Raises
    ------
    ScenarioError
        The file or a file it names is missing, the TOML is malformed, a key is unknown or
        a value is out of range.
    """
    path = Path(path)
    if not path.is_file():
        raise ScenarioError(f"scenario file not found: {path}")
    try:
        with path.open("rb") as fh:
            data = tomllib.load(fh)
    except tomllib.TOMLDecodeError as err:
        raise ScenarioError(f"{path}: not valid TOML: {err}") from err
    return scenario_from_dict(data, base=path.parent, path=path)


def scenario_from_dict(
    data: Mapping[str, Any], *, base: str | Path = ".", path: Path | None = None
) -> Scenario:
    """A scenario from the parsed TOML mapping; relative paths are taken from ``base``."""
    where = str(path) if path is not None else "scenario"
    base = Path(base)
    _check_keys(data, _TOP_KEYS, where, "")
    for key in ("network", "ego"):
        if key not in data:
            raise ScenarioError(f"{where}: missing key {key!r}")
    network = _existing(base, data["network"], where, "network")
    routes = tuple(_existing(base, p, where, "routes") for p in _str_list(data, "routes", where))
    additional = tuple(_existing(base, p, where, "additional")
                       for p in _str_list(data, "additional", where))
    raw_egos = data["ego"]
    if isinstance(raw_egos, list):  # [[ego]] tables
        if not raw_egos or not all(isinstance(e, Mapping) for e in raw_egos):
            raise ScenarioError(f"{where}: [[ego]] must be one or more tables")
        egos = tuple(
            _build(EgoSpec, {"id": "ego" if i == 0 else f"ego{i + 1}", **e}, where,
                   "ego" if i == 0 else f"ego {i + 1}")
            for i, e in enumerate(raw_egos))
    else:
        egos = (_build(EgoSpec, _section(data, "ego", where), where, "ego"),)
    ego = egos[0]
    sim = _build(SimParams, _section(data, "sim", where), where, "sim")
    roadmap_raw = dict(_section(data, "roadmap", where))
    for key in _EGO_DIMENSIONS:
        if key in roadmap_raw:
            raise ScenarioError(f"{where}: roadmap.{key} comes from [ego] (length, width); "
                                "remove it from [roadmap]")
    roadmap_raw["vehicle_length"] = ego.length
    roadmap_raw["vehicle_width"] = ego.width
    roadmap = _build(RoadmapParams, roadmap_raw, where, "roadmap")
    if "d" in roadmap_raw and not D_RANGE[0] <= roadmap.d <= D_RANGE[1]:
        raise ScenarioError(f"{where}: [roadmap] d, the sweep-line spacing, must be between "
                            f"{D_RANGE[0]:g} and {D_RANGE[1]:g} m, got {roadmap.d:g}")

    from splineplan.trajectory import TrajectoryParams

    traj_raw = dict(_section(data, "trajectory", where))
    names = {f.name for f in dataclasses.fields(TrajectoryParams)}
    if "s_max" in names and "s_max" not in traj_raw:
        traj_raw["s_max"] = ego.max_speed
    trajectory = _build(TrajectoryParams, traj_raw, where, "trajectory")
    if "s_max" in names and trajectory.s_max > ego.max_speed + 1e-9:
        raise ScenarioError(f"{where}: trajectory.s_max ({trajectory.s_max}) exceeds "
                            f"ego.max_speed ({ego.max_speed})")
    name = data.get("name", path.stem if path is not None else "scenario")
    if not isinstance(name, str):
        raise ScenarioError(f"{where}: name must be a string")
    description = data.get("description", "")
    if not isinstance(description, str):
        raise ScenarioError(f"{where}: description must be a string")
    return Scenario(name=name, network=network, ego=ego, routes=routes, additional=additional,
                    sim=sim, roadmap=roadmap, trajectory=trajectory, description=description,
                    path=path, egos=egos)


def _check_keys(data: Mapping[str, Any], allowed: set[str], where: str, section: str) -> None:
    unknown = sorted(set(data) - allowed)
    if unknown:
        prefix = f"[{section}] " if section else ""
        raise ScenarioError(f"{where}: unknown key {prefix}{unknown[0]!r}; allowed: "
                            f"{', '.join(sorted(allowed))}")


def _section(data: Mapping[str, Any], key: str, where: str) -> Mapping[str, Any]:
    value = data.get(key, {})
    if not isinstance(value, Mapping):
        raise ScenarioError(f"{where}: [{key}] must be a table")
    return value


def _str_list(data: Mapping[str, Any], key: str, where: str) -> list[str]:
    value = data.get(key, [])
    if isinstance(value, str):
        value = [value]
    if not isinstance(value, list) or not all(isinstance(v, str) for v in value):
        raise ScenarioError(f"{where}: {key} must be a list of file names")
    return value


def _existing(base: Path, name: Any, where: str, key: str) -> Path:
    if not isinstance(name, str) or not name:
        raise ScenarioError(f"{where}: {key} must be a file name")
    p = Path(name)
    full = p if p.is_absolute() else (base / p)
    if not full.is_file():
        raise ScenarioError(f"{where}: {key} file not found: {full}")
    return full.resolve()


def _build(cls: Any, raw: Mapping[str, Any], where: str, section: str) -> Any:
    allowed = {f.name for f in dataclasses.fields(cls) if f.init and not f.name.startswith("_")}
    _check_keys(raw, allowed, where, section)
    kwargs = {}
    for f in dataclasses.fields(cls):
        if f.name in raw:
            value = raw[f.name]
            if isinstance(value, int) and not isinstance(value, bool) and _is_float(f.type):
                value = float(value)
            kwargs[f.name] = value
    try:
        return cls(**kwargs)
    except (SplineplanError, TypeError, ValueError) as err:
        raise ScenarioError(f"{where}: [{section}] {err}") from err


def _is_float(annotation: Any) -> bool:
    text = annotation if isinstance(annotation, str) else getattr(annotation, "__name__", "")
    return "float" in str(text)



def sumo_scenario(
    config: str | Path | None = None,
    *,
    net: str | Path | None = None,
    routes: tuple[str | Path, ...] = (),
    additional: tuple[str | Path, ...] = (),
    duration: float | None = None,
    name: str | None = None,
) -> Scenario:
    """A SUMO scenario as it is: a ``.sumocfg`` (run with its own options) or a network with
    route and additional files.

    The planned vehicles are chosen among SUMO's own when the run starts
    (:class:`~splineplan.closedloop.select.Selection`); their start, route and goal are
    SUMO's. The planner's parameters are the defaults of the bundled scenarios; the
    duration [s] is ``duration``, else the configuration's ``end - begin``, else an hour.

    Raises
    ------
    ScenarioError
        A file is missing or not readable XML, or the configuration names no network.
    """
    import xml.etree.ElementTree as ET

    cfg_path: Path | None = None
    step = 0.1
    step_given = False
    if config is not None:
        cfg_path = Path(config)
        if not cfg_path.is_file():
            raise ScenarioError(f"SUMO configuration not found: {cfg_path}")
        try:
            root = ET.parse(cfg_path).getroot()
        except ET.ParseError as err:
            raise ScenarioError(f"{cfg_path}: not readable XML: {err}") from err
        values = {el.tag: el.get("value", "") for el in root.iter() if el.get("value")}
        base = cfg_path.parent
        if net is None and "net-file" in values:
            net = base / values["net-file"]
        routes = (*routes, *(base / p.strip() for p in values.get("route-files", "").split(",")
                             if p.strip()))
        additional = (*additional, *(base / p.strip() for p in
                                     values.get("additional-files", "").split(",")
                                     if p.strip()))
        if duration is None and "end" in values:
            try:
                duration = float(values["end"]) - float(values.get("begin", 0.0))
            except ValueError as err:
                raise ScenarioError(f"{cfg_path}: end {values['end']!r} is not a number"
                                    ) from err
        if "step-length" in values:
            step = float(values["step-length"])
            step_given = True
    if net is None:
        raise ScenarioError("a SUMO scenario needs a network: a .sumocfg with a net-file, "
                            "or --net")
    where = str(cfg_path) if cfg_path is not None else "SUMO scenario"
    network = _existing(Path("."), str(net), where, "net-file")
    rou = tuple(_existing(Path("."), str(p), where, "route-files") for p in routes)
    add = tuple(_existing(Path("."), str(p), where, "additional-files") for p in additional)
    sim = SimParams(duration=float(duration) if duration else 3600.0, step_length=step,
                    lookahead=100.0)
    template = EgoSpec(start_edge="-", goal_edge="-", id="planned")
    stem = cfg_path.name.split(".")[0] if cfg_path is not None else Path(network).name.split(".")[0]
    return Scenario(name=name or stem, network=network, ego=template, routes=rou,
                    additional=add, sim=sim,
                    roadmap=RoadmapParams(vehicle_length=template.length,
                                          vehicle_width=template.width),
                    description="SUMO's own scenario, a chosen share of its vehicles planned",
                    path=cfg_path, sumo_config=cfg_path, from_sumo=True,
                    sim_step_given=step_given)
