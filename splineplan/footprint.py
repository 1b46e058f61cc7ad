"""The vehicle's footprint against obstacles and road edges, at many curve samples at once.

Level 3 checks each sample of a curve: the vehicle's rectangle, centred on the curve and
oriented along it, keeps the safety margin from every obstacle polygon (exact
rectangle-polygon distance, culled by bounding box) and the road margin from the road edges
(by default none: it stays on the road; its corners
and long-side midpoints in the frames of the corridor's reference segments, and the road
edges' inward vertices, which can come between those points, by exact rectangle-point
distance). A module of its own because both the repair of the first curve and the
optimiser's moves (:mod:`splineplan.optimiser`) and the final samples
(:mod:`splineplan.trajectory`) use it.

The checks are loops over samples compiled with numba (cached on disk after the first
run): level 3 calls them a few thousand times per route on tens to hundreds of samples,
where array code spent most of its time in the overhead of small numpy calls.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.ndimage import maximum_filter1d, minimum_filter1d

from splineplan import kernels
from splineplan.corridor import Corridor
from splineplan.geometry import FloatArray, kernel_floats
from splineplan.obstacles import Obstacles
from splineplan.roadmap import RoadmapParams

#: Distance [m] beyond the safety margin within which obstacle clearance is computed exactly.
CLEARANCE_HORIZON = 2.0
#: Distance [m] beyond the safety margin within which the road clearance also counts the
#: road edges' inward vertices (a vertex between two probe points of the footprint comes
#: up to about 0.2 m closer than they do at a 40 degree corner of a lane).
CORNER_BAND = 1.0


@dataclass(frozen=True, eq=False)
class _Checker:
    """Footprint clearance of the vehicle at curve samples.

    The road check works in the frames of the reference line's segments (cached once:
    origins, stations, unit directions, boundary offsets); it needs an estimate of each
    centre's station, which the optimiser keeps per sample, so that no nearest-neighbour
    search runs per move.
    """

    corridor: Corridor
    half_length: float
    half_width: float
    margin: float  # from the obstacles
    road_margin: float  # from the road edges
    vx: FloatArray  # (V,): x and y of the obstacles' vertices, polygon after polygon
    vy: FloatArray
    offsets: NDArray[np.int64]  # (K + 1,): polygon k's vertices are offsets[k]:offsets[k + 1]
    bbox: FloatArray  # (K, 4)
    body: FloatArray = field(init=False)  # (2, q) body-frame points: footprint, then centre
    frames: tuple[FloatArray, ...] = field(init=False)
    window: tuple[FloatArray, ...] = field(init=False)
    corners: tuple[FloatArray, ...] = field(init=False)  # stations, x, y, side (+1 left)

    def __post_init__(self) -> None:
        hl, hw = self.half_length, self.half_width
        pts = np.array([[-hl, -hw], [hl, -hw], [hl, hw], [-hl, hw], [0.0, -hw], [0.0, hw],
                        [0.0, 0.0]])
        object.__setattr__(self, "body", kernel_floats(pts.T))
        # the road's part, once per corridor and vehicle size
        frames, window, corners = self.corridor.derived(
            ("footprint", hl, hw), lambda: _road_frames(self.corridor, hl, hw))
        object.__setattr__(self, "frames", frames)
        object.__setattr__(self, "window", window)
        object.__setattr__(self, "corners", corners)

    @classmethod
    def build(cls, corridor: Corridor, obstacles: Obstacles, params: RoadmapParams,
              near_xy: FloatArray, road_margin: float) -> _Checker:
        reach = np.hypot(params.vehicle_length, params.vehicle_width) / 2.0
        radius = reach + params.safety_margin + CLEARANCE_HORIZON + 5.0
        # the obstacles whose bounding box comes within the radius of the points' extent
        lo, hi = near_xy.min(axis=0) - radius, near_xy.max(axis=0) + radius
        b = obstacles.bbox
        sel = np.flatnonzero((b[:, 0] <= hi[0]) & (b[:, 2] >= lo[0]) & (b[:, 1] <= hi[1])
                             & (b[:, 3] >= lo[1]))
        count = obstacles.offsets[sel + 1] - obstacles.offsets[sel]
        offsets = np.concatenate(([0], np.cumsum(count))).astype(np.int64)
        idx = np.repeat(obstacles.offsets[sel] - offsets[:-1], count) + np.arange(offsets[-1])
        verts = obstacles.vertices[idx]
        return cls(corridor, params.vehicle_length / 2.0, params.vehicle_width / 2.0,
                   params.safety_margin, road_margin, kernel_floats(verts[:, 0]),
                   kernel_floats(verts[:, 1]), offsets, kernel_floats(b[sel]))

    def stations(self, xy: FloatArray) -> FloatArray:
        """Stations [m] of points ``(n, 2)`` on the reference line (exact projection)."""
        return np.asarray(self.corridor.to_sl(xy)[:, 0])

    def road(self, xy: FloatArray, heading: FloatArray, sc: FloatArray | None = None,
             sides: bool = False) -> tuple[FloatArray, FloatArray]:
        """Distance [m] of the footprint to the nearer road edge (negative: off the road),
        and the centres' stations [m]; with ``sides``, its distances to the left and to the
        right road edge instead.

        ``sc`` estimates the centres' stations (``None``: projected exactly). All footprint
        points are projected onto the line of the reference segment at that estimate, then
        measured in the frame of the segment at their own station (the reference is
        resampled finely, so one segment's frame is exact enough; past the ends, the end
        segments extend the road).
        """
        if sc is None:
            sc = self.stations(xy)
        to_left, to_right, station = kernels.road_clearance(
            *_xyh(xy, heading), kernel_floats(sc), *self._road_args())
        if sides:
            return to_left, to_right
        return np.minimum(to_left, to_right), station

    def slack(self, xy: FloatArray, heading: FloatArray, sc: FloatArray | None = None
              ) -> tuple[FloatArray, FloatArray]:
        """Footprint clearance [m] beyond the margins (negative: too close to an obstacle or
        a road edge), and the centres' stations [m] (see :meth:`road`)."""
        if sc is None:
            sc = self.stations(xy)
        return kernels.footprint_slack(*_xyh(xy, heading), kernel_floats(sc),
                                       *self.slack_args())

    def obstacles(self, xy: FloatArray, heading: FloatArray,
                  horizon: float = CLEARANCE_HORIZON, cull: bool = False) -> FloatArray:
        """Distance [m] of the footprint to the nearest obstacle, ``inf`` beyond
        ``margin + horizon`` (obstacles are culled by bounding box; with ``cull``, also
        those separated by more than that along the footprint's axes, so that ``inf``
        may stand for any distance beyond ``margin + horizon``)."""
        return kernels.obstacle_clearance(*_xyh(xy, heading), *self._obstacle_args(),
                                          self.half_length, self.half_width, self.margin,
                                          float(horizon), bool(cull))

    def slack_args(self) -> tuple[Any, ...]:
        """What :func:`splineplan.kernels.footprint_slack` takes after the samples."""
        return (*self._road_args(), *self.window, *self._obstacle_args(), self.margin)

    def _road_args(self) -> tuple[Any, ...]:
        rm = self.road_margin
        reach = np.hypot(self.half_length, self.half_width) + rm + CORNER_BAND
        return (*self.frames, *self.body, *self.corners, self.half_length, self.half_width,
                rm, rm + CORNER_BAND, reach)

    def _obstacle_args(self) -> tuple[Any, ...]:
        return self.vx, self.vy, self.offsets, self.bbox


