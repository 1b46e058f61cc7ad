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

    def __post_init__(self) -> None:
        if self.trajectory is None:
            from splineplan.trajectory import TrajectoryParams

            object.__setattr__(self, "trajectory", TrajectoryParams())

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
    ego_raw = _section(data, "ego", where)
    ego = _build(EgoSpec, ego_raw, where, "ego")
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
                    path=path)


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

