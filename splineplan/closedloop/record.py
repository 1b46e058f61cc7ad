"""The closed loop's record: one writer for a run folder's tables and JSON.

Per planned vehicle: its driven path (``trajectory.csv``, columns as arrays) and its
``metrics.json``; the :class:`SimResult` of a run.
"""

from __future__ import annotations

import csv
import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from splineplan.closedloop.replan import Replan
from splineplan.metrics import CURVATURE_SPAN, dynamics, finite_or_none, summary_stats
from splineplan.traffic import OFF_ROAD_TOLERANCE

#: Columns of ``trajectory.csv``, in a row's order: ``lane`` is SUMO's lane under the
#: vehicle, ``why_slow`` what held its speed back in words (empty where nothing did).
COLUMNS = ("t", "x", "y", "heading", "speed", "station", "lateral", "lane", "sumo_x",
           "sumo_y", "position_error", "clearance_obstacles", "clearance_vehicles",
           "off_road", "speed_limited", "why_slow")
#: The columns of text.
TEXT_COLUMNS = ("lane", "why_slow")


@dataclass(frozen=True, eq=False)
class SimResult:
    """Outcome of :func:`simulate`.

    Attributes
    ----------
    status
        ``arrived``, ``timeout`` (duration reached), ``failed`` or ``interrupted``
        (Ctrl-C).
    reason
        Why the run stopped, in words.
    out_dir
        Where the outputs are.
    metrics
        What ``metrics.json`` holds.
    replans
        Every planning call.
    route
        The route's edges from the ego's start (after a re-route: the edges driven before
        it, then the new route).
    driven
        Columns of ``trajectory.csv``, as arrays.
    plans
        ``(time, roadmaps, trajectory, corridor window)`` of each successful plan (for plots).
    vehicles
        With several planned vehicles: each one's result by id (the run's own ``metrics``
        are then ``summary.json``'s, ``driven`` and ``route`` empty).
    """

    status: str
    reason: str
    out_dir: Path
    metrics: dict[str, Any]
    replans: tuple[Replan, ...]
    route: tuple[str, ...]
    driven: dict[str, np.ndarray]
    plans: tuple[Any, ...] = field(default=(), repr=False)
    vehicles: dict[str, SimResult] = field(default_factory=dict, repr=False)

    @property
    def arrived(self) -> bool:
        """Whether the ego (every planned vehicle) reached its goal."""
        return self.status == "arrived"



@dataclass(frozen=True)
class RunTotals:
    """What the run as a whole contributes to each vehicle's metrics.

    ``time`` [s] the simulation time reached; ``sumo_collisions`` SUMO's collision reports;
    ``teleports`` SUMO's teleports of any vehicle; wall times [s]: the run's, inside SUMO,
    and in the planner (of the vehicles the metrics are for).
    """

    time: float
    sumo_collisions: list[dict[str, Any]]
    teleports: int
    wall_time: float
    sumo_seconds: float
    plan_seconds: float


def driven_columns(rows: list[tuple[Any, ...]]) -> dict[str, np.ndarray]:
    """The rows of a driver's record as named columns, with the dynamics derived."""
    cols: dict[str, np.ndarray] = {}
    for i, name in enumerate(COLUMNS):
        vals = [r[i] for r in rows]
        cols[name] = np.array(vals, dtype=object if name in TEXT_COLUMNS else float)
    dyn = dynamics(cols["t"], cols["x"], cols["y"], cols["speed"])
    cols.update(dyn)
    return cols


