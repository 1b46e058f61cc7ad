"""The attributes of a planned vehicle's state, declared once for the driver's mixins."""

from __future__ import annotations

from typing import Any

import numpy as np

from splineplan.closedloop.lanes import LaneChange
from splineplan.corridor import Corridor
from splineplan.geometry import FloatArray
from splineplan.network import CarShape
from splineplan.obstacles import Obstacles
from splineplan.sumo.world import Signals
from splineplan.traffic import Others


class DriverState:
    """Declarations only (set in :class:`~splineplan.closedloop.driver.Driver`)."""

    sc: Any
    net: Any
    ego: str
    kind: str
    dt: float
    time: float
    status: str
    reason: str
    rows: list[tuple[Any, ...]]
    replans: list[Any]
    plans: list[Any]
    collisions: list[dict[str, Any]]
    position_errors: list[float]
    avoid: set[str]
    route_edges: tuple[str, ...]
    driven_before: tuple[str, ...]
    route_length: float
    route_request: list[str] | None
    corridor: Corridor | None
    polygons: Obstacles
    road: Any
    traj: Any
    path_s: FloatArray
    path_xy: FloatArray
    path_heading: FloatArray
    path_speed: FloatArray
    ext_s: FloatArray
    ext_xy: FloatArray
    ext_heading: FloatArray
    full_s: FloatArray
    full_xy: FloatArray
    full_heading: FloatArray
    u: float
    v: float
    pose: FloatArray
    sumo_front: FloatArray
    sumo_heading: float
    planned_ids: frozenset[str]
    window_end: float
    truncated: bool
    stop_at: float | None
    retry_at: float | None
    goal_station: float
    last_lane: str
    plan_seconds: float
    station: float
    lateral: float
    deviation: float
    limited: int
    traffic_after: float
    trigger_after: float
    horizon_after: float
    joined_at: float | None
    others: Others
    board: Any  # Mapping[str, cooperate.Published]: the plans published so far
    priority: int
    publish: bool
    keep_plans: bool
    keep_lane: bool
    lane_change: LaneChange | None
    keep_clear: bool
    published_plan: Any  # spacetime.MovingObstacle | None: this vehicle's latest plan
    own_plan: Any  # the same, kept after the run took it to the board
    go_at: float
    waiting_for: tuple[str, ...]
    plan_wait: float | None  # station on the trajectory where its plan first stands
    board_seen: int  # the board's count of plans when this one last planned
    trusted: dict[str, Any]  # id -> spacetime.MovingObstacle: plans the current one is timed among
    why_slow: str
    slowed_by: tuple[str, ...]
    stand_since: float | None  # since when it stands (the deadlock watch) [s]
    released: dict[str, float]
    held_by: str
    wait_replan_at: float
    conflicts: list[dict[str, Any]]
    signals: Signals
    _obs_cache: dict[tuple[str, float, float], tuple[float, float, bool]]
    _body_paths: dict[tuple[str, str], Any]  # (lane, via) -> (bodies.BodyPath, lane) | None
    _bodies_now: dict[tuple[Any, float], Any]  # (LanePlace, length) -> predicted body | None
    _bodies_after: dict[str, Any]  # id -> (bodies.BodyPath, lane index, lane id) after
    _pl: tuple[list[float], ...]
    _pl_np: tuple[FloatArray, FloatArray]
    _corner_reach: list[float]
    _times_key: tuple[float, float] | None
    _times: tuple[int, list[float], list[float]]
    _full: tuple[list[float], ...]
    _ahead_box: tuple[list[float], ...]
    _sample_step: float
    _lane_of: tuple[str, int]
    _ref_a: FloatArray
    _ref_ab: FloatArray
    _ref_s: list[float]
    _ref_cols: tuple[FloatArray, ...]
    _ref_len: FloatArray
    _ref_heading: FloatArray
    _edge_starts: list[float]
    _junction_spans: list[tuple[float, float]]
    _one_lane_junctions: set[float]  # their entry stations [m]
    _stop_lines: list[tuple[float, str, str]]  # (route station [m], edge, kind) of each
    stops_done: set[str]  # the edges at whose stop line the vehicle has stopped
    stop_since: float | None  # since when [s] it stands at a stop line
    _beside_at: tuple[float, float] | None
    _beside_was: tuple[np.ndarray, FloatArray]
    _cand_at: tuple[float, float] | None
    _cand_was: list[int]
    _turn_key: tuple[Corridor, float] | None
    _reach: dict[tuple[str, float], list[float]]
    _bands: dict[tuple[str, float], Any]  # see Control._lane_band
    _turn_window: FloatArray

    @property
    def car(self) -> CarShape:
        """The vehicle as level 1 sees it: which junction turns it can make."""
        return CarShape(self.sc.ego.length, self.sc.ego.width,
                        self.sc.trajectory.min_turn_radius)