def _road_frames(cor: Corridor, hl: float, hw: float
                 ) -> tuple[tuple[FloatArray, ...], ...]:
    """The road's part of :class:`_Checker` for a vehicle of half length ``hl`` and half
    width ``hw`` [m]: the reference segments' frames, their windows and the road edges'
    inward vertices."""
    # writable copies: the compiled kernels take one array type
    st = np.array(cor.s, dtype=float)
    h = cor.heading_at(st[:-1])
    ref = np.asarray(cor.reference, dtype=float)
    left, right = np.array(cor.left, dtype=float), np.array(cor.right, dtype=float)
    frames = (st, ref[:-1, 0].copy(), ref[:-1, 1].copy(), np.cos(h), np.sin(h), left, right)
    # per segment, over the stations the footprint can reach from it: the narrowest
    # boundaries and the largest turn of the reference line (for a quick clear test),
    # and the segment's own heading [rad]
    ds = np.diff(st)
    w = int(np.ceil((np.hypot(hl, hw) + 1.0) / max(float(np.quantile(ds, 0.1)), 1e-3)))
    size = min(2 * w + 1, 2 * len(ds) + 1)
    lmin = minimum_filter1d(left, size, mode="nearest")[:-1]
    rmax = maximum_filter1d(right, size, mode="nearest")[:-1]
    hh = np.unwrap(h)
    turn = (maximum_filter1d(hh, size, mode="nearest")
            - minimum_filter1d(hh, size, mode="nearest"))
    seg_heading = np.arctan2(frames[4], frames[3])
    window = (lmin, rmax, turn, seg_heading)
    # the road edges' vertices that point into the road (where an edge turns towards
    # it): the footprint's sides can meet them between the probe points
    found = []
    for side, line in ((1.0, cor.left_xy()), (-1.0, cor.right_xy())):
        d = np.diff(line, axis=0)
        turn_in = side * (d[:-1, 0] * d[1:, 1] - d[:-1, 1] * d[1:, 0]) > 1e-12
        j = np.flatnonzero(turn_in) + 1
        found.append((st[j], line[j, 0], line[j, 1], np.full(len(j), side)))
    cat = [np.concatenate(a) for a in zip(*found, strict=True)]
    order = np.argsort(cat[0], kind="stable")
    return frames, window, tuple(a[order] for a in cat)


def _xyh(xy: FloatArray, heading: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
    return (kernel_floats(xy[:, 0]),
            kernel_floats(xy[:, 1]),
            kernel_floats(heading))