def vehicle_metrics(driver: Any, d: dict[str, np.ndarray], totals: RunTotals
                    ) -> dict[str, Any]:
    """``metrics.json`` of one planned vehicle (a :class:`~.driver.Driver`)."""
    sc = driver.sc
    t = d["t"]
    xy = np.column_stack((d["x"], d["y"])) if len(t) else np.zeros((0, 2))
    dist = float(np.hypot(*np.diff(xy, axis=0).T).sum()) if len(t) > 1 else 0.0
    ego_coll = [c for c in totals.sumo_collisions
                if driver.ego in (c["collider"], c["victim"])]
    plan_times = [r.planning_time for r in driver.replans]
    off = d["off_road"].astype(bool) if len(t) else np.zeros(0, dtype=bool)
    travel = (t[-1] - driver.depart_time) if (len(t) and driver.depart_time is not None) else None
    return {
        "scenario": sc.name,
        "scenario_file": str(sc.path) if sc.path else None,
        "driver": driver.kind,
        "status": driver.status,
        "arrived": driver.status == "arrived",
        "reason": driver.reason,
        "seed": sc.sim.seed,
        "step_length": driver.dt,
        "sim_time_end": totals.time,
        "depart_time": driver.depart_time,
        "travel_time": travel,
        "distance": dist,
        # the route from the ego's start: after a re-route, the edges driven before it
        # and the new route
        "route": list(driver.driven_before + driver.route_edges),
        "route_length": finite_or_none(driver.route_length),
        "avoided_edges": sorted(driver.avoid),
        "safety_margin": sc.roadmap.safety_margin,
        "min_clearance_obstacles": finite_or_none(
            float(d["clearance_obstacles"].min()) if len(t) else math.inf),
        "min_clearance_vehicles": finite_or_none(
            float(d["clearance_vehicles"].min()) if len(t) else math.inf),
        # our own check: the ego's rectangle overlaps another vehicle's rectangle
        "collisions": len(driver.collisions),
        "collision_events": driver.collisions[:100],
        # SUMO's reports: lane-based, so a remote-controlled ego passing a vehicle on the
        # same lane with a lateral offset is reported too; recorded, not counted
        "sumo_collision_reports": len(ego_coll),
        "sumo_collision_reports_list": ego_coll[:100],
        "sumo_collisions_others": len(totals.sumo_collisions) - len(ego_coll),
        "time_off_road": float(off.sum() * driver.dt),
        "off_road_tolerance": OFF_ROAD_TOLERANCE,
        "max_speed": float(d["speed"].max()) if len(t) else None,
        "max_lateral_acceleration": float(np.abs(d["a_lat"]).max()) if len(t) else None,
        "max_curvature": float(np.abs(d["curvature"]).max()) if len(t) else None,
        "lateral_acceleration_method": (
            "v^2 * kappa; kappa of the circle through the driven centre positions at "
            f"each sample and {CURVATURE_SPAN:g} m of path before and after it"),
        "max_longitudinal_acceleration": float(np.abs(d["a_lon"]).max()) if len(t) else None,
        "max_jerk": float(d["jerk"].max()) if len(t) else None,
        # stands of STUCK_AFTER seconds or more, and why (the deadlock watch)
        "stuck": driver.stuck,
        # published plans of vehicles before it that speed alone could not keep clear of
        "plan_conflicts": driver.conflicts[:100],
        "replans": [r.__dict__ for r in driver.replans],
        "replan_count": len(driver.replans),
        "planning_time": summary_stats(plan_times),
        "position_error_max": (float(max(driver.position_errors))
                               if driver.position_errors else None),
        # --time-to-teleport -1: SUMO teleports nobody, so these stay 0 unless the
        # option is changed; a stuck SUMO driver shows as status "timeout" instead
        "teleports": totals.teleports,
        "ego_teleports": len(driver.teleports),
        # wall time [s] of the run: inside SUMO (start, steps, moveToXY, subscription
        # reads, close), in the planner (levels 1 to 3 at each replan) and in the loop
        # itself (the rest: reading the network, observation, safety checks, speed
        # control)
        "wall_time": totals.wall_time,
        "wall_time_sumo": totals.sumo_seconds,
        "wall_time_planner": totals.plan_seconds,
        "wall_time_loop": max(totals.wall_time - totals.sumo_seconds - totals.plan_seconds, 0.0),
        "safety_check_time": driver.check_seconds,
    }


def write_vehicle(out: Path, driven: dict[str, np.ndarray], metrics: dict[str, Any]) -> None:
    """``trajectory.csv`` and ``metrics.json`` of one vehicle into ``out``."""
    out.mkdir(parents=True, exist_ok=True)
    write_csv(out / "trajectory.csv", driven)
    write_json(out / "metrics.json", metrics)


