"""Plans on disk: a small run-folder format, so that figures can be redrawn from files.

A *plan folder* holds

``plan.json``
    ``{"format": "splineplan.plan", "version": 1, ...}`` with

    - ``corridor``: ``reference`` ``(n, 2)``, ``s``, ``left``, ``right`` ``(n,)`` [m],
      ``edges``, ``edge_starts``, ``edge_ends``, ``offset`` (the fields of
      :class:`~splineplan.corridor.Corridor`);
    - ``obstacles``: ``ids`` and ``polygons``, a list of ``(k, 2)`` vertex lists [m];
    - ``roadmaps``: one object per road segment with the fields of
      :class:`~splineplan.roadmap.Roadmap` (arrays as nested lists, ``params`` as an object);
    - ``trajectory``: ``file`` (the CSV's name), ``control_points`` ``(k, 2)`` [m] and the
      trajectory's scalar results (``min_clearance``, ``feasible``, ...);
    - ``trajectory_params``: the level-3 parameters as an object (for the speed limits);
    - ``meta``: anything else worth keeping (the map image and its scale, the seed, ...).

``trajectory.csv``
    One row per sample, header ``t,x,y,heading,speed,curvature,s``: time [s], position [m],
    heading [rad, counter-clockwise from east], speed [m/s], curvature [1/m] and station
    along the curve [m]. Readers need only the first five columns (a simulation run's
    ``trajectory.csv`` has more columns and no curvature).

Everything here is plain JSON and CSV; nothing depends on SUMO.
"""

from __future__ import annotations

import csv
import dataclasses
import json
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from os import PathLike
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from splineplan.corridor import Corridor
from splineplan.errors import ScenarioError, SplineplanError
from splineplan.geometry import FloatArray
from splineplan.obstacles import Obstacles
from splineplan.roadmap import Roadmap, RoadmapParams

PLAN_FILE = "plan.json"
TRAJECTORY_FILE = "trajectory.csv"
FORMAT = "splineplan.plan"
VERSION = 1
#: Columns of the trajectory CSV, in order; the first six are required when reading.
TRAJECTORY_COLUMNS = ("t", "x", "y", "heading", "speed", "curvature", "s")

_INT_FIELDS = {"graph_line", "arcs", "path"}


@dataclass(frozen=True, eq=False)
class TrajectorySamples:
    """A trajectory as read back from files: samples and a few results.

    Attributes
    ----------
    t, x, y, heading, speed, curvature, s
        Samples ``(n,)``: time [s], position [m], heading [rad], speed [m/s],
        curvature [1/m], station along the curve [m].
    control_points
        The spline's control points ``(k, 2)`` [m] (empty when unknown).
    info
        Scalar results saved with the trajectory (``min_clearance`` [m], ``feasible``, ...).
    """

    t: FloatArray
    x: FloatArray
    y: FloatArray
    heading: FloatArray
    speed: FloatArray
    curvature: FloatArray
    s: FloatArray
    control_points: FloatArray = field(default_factory=lambda: np.zeros((0, 2)))
    info: Mapping[str, Any] = field(default_factory=dict)

    @property
    def xy(self) -> FloatArray:
        """Positions ``(n, 2)`` [m]."""
        return np.column_stack((self.x, self.y))

    def __getattr__(self, name: str) -> Any:
        info = self.__dict__.get("info", {})
        if name in info:
            return info[name]
        raise AttributeError(name)


@dataclass(frozen=True, eq=False)
class SavedPlan:
    """Everything a plan folder holds (see the module's docstring)."""

    corridor: Corridor
    obstacles: Obstacles
    roadmaps: tuple[Roadmap, ...]
    trajectory: TrajectorySamples | None
    trajectory_params: Mapping[str, Any]
    meta: Mapping[str, Any]
    directory: Path


# -- writing -------------------------------------------------------------------------------
def save_plan(
    directory: str | PathLike[str],
    *,
    corridor: Corridor,
    obstacles: Obstacles,
    roadmaps: Sequence[Roadmap] = (),
    trajectory: Any = None,
    trajectory_params: Any = None,
    meta: Mapping[str, Any] | None = None,
) -> Path:
    """Write a plan folder (created if needed); returns the path of ``plan.json``.

    ``trajectory`` is any object with the sample arrays ``t, x, y, heading, speed,
    curvature`` (and optionally ``s`` and ``control_points``); its scalar attributes are
    kept as results. ``trajectory_params`` is a dataclass or a mapping.
    """
    out = Path(directory)
    out.mkdir(parents=True, exist_ok=True)
    doc: dict[str, Any] = {
        "format": FORMAT,
        "version": VERSION,
        "corridor": corridor_to_dict(corridor),
        "obstacles": obstacles_to_dict(obstacles),
        "roadmaps": [roadmap_to_dict(r) for r in roadmaps],
        "meta": _plain(dict(meta or {})),
    }
    if trajectory is not None:
        write_trajectory_csv(out / TRAJECTORY_FILE, trajectory)
        cp = getattr(trajectory, "control_points", None)
        doc["trajectory"] = {
            "file": TRAJECTORY_FILE,
            "control_points": _plain(np.zeros((0, 2)) if cp is None else np.asarray(cp)),
            **_scalars(trajectory),
        }
    if trajectory_params is not None:
        doc["trajectory_params"] = _plain(trajectory_params)
    path = out / PLAN_FILE
    path.write_text(json.dumps(doc, indent=1, allow_nan=False))
    return path


