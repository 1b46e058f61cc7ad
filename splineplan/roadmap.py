"""Level 2: the sweep-line roadmap, searched for the widest, then shortest, path.

(Kala & Warwick, section III; the objective as fixed in ALGORITHM.md: maximise
``min(bottleneck width, wmax)``, then minimise length.)
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from splineplan.corridor import Corridor
from splineplan.errors import ParameterError
from splineplan.geometry import FloatArray
from splineplan.obstacles import Obstacles


@dataclass(frozen=True)
class RoadmapParams:
    """Parameters of level 2, checked on creation.

    Attributes
    ----------
    d
        Spacing [m] of the sweep lines.
    wmax
        Width [m] above which free intervals count as equally wide.
    safety_margin
        Clearance [m] kept from obstacles and road edges, beyond the ego's half width.
    vehicle_length, vehicle_width
        Ego dimensions [m].
    segment_length
        Length [m] of the road segments a long route is cut into.
    """

    d: float = 1.0
    wmax: float = 3.5
    safety_margin: float = 0.3
    vehicle_length: float = 4.5
    vehicle_width: float = 1.8
    segment_length: float = 300.0

    def __post_init__(self) -> None:
        for name in ("d", "wmax", "vehicle_length", "vehicle_width", "segment_length"):
            value = getattr(self, name)
            if not (np.isfinite(value) and value > 0):
                raise ParameterError(f"RoadmapParams.{name} must be positive, got {value!r}")
        if not (np.isfinite(self.safety_margin) and self.safety_margin >= 0):
            raise ParameterError(
                f"RoadmapParams.safety_margin must be >= 0, got {self.safety_margin!r}"
            )
        if self.segment_length < 2 * self.d:
            raise ParameterError("RoadmapParams.segment_length must be at least 2 d")

    @property
    def inflation(self) -> float:
        """How far [m] obstacles and road edges are grown: half width plus margin."""
        return self.vehicle_width / 2.0 + self.safety_margin


@dataclass(frozen=True, eq=False)
class Roadmap:
    """Result of level 2.

    The chosen path runs through ``m`` vertices, one per sweep line from the source's
    line to the last line. Widths are those of the free intervals of the grown
    (configuration-space) obstacles: a width of 0 means the ego just fits.

    Attributes
    ----------
    xy, s, l, width
        The chosen vertices: points ``(m, 2)`` [m], station ``(m,)`` [m], lateral offset
        ``(m,)`` [m] and free-interval width ``(m,)`` [m].
    bottleneck_width
        Narrowest width [m] on the chosen path (not capped at wmax).
    bottleneck_index
        Index into the chosen vertices of that narrowest vertex.
    length
        Length [m] of the chosen polyline.
    graph_xy, graph_s, graph_l, graph_width, graph_line
        The whole graph's vertices: points ``(V, 2)``, station, lateral offset, width and
        the index of each vertex's sweep line ``(V,)``.
    graph_lo, graph_hi
        Lateral bounds ``(V,)`` [m] of each vertex's free interval.
    arcs
        ``(E, 2)`` vertex indices of the graph's arcs, from line i to line i + 1.
    path
        ``(m,)`` indices into the graph's vertices of the chosen path.
    start_xy
        Where the vehicle was ``(2,)`` [m].
    params
        The parameters used.
    """

    xy: FloatArray
    s: FloatArray
    l: FloatArray  # noqa: E741
    width: FloatArray
    bottleneck_width: float
    bottleneck_index: int
    length: float
    graph_xy: FloatArray
    graph_s: FloatArray
    graph_l: FloatArray
    graph_width: FloatArray
    graph_line: NDArray[np.int64]
    graph_lo: FloatArray
    graph_hi: FloatArray
    arcs: NDArray[np.int64]
    path: NDArray[np.int64]
    start_xy: FloatArray
    params: RoadmapParams

    @property
    def bottleneck_s(self) -> float:
        """Station [m] of the narrowest vertex on the chosen path."""
        return float(self.s[self.bottleneck_index])


def plan_roadmap(
    corridor: Corridor,
    obstacles: Obstacles,
    start_xy: ArrayLike,
    params: RoadmapParams | None = None,
) -> Roadmap:
    """Widest-then-shortest roadmap across a corridor among obstacles."""
    raise NotImplementedError