def write_json(path: Path, value: Any) -> None:
    """``value`` as JSON (non-finite floats as ``null``)."""
    with path.open("w") as fh:
        json.dump(jsonable(value), fh, indent=2, allow_nan=False)


def jsonable(value: Any) -> Any:
    """Plain JSON values: non-finite floats become ``None``, numpy scalars Python ones."""
    if isinstance(value, dict):
        return {str(k): jsonable(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [jsonable(v) for v in value]
    if isinstance(value, np.generic):
        value = value.item()
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


def write_csv(path: Path, cols: dict[str, np.ndarray]) -> None:
    """Columns of equal length as a CSV table (numbers with 10 significant digits)."""
    names = list(cols)
    n = len(cols[names[0]]) if names else 0
    with path.open("w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(names)
        for i in range(n):
            row = []
            for name in names:
                v = cols[name][i]
                row.append(v if isinstance(v, str) else f"{float(v):.10g}")
            w.writerow(row)


def run_summary(run: Any, results: dict[str, SimResult]) -> dict[str, Any]:
    """``summary.json`` of a run with several planned vehicles."""
    ms = [r.metrics for r in results.values()]
    statuses: dict[str, int] = {}
    for r in results.values():
        statuses[r.status] = statuses.get(r.status, 0) + 1
    n = len(results)
    arrived = statuses.get("arrived", 0)
    if run.status in ("failed", "interrupted"):
        status = run.status
    elif n and arrived == n:
        status = "arrived"
    elif any(r.status == "failed" for r in results.values()):
        status = "failed"
    else:
        status = "timeout"
    reason = run.reason or (f"{arrived} of {n} planned vehicles arrived"
                            + "".join(f"; {k}: {v}" for k, v in sorted(statuses.items())
                                      if k != "arrived"))
    travel = [m["travel_time"] for m in ms if m["arrived"] and m["travel_time"] is not None]
    gaps = [m["min_clearance_vehicles"] for m in ms if m["min_clearance_vehicles"] is not None]
    plan_s = sum(float(m["wall_time_planner"]) for m in ms)
    driven_s = sum(float(len(r.driven.get("t", ()))) * float(m["step_length"])
                   for r, m in zip(results.values(), ms, strict=True))
    return {
        "scenario": run.sc.name,
        "scenario_file": str(run.sc.path) if run.sc.path else None,
        "status": status,
        "reason": reason,
        "seed": run.sc.sim.seed,
        "selection": (None if run.selection is None else
                      {"vehicles": list(run.selection.vehicles), "vtype": run.selection.vtype,
                       "share": run.selection.share, "seed": run.selection.seed}),
        "planned": n,
        "statuses": statuses,
        "arrived": arrived,
        "vehicles": {vid: {"status": r.status, "reason": r.reason,
                           "travel_time": r.metrics["travel_time"],
                           "collisions": r.metrics["collisions"],
                           "time_off_road": r.metrics["time_off_road"],
                           "min_clearance_vehicles": r.metrics["min_clearance_vehicles"],
                           "stuck": r.metrics.get("stuck")}
                     for vid, r in results.items()},
        "not_planned": dict(run.unplanned),
        "collisions": sum(int(m["collisions"]) for m in ms),
        "vehicles_off_road": sum(1 for m in ms if m["time_off_road"] > 0.0),
        "time_off_road": sum(float(m["time_off_road"]) for m in ms),
        "mean_travel_time_planned": (sum(travel) / len(travel)) if travel else None,
        "min_clearance_planned_vehicles": min(gaps) if gaps else None,
        "sumo_collision_reports": len(run.sumo_collisions),
        "teleports": run.teleports,
        "deadlocks": run.deadlocks,
        "sim_time_end": run.time,
        "wall_time": run.wall_time,
        "wall_time_sumo": run.world.seconds,
        "wall_time_planner": plan_s,
        "real_time_factor": (run.time / run.wall_time) if run.wall_time > 0 else None,
        # wall time per planned vehicle and simulated second it drove [s/s]
        "wall_time_per_vehicle_second": (run.wall_time / driven_s) if driven_s > 0 else None,
        "planned_vehicle_seconds": driven_s,
    }