def write_trajectory_csv(path: str | PathLike[str], trajectory: Any) -> Path:
    """Write a trajectory's samples as CSV (``TRAJECTORY_COLUMNS``); returns the path.

    ``s`` is written when the trajectory has it, else the arc length of ``x, y``.
    """
    cols = [np.asarray(getattr(trajectory, c), dtype=float) for c in TRAJECTORY_COLUMNS[:6]]
    s = getattr(trajectory, "s", None)
    cols.append(_arc_length(cols[1], cols[2]) if s is None else np.asarray(s, dtype=float))
    n = len(cols[0])
    if any(len(c) != n for c in cols):
        raise ScenarioError("trajectory arrays differ in length")
    p = Path(path)
    with p.open("w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(TRAJECTORY_COLUMNS)
        w.writerows(np.column_stack(cols).tolist())
    return p


def corridor_to_dict(corridor: Corridor) -> dict[str, Any]:
    """A corridor's fields as JSON-ready lists."""
    return {
        "reference": _plain(corridor.reference),
        "s": _plain(corridor.s),
        "left": _plain(corridor.left),
        "right": _plain(corridor.right),
        "edges": list(corridor.edges),
        "edge_starts": _plain(corridor.edge_starts),
        "edge_ends": _plain(corridor.edge_ends),
        "offset": float(corridor.offset),
    }


def obstacles_to_dict(obstacles: Obstacles) -> dict[str, Any]:
    """Obstacles as ids and vertex lists."""
    return {"ids": list(obstacles.ids), "polygons": [_plain(p) for p in obstacles.polygons()]}


def roadmap_to_dict(roadmap: Roadmap) -> dict[str, Any]:
    """A roadmap's fields as JSON-ready values."""
    out: dict[str, Any] = {}
    for f in dataclasses.fields(roadmap):
        value = getattr(roadmap, f.name)
        out[f.name] = (dataclasses.asdict(value) if f.name == "params" else _plain(value))
    return out


# -- reading -------------------------------------------------------------------------------
def load_plan(directory: str | PathLike[str]) -> SavedPlan:
    """Read a plan folder written by :func:`save_plan`.

    Raises ScenarioError when ``plan.json`` is missing or malformed.
    """
    d = Path(directory)
    path = d / PLAN_FILE
    try:
        doc = json.loads(path.read_text())
    except FileNotFoundError as err:
        raise ScenarioError(f"{d} holds no {PLAN_FILE}") from err
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as err:
        raise ScenarioError(f"{path} is not readable JSON: {err}") from err
    if not isinstance(doc, dict) or doc.get("format") != FORMAT:
        raise ScenarioError(f"{path} is not a splineplan plan (format {FORMAT!r})")
    if doc.get("version") != VERSION:
        raise ScenarioError(f"{path} has version {doc.get('version')!r}; this reads {VERSION}")
    try:
        corridor = corridor_from_dict(doc["corridor"])
        obstacles = obstacles_from_dict(doc["obstacles"])
        roadmaps = tuple(roadmap_from_dict(r) for r in doc.get("roadmaps", []))
        traj = None
        if "trajectory" in doc:
            t = doc["trajectory"]
            traj = read_trajectory_csv(d / t.get("file", TRAJECTORY_FILE))
            info = {k: v for k, v in t.items() if k not in ("file", "control_points")}
            cp = np.asarray(t.get("control_points", []), dtype=float).reshape(-1, 2)
            traj = dataclasses.replace(traj, control_points=cp, info=info)
    except (KeyError, TypeError, ValueError) as err:
        raise ScenarioError(f"{path} is malformed: {err!r}") from err
    except SplineplanError as err:
        if isinstance(err, ScenarioError):
            raise
        raise ScenarioError(f"{path} is malformed: {err}") from err
    return SavedPlan(corridor, obstacles, roadmaps, traj, dict(doc.get("trajectory_params", {})),
                     dict(doc.get("meta", {})), d)


def read_trajectory_csv(path: str | PathLike[str]) -> TrajectorySamples:
    """Read a trajectory CSV by its header (``t, x, y, heading, speed`` needed; other
    columns than :data:`TRAJECTORY_COLUMNS` are skipped).

    Without a ``curvature`` column (a simulation's driven path) the curvature is the
    heading's change per metre; without ``s``, the arc length of ``x, y``.
    """
    p = Path(path)
    try:
        with p.open(newline="") as fh:
            rows = list(csv.reader(fh))
    except FileNotFoundError as err:
        raise ScenarioError(f"trajectory file {p} not found") from err
    except (OSError, UnicodeDecodeError) as err:
        raise ScenarioError(f"trajectory file {p} is not readable: {err}") from err
    if not rows:
        raise ScenarioError(f"trajectory file {p} is empty")
    header = [h.strip() for h in rows[0]]
    missing = [c for c in TRAJECTORY_COLUMNS[:5] if c not in header]
    if missing:
        raise ScenarioError(f"trajectory file {p} lacks the columns {', '.join(missing)}")
    # only the columns read here need be numbers (a driven path has text columns too)
    use = [i for i, h in enumerate(header) if h in TRAJECTORY_COLUMNS]
    try:
        data = np.array([[float(r[i]) for i in use] for r in rows[1:] if r], dtype=float)
    except (ValueError, IndexError) as err:
        raise ScenarioError(f"trajectory file {p} has a non-numeric value or a short "
                            f"row: {err}") from err
    data = data.reshape(-1, len(use))
    col = {header[i]: data[:, k] for k, i in enumerate(use)}
    s = col["s"] if "s" in col else _arc_length(col["x"], col["y"])
    if "curvature" in col:
        kappa = col["curvature"]
    else:  # a driven path (simulation run): heading change per metre
        with np.errstate(divide="ignore", invalid="ignore"):
            kappa = np.nan_to_num(np.gradient(np.unwrap(col["heading"]), s), nan=0.0,
                                  posinf=0.0, neginf=0.0) if len(s) > 1 else np.zeros(len(s))
    return TrajectorySamples(col["t"], col["x"], col["y"], col["heading"], col["speed"],
                             kappa, s)


def corridor_from_dict(d: Mapping[str, Any]) -> Corridor:
    """Inverse of :func:`corridor_to_dict`."""
    return Corridor(
        np.asarray(d["reference"], dtype=float).reshape(-1, 2),
        np.asarray(d["s"], dtype=float),
        np.asarray(d["left"], dtype=float),
        np.asarray(d["right"], dtype=float),
        tuple(d.get("edges", ())),
        np.asarray(d.get("edge_starts", []), dtype=float).reshape(-1),
        float(d.get("offset", 0.0)),
        edge_ends=np.asarray(d.get("edge_ends", []), dtype=float).reshape(-1),
    )


def obstacles_from_dict(d: Mapping[str, Any]) -> Obstacles:
    """Inverse of :func:`obstacles_to_dict`."""
    polys = [np.asarray(p, dtype=float) for p in d["polygons"]]
    return Obstacles.from_polygons(polys, list(d["ids"]) if polys else None)


def roadmap_from_dict(d: Mapping[str, Any]) -> Roadmap:
    """Inverse of :func:`roadmap_to_dict`."""
    kw: dict[str, Any] = {}
    for f in dataclasses.fields(Roadmap):
        if f.name not in d and f.default_factory is not dataclasses.MISSING:
            continue  # written before the field existed: its default
        value = d[f.name]
        if f.name == "params":
            kw[f.name] = RoadmapParams(**value)
        elif f.name in _INT_FIELDS:
            arr = np.asarray(value, dtype=np.int64)
            kw[f.name] = arr.reshape(-1, 2) if f.name == "arcs" else arr
        elif isinstance(value, list):
            arr = np.asarray(value, dtype=float)
            kw[f.name] = arr.reshape(-1, 2) if f.name in ("xy", "graph_xy") else arr
        elif f.name == "bottleneck_index":
            kw[f.name] = int(value)
        else:
            kw[f.name] = float(value)
    return Roadmap(**kw)


# -- helpers -------------------------------------------------------------------------------
def _arc_length(x: ArrayLike, y: ArrayLike) -> FloatArray:
    seg = np.hypot(np.diff(np.asarray(x, dtype=float)), np.diff(np.asarray(y, dtype=float)))
    return np.concatenate(([0.0], np.cumsum(seg)))


def _scalars(obj: Any) -> dict[str, Any]:
    """A trajectory's scalar results, JSON-ready.

    The scalar (and nested dataclass, and tuple of dataclasses) fields of a dataclass, plus
    its ``min_clearance``, ``duration`` and ``length`` where it has them.
    """
    if not dataclasses.is_dataclass(obj):
        return dict(getattr(obj, "info", {}))
    out: dict[str, Any] = {}
    for f in dataclasses.fields(obj):
        v = getattr(obj, f.name)
        if dataclasses.is_dataclass(v) or (
            isinstance(v, bool | int | float | str | np.generic) and np.ndim(v) == 0
        ) or (isinstance(v, tuple) and all(dataclasses.is_dataclass(x) for x in v)):
            out[f.name] = _plain(v)
    for name in ("min_clearance", "duration", "length"):
        v = getattr(obj, name, None)
        if isinstance(v, int | float | np.generic):
            out[name] = _plain(v)
    return out


def _plain(value: Any) -> Any:
    """Numpy values and containers as JSON values; non-finite floats as "inf", "-inf", "nan".

    ``float()`` and ``np.asarray(..., dtype=float)`` read those strings back.
    """
    if isinstance(value, np.ndarray):
        return _plain(value.tolist())
    if isinstance(value, np.generic):
        return _plain(value.item())
    if isinstance(value, float):
        return value if math.isfinite(value) else str(value)
    if isinstance(value, Mapping):
        return {str(k): _plain(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_plain(v) for v in value]
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return _plain(dataclasses.asdict(value))
    return value
