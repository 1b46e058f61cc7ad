"""SUMO road networks as compact arrays: the edge graph of level 1 and lane geometry.

This is the only module that reads SUMO files. :func:`load_network` reads a ``.net.xml`` or
``.net.xml.gz`` with sumolib and keeps plain arrays and small frozen records.

The graph
---------
A vertex is a normal SUMO edge (a road in one direction); internal (junction) edges, whose
ids start with ``':'``, are not vertices. An arc ``e -> f`` exists for a vehicle class where a
connection leads from a lane of ``e`` to a lane of ``f`` such that the class may use the
from-lane, the to-lane, the connection itself and every internal (via) lane it runs over.
The arcs are stored per class in CSR form (:class:`ClassGraph`), built on first use and cached.

Length convention (the same as ``sumolib.net.Net.getShortestPath``)
------------------------------------------------------------------
The length of a route ``e0, e1, ..., ek`` is::

    (length(e0) - start_pos) + sum_i ( internal(e_{i-1} -> e_i) + length(e_i) )

where an edge's length is that of its first lane (SUMO's ``length`` attribute, which can
differ from the length of the drawn shape), the last edge counts in full, and
``internal(e -> f)`` is the length of the shortest chain of internal lanes over which an
allowed connection from ``e`` to ``f`` runs (0 where no allowed connection has internal
lanes, e.g. in networks built without them). By travel time, every length is divided by
its lane's (for an edge: its last lane's) speed limit, and the internal chain is the one
of least time. A route of one edge has the length ``length(e0) - start_pos``.
"""

from __future__ import annotations

import logging
from collections.abc import Iterable
from dataclasses import dataclass, field
from itertools import chain
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from splineplan.corridor import Corridor
from splineplan.errors import (
    GeometryError,
    NetworkError,
    UnknownEdgeError,
    VehicleClassError,
)
from splineplan.geometry import FloatArray, dedupe_polyline, polyline_stations, resample_polyline
from splineplan.obstacles import Obstacles

log = logging.getLogger(__name__)

IntArray = NDArray[np.int64]

#: SUMO's vehicle classes (SUMO 1.x, without the deprecated aliases).
VEHICLE_CLASSES: frozenset[str] = frozenset((
    "private", "emergency", "authority", "army", "vip", "passenger", "hov", "taxi", "bus",
    "coach", "delivery", "truck", "trailer", "tram", "rail_urban", "rail", "rail_electric",
    "motorcycle", "moped", "bicycle", "pedestrian", "evehicle", "ship", "container",
    "cable_car", "subway", "aircraft", "wheelchair", "scooter", "drone", "custom1", "custom2",
))


@dataclass(frozen=True, eq=False)
class Lane:
    """One lane of a normal or internal edge.

    Attributes
    ----------
    id
        SUMO lane id, ``<edge>_<index>``.
    index
        Index within its edge, 0 = rightmost.
    width, length, speed
        Width [m], length [m] (SUMO's attribute) and speed limit [m/s].
    shape
        Centre line ``(n, 2)`` [m] in the direction of travel.
    allowed
        Vehicle classes that may use the lane.
    """

    id: str
    index: int
    width: float
    length: float
    speed: float
    shape: FloatArray
    allowed: frozenset[str]

    def allows(self, vclass: str) -> bool:
        """Whether vehicle class ``vclass`` may use this lane."""
        return vclass in self.allowed


@dataclass(frozen=True)
class Connection:
    """A link from a lane of one normal edge to a lane of the next.

    Attributes
    ----------
    from_edge, to_edge
        Normal edge ids.
    from_lane, to_lane
        Lane indices on those edges.
    via
        Internal lane ids the link runs over, in order (empty where the network has none).
    allowed
        Vehicle classes the connection itself admits.
    direction
        SUMO's direction code: ``s`` straight, ``l``/``r`` left/right, ``t`` turnaround, ...
    """

    from_edge: str
    to_edge: str
    from_lane: int
    to_lane: int
    via: tuple[str, ...]
    allowed: frozenset[str]
    direction: str


@dataclass(frozen=True, eq=False)
class ClassGraph:
    """The edge graph of one vehicle class, in CSR form.

    Attributes
    ----------
    vclass
        The vehicle class.
    usable
        ``(n,)`` whether the class may use some lane of each edge.
    indptr, indices
        CSR arrays: the arcs of edge ``e`` lead to ``indices[indptr[e]:indptr[e + 1]]``.
    via_length, via_time
        ``(m,)`` length [m] and travel time [s] of each arc's shortest (fastest) internal
        lane chain, 0 where the connections have none.
    """

    vclass: str
    usable: NDArray[np.bool_]
    indptr: IntArray
    indices: IntArray
    via_length: FloatArray
    via_time: FloatArray

    @property
    def n_arcs(self) -> int:
        """Number of arcs."""
        return len(self.indices)


@dataclass(frozen=True, eq=False)
class RoadNetwork:
    """A SUMO network: normal edges as arrays, lanes and connections as records.

    Use :func:`load_network` to build one. Edge ``i`` of every array is ``edge_ids[i]``.

    Attributes
    ----------
    path
        The file it was read from.
    edge_ids
        Normal edge ids ``(n,)``.
    lengths
        Edge lengths ``(n,)`` [m] (SUMO's length of the first lane).
    speeds
        Edge speed limits ``(n,)`` [m/s] (of the last lane, as sumolib).
    lanes
        Per edge, its lanes from right to left.
    connections
        Every connection between normal edges.
    internal_lanes
        Internal (junction) lanes by id.
    bounds
        ``(xmin, ymin, xmax, ymax)`` [m] of the lane shapes.
    junction_shapes
        Outline ``(k, 2)`` [m] of each junction (SUMO's node shape) by junction id; only
        outlines with at least three points.
    to_junctions
        Per edge, the id of the junction it ends at (empty where unknown).
    """

    path: Path
    edge_ids: tuple[str, ...]
    lengths: FloatArray
    speeds: FloatArray
    lanes: tuple[tuple[Lane, ...], ...]
    connections: tuple[Connection, ...]
    internal_lanes: dict[str, Lane]
    bounds: tuple[float, float, float, float]
    _index: dict[str, int] = field(repr=False)
    _conn_from: IntArray = field(repr=False)
    _conn_to: IntArray = field(repr=False)
    _graphs: dict[str, ClassGraph] = field(default_factory=dict, repr=False)
    junction_shapes: dict[str, FloatArray] = field(default_factory=dict, repr=False)
    to_junctions: tuple[str, ...] = ()

    @property
    def n_edges(self) -> int:
        """Number of normal edges."""
        return len(self.edge_ids)

    def __contains__(self, edge_id: object) -> bool:
        return edge_id in self._index

    def edge_index(self, edge_id: str) -> int:
        """Index of a normal edge; :class:`UnknownEdgeError` naming it if absent."""
        try:
            return self._index[edge_id]
        except KeyError:
            hint = " (internal edges cannot be used)" if str(edge_id).startswith(":") else ""
            raise UnknownEdgeError(
                f"edge '{edge_id}' is not in network {self.path.name}{hint}") from None

    def lanes_of(self, edge_id: str) -> tuple[Lane, ...]:
        """Lanes of a normal edge, rightmost first."""
        return self.lanes[self.edge_index(edge_id)]

    def length_of(self, edge_id: str) -> float:
        """Length [m] of a normal edge."""
        return float(self.lengths[self.edge_index(edge_id)])

    def allows(self, edge_id: str, vclass: str) -> bool:
        """Whether ``vclass`` may use some lane of ``edge_id``."""
        i = self.edge_index(edge_id)
        return bool(self.graph(vclass).usable[i])

    def internal_lane(self, lane_id: str) -> Lane:
        """An internal (junction) lane by id."""
        try:
            return self.internal_lanes[lane_id]
        except KeyError:
            raise UnknownEdgeError(f"internal lane '{lane_id}' is not in network "
                                   f"{self.path.name}") from None

    def connections_between(self, from_edge: str, to_edge: str, *,
                            vclass: str | None = None) -> tuple[Connection, ...]:
        """Connections from ``from_edge`` to ``to_edge``, only those ``vclass`` may use if given."""
        i, j = self.edge_index(from_edge), self.edge_index(to_edge)
        lo, hi = np.searchsorted(self._conn_from, [i, i + 1])
        ks = [k for k in range(int(lo), int(hi)) if self._conn_to[k] == j]
        conns = [self.connections[k] for k in ks]
        if vclass is not None:
            check_vclass(vclass)
            conns = [c for c in conns if self._connection_allows(c, vclass)]
        return tuple(conns)

    def graph(self, vclass: str) -> ClassGraph:
        """The edge graph of ``vclass`` (built on first use, then cached)."""
        g = self._graphs.get(vclass)
        if g is None:
            check_vclass(vclass)
            g = _build_graph(self, vclass)
            self._graphs[vclass] = g
        return g

    def _connection_allows(self, c: Connection, vclass: str) -> bool:
        fl = self.lanes_of(c.from_edge)[c.from_lane]
        tl = self.lanes_of(c.to_edge)[c.to_lane]
        return (vclass in c.allowed and fl.allows(vclass) and tl.allows(vclass)
                and all(self.internal_lanes[v].allows(vclass) for v in c.via))


def check_vclass(vclass: str) -> None:
    """Raise :class:`VehicleClassError` unless ``vclass`` is a SUMO vehicle class."""
    if vclass not in VEHICLE_CLASSES:
        raise VehicleClassError(
            f"unknown vehicle class '{vclass}'; SUMO's classes are e.g. passenger, bus, "
            "truck, bicycle, pedestrian")


def load_network(path: str | Path) -> RoadNetwork:
    """Read a SUMO network file (``.net.xml`` or ``.net.xml.gz``).

    Raises
    ------
    NetworkError
        The file is missing, unreadable or not a SUMO network.
    """
    import sumolib  # deferred: heavy, and only this module touches it

    p = Path(path)
    if not p.is_file():
        raise NetworkError(f"network file not found: {p}")
    try:
        net = sumolib.net.readNet(str(p), withInternal=True, withFoes=False, maxcache=0)
    except Exception as err:  # sumolib raises whatever its XML parser raises
        raise NetworkError(f"cannot read SUMO network {p}: {err}".splitlines()[0]) from err
    try:
        return _from_sumolib(p, net)
    except (KeyError, ValueError, IndexError, AttributeError) as err:
        raise NetworkError(f"{p} is not a usable SUMO network: {err}") from err


def _from_sumolib(path: Path, net: Any) -> RoadNetwork:
    """Copy what splineplan needs out of a sumolib ``Net``."""
    all_classes = VEHICLE_CLASSES
    perm_cache: dict[frozenset[str], frozenset[str]] = {}

    def perms(allowed: Iterable[str]) -> frozenset[str]:
        fs = frozenset(allowed)
        if "all" in fs:
            fs = all_classes
        return perm_cache.setdefault(fs, fs)

    def lane_record(lane: Any, index: int) -> Lane:
        shape = np.asarray([pt[:2] for pt in lane.getShape()], dtype=float).reshape(-1, 2)
        shape.setflags(write=False)
        return Lane(id=f"{lane.getEdge().getID()}_{index}", index=index,
                    width=float(lane.getWidth()), length=float(lane.getLength()),
                    speed=float(lane.getSpeed()), shape=shape,
                    allowed=perms(lane.getPermissions()))

    normal = []
    internal: dict[str, Lane] = {}
    for e in net.getEdges(withInternal=True):
        fn = e.getFunction()
        if fn == "":
            normal.append(e)
        elif fn == "internal":
            for k, ln in enumerate(e.getLanes()):
                rec = lane_record(ln, k)
                internal[rec.id] = rec
    if not normal:
        raise NetworkError(f"{path} is not a SUMO network (it has no edges)")

    edge_ids = tuple(e.getID() for e in normal)
    index = {eid: i for i, eid in enumerate(edge_ids)}
    lanes = tuple(tuple(lane_record(ln, k) for k, ln in enumerate(e.getLanes()))
                  for e in normal)
    lengths = np.array([e.getLength() for e in normal], dtype=float)
    speeds = np.array([e.getSpeed() for e in normal], dtype=float)

    # the internal lane that follows each internal lane (internal junctions split a link)
    next_via: dict[str, str] = {}
    for lid in internal:
        ln = net.getLane(lid)
        out = ln.getOutgoing()
        if out and out[0].getViaLaneID():
            next_via[lid] = out[0].getViaLaneID()

    conns: list[Connection] = []
    for e in normal:
        for f, cs in e.getOutgoing().items():
            if f.getFunction() != "":
                continue
            for c in cs:
                chain: list[str] = []
                v = c.getViaLaneID() or ""
                while v and v in internal and len(chain) < 16:
                    chain.append(v)
                    v = next_via.get(v, "")
                conns.append(Connection(
                    from_edge=e.getID(), to_edge=f.getID(),
                    from_lane=c.getFromLane().getIndex(), to_lane=c.getToLane().getIndex(),
                    via=tuple(chain), allowed=perms(c._allowed),
                    direction=str(c.getDirection())))
    conns.sort(key=lambda c: (index[c.from_edge], index[c.to_edge], c.from_lane, c.to_lane))
    conn_from = np.array([index[c.from_edge] for c in conns], dtype=np.int64)
    conn_to = np.array([index[c.to_edge] for c in conns], dtype=np.int64)

    junctions: dict[str, FloatArray] = {}
    for nd in net.getNodes():
        outline = np.asarray([pt[:2] for pt in nd.getShape()], dtype=float).reshape(-1, 2)
        if len(outline) >= 3:
            outline.setflags(write=False)
            junctions[nd.getID()] = outline
    to_junctions = tuple(e.getToNode().getID() for e in normal)

    pts = [ln.shape for ls in lanes for ln in ls if len(ln.shape)]
    allpts = np.concatenate(pts) if pts else np.zeros((1, 2))
    lo, hi = allpts.min(axis=0), allpts.max(axis=0)
    for a in (lengths, speeds, conn_from, conn_to):
        a.setflags(write=False)
    log.info("loaded %s: %d edges, %d connections, %d internal lanes",
             path, len(edge_ids), len(conns), len(internal))
    return RoadNetwork(
        path=path, edge_ids=edge_ids, lengths=lengths, speeds=speeds, lanes=lanes,
        connections=tuple(conns), internal_lanes=internal,
        bounds=(float(lo[0]), float(lo[1]), float(hi[0]), float(hi[1])),
        _index=index, _conn_from=conn_from, _conn_to=conn_to,
        junction_shapes=junctions, to_junctions=to_junctions)


def _build_graph(net: RoadNetwork, vclass: str) -> ClassGraph:
    """CSR arcs of ``vclass``: one per (from, to) pair with at least one allowed connection."""
    n = net.n_edges
    usable = np.array([any(vclass in ln.allowed for ln in ls) for ls in net.lanes], dtype=bool)
    keys: list[int] = []
    vlen: list[float] = []
    vtime: list[float] = []
    for c in net.connections:
        if not net._connection_allows(c, vclass):
            continue
        keys.append(net._index[c.from_edge] * n + net._index[c.to_edge])
        if c.via:
            vias = [net.internal_lanes[v] for v in c.via]
            vlen.append(sum(v.length for v in vias))
            vtime.append(sum(v.length / v.speed for v in vias))
        else:  # as sumolib: a link without internal lanes does not count
            vlen.append(np.inf)
            vtime.append(np.inf)
    if keys:
        k = np.asarray(keys, dtype=np.int64)
        order = np.argsort(k, kind="stable")
        k = k[order]
        starts = np.flatnonzero(np.concatenate(([True], k[1:] != k[:-1])))
        via_length = np.minimum.reduceat(np.asarray(vlen)[order], starts)
        via_time = np.minimum.reduceat(np.asarray(vtime)[order], starts)
        via_length[~np.isfinite(via_length)] = 0.0
        via_time[~np.isfinite(via_time)] = 0.0
        uk = k[starts]
        src, dst = uk // n, uk % n
    else:
        src = dst = np.zeros(0, dtype=np.int64)
        via_length = via_time = np.zeros(0)
    indptr = np.zeros(n + 1, dtype=np.int64)
    np.add.at(indptr, src + 1, 1)
    indptr = np.cumsum(indptr)
    for a in (usable, indptr, dst, via_length, via_time):
        a.setflags(write=False)
    return ClassGraph(vclass, usable, indptr, dst.astype(np.int64), via_length, via_time)


# ---- corridor adapter ---------------------------------------------------------------------

#: Standard deviation [m] of the Gaussian that smooths a route corridor's reference line
#: along the edges.
REFERENCE_SMOOTHING = 2.0
#: Standard deviation [m] of the Gaussian that smooths the reference line through junctions
#: (and :data:`JUNCTION_APPROACH` before and after), so that it turns with a radius a car
#: can drive where the junction's area allows.
JUNCTION_SMOOTHING = 5.0
#: Length [m] of the approach before and after a junction that is smoothed as the junction.
JUNCTION_APPROACH = 6.0
#: How far [m] beyond the junction lanes the route takes the corridor may spread over the
#: junction's paved area (so it does not sweep across the whole junction).
JUNCTION_REACH = 3.0
#: Largest distance [m] of a corridor boundary from the reference line.
MAX_OFFSET = 6.0
#: On the inner side of a bend the boundary stays within this fraction of the reference
#: line's radius of curvature, so that neighbouring sweep lines never cross.
INNER_RADIUS_FRACTION = 0.9
#: Margin [m] by which the corridor's boundaries stay inside the drivable region.
BOUNDARY_MARGIN = 0.0
#: Gaps [m] along a ray between pieces of the region narrower than this count as covered
#: (where neighbouring lane shapes meet with rounding error).
_GAP = 0.02
#: How often the reference line is smoothed less where it leaves the drivable region or
#: comes closer than :data:`REFERENCE_CLEARANCE` [m] (or a quarter of the width) to its edge.
REFERENCE_ATTEMPTS = 3
REFERENCE_CLEARANCE = 0.3
_LANE, _JUNCTION = 0, 1
_MIN_WIDTH = 0.05
_TAG_REACH = 2  # a stretch's lines meet its own pieces and those one junction either way


def route_corridor(network: RoadNetwork, route: Any, *, vclass: str | None = None) -> Corridor:
    """The drivable area of a route as a :class:`~splineplan.corridor.Corridor`.

    The drivable region of the route is the union of the lanes of each route edge from its
    rightmost to its leftmost lane that ``vclass`` may use, the junction (internal) lanes
    of the allowed connections between consecutive route edges, and the paved area of each
    junction passed through (SUMO's junction outline) within :data:`JUNCTION_REACH` of
    those junction lanes. The reference line joins the midlines of the edges' lanes and of
    the junction lanes, smoothed more strongly through junctions. The boundary offsets come
    from casting each sweep line (the normal of the reference line at every vertex, as
    :meth:`Corridor.to_xy` draws it) left and right through the region: the boundary is the
    end of the region's covered stretch that holds the reference point, at most
    :data:`MAX_OFFSET` away, kept within :data:`INNER_RADIUS_FRACTION` of the radius of
    curvature on the inner side of bends, and :data:`BOUNDARY_MARGIN` inside. Junction
    stretches count towards the edge before them in ``edge_at``. The corridor covers the
    whole first edge (also when the route starts at ``start_pos > 0``).

    Parameters
    ----------
    route
        A :class:`splineplan.route.Route` (anything with ``edges`` and ``vclass``).
    vclass
        Vehicle class; defaults to the route's.
    """
    cls = vclass if vclass is not None else getattr(route, "vclass", "passenger")
    check_vclass(cls)
    edges = tuple(route.edges)
    if not edges:
        raise GeometryError("route has no edges")
    mids: list[FloatArray] = []
    in_junction: list[bool] = []
    mid_tags: list[int] = []
    firsts: list[FloatArray] = []  # where each edge's own stretch begins
    polys: list[FloatArray] = []
    kinds: list[int] = []
    tags: list[int] = []  # 2i: edge i, 2i + 1: the junction after it
    for i, eid in enumerate(edges):
        all_lanes = network.lanes_of(eid)
        lanes = [ln for ln in all_lanes if ln.allows(cls)]
        if not lanes:
            raise GeometryError(f"vehicle class '{cls}' may use no lane of edge '{eid}'")
        ref, _, _ = _band(lanes[0].shape, lanes[0].width, lanes[-1].shape, lanes[-1].width)
        mids.append(ref)
        in_junction.append(False)
        mid_tags.append(2 * i)
        firsts.append(ref[0])
        for ln in all_lanes[lanes[0].index:lanes[-1].index + 1]:
            polys.extend(_lane_polygons(ln.shape, ln.width))
        kinds.extend([_LANE] * (len(polys) - len(kinds)))
        tags.extend([2 * i] * (len(polys) - len(tags)))
        if i + 1 == len(edges):
            break
        conns = [c for c in network.connections_between(eid, edges[i + 1], vclass=cls)
                 if c.via]
        for v in dict.fromkeys(v for c in conns for v in c.via):
            ln = network.internal_lanes[v]
            polys.extend(_lane_polygons(ln.shape, ln.width))
        kinds.extend([_LANE] * (len(polys) - len(kinds)))
        jid = network.to_junctions[network.edge_index(eid)] if network.to_junctions else ""
        outline = network.junction_shapes.get(jid)
        if outline is not None and abs(_signed_area(outline)) > 1e-6:
            polys.append(outline)
            kinds.append(_JUNCTION)
        tags.extend([2 * i + 1] * (len(polys) - len(tags)))
        if conns:
            conns.sort(key=lambda c: (c.from_lane, c.to_lane))
            rshape = _via_shape(network, conns[0].via)
            lshape = _via_shape(network, conns[-1].via)
            if len(rshape) >= 2 and len(lshape) >= 2:
                rw = network.internal_lanes[conns[0].via[0]].width
                lw = network.internal_lanes[conns[-1].via[0]].width
                mids.append(_band(rshape, rw, lshape, lw)[0])
                in_junction.append(True)
                mid_tags.append(2 * i + 1)
    region = _Region(polys, np.asarray(kinds, dtype=np.int64), np.asarray(tags, dtype=np.int64))
    level = None
    for _ in range(REFERENCE_ATTEMPTS):
        # where the smoothed reference line leaves the region (or nearly), smooth less there
        reference, level, ref_tags = _reference_line(mids, in_junction, mid_tags, level)
        extents = _extents(region, reference, ref_tags)
        left, right = extents[0], extents[1]
        need = np.minimum(REFERENCE_CLEARANCE, 0.25 * (left - right))
        bad = np.minimum(left, -right) < need
        if not bad.any() or not level.any():
            break
        idx = np.flatnonzero(bad) * (len(level) - 1) // max(len(reference) - 1, 1)
        near = np.zeros(len(level), dtype=bool)
        near[idx] = True
        near = np.convolve(near, np.ones(17), mode="same") > 0  # +-4 m
        level = np.where(near, np.maximum(level - 1.0, 0.0), level)
    left, right = _ray_offsets(region, reference, ref_tags, extents)
    s = polyline_stations(reference)
    probe = Corridor(reference, s, left, right)
    starts_s = probe.to_sl(np.array(firsts))[:, 0]
    starts_s[0] = 0.0
    starts_s = np.maximum.accumulate(np.clip(starts_s, 0.0, probe.length))
    return Corridor(reference, s, left, right, edges, starts_s)


def _reference_line(mids: list[FloatArray], in_junction: list[bool], mid_tags: list[int],
                    level: FloatArray | None = None
                    ) -> tuple[FloatArray, FloatArray, IntArray]:
    """The joined midlines, resampled every 0.5 m and smoothed, ``(n, 2)`` [m].

    Gaussian of :data:`REFERENCE_SMOOTHING` along edges, of :data:`JUNCTION_SMOOTHING`
    through junction stretches and their approaches, blended smoothly; the end points stay.
    ``level`` (per point of the joined midlines resampled every 0.5 m) overrides where:
    0 = not smoothed, 1 = along edges, 2 = junction, fractions blend. Returns the
    reference line, the level used and the tag of the midline each point comes from.
    """
    from scipy.ndimage import gaussian_filter1d

    pts = np.concatenate(mids)
    flag = np.concatenate([np.full(len(m), j) for m, j in zip(mids, in_junction, strict=True)])
    vtag = np.concatenate([np.full(len(m), g) for m, g in zip(mids, mid_tags, strict=True)])
    keep = np.concatenate(([True], np.hypot(*np.diff(pts, axis=0).T) > 1e-9))
    pts, flag, vtag = pts[keep], flag[keep], vtag[keep]
    if len(pts) < 2:
        raise GeometryError("route has a reference line of zero length")
    st = polyline_stations(pts)
    ref = resample_polyline(pts, 0.5)
    if len(ref) < 5:
        return ref, np.zeros(len(ref)), _tags_at(st, vtag, np.linspace(0, st[-1], len(ref)))
    step = st[-1] / (len(ref) - 1)
    t = np.linspace(0.0, st[-1], len(ref))
    mask = np.zeros(len(ref))
    edges_of_runs = np.flatnonzero(np.diff(np.concatenate(([0], flag.astype(int), [0]))))
    for a, b in zip(edges_of_runs[::2], edges_of_runs[1::2], strict=True):
        lo, hi = st[a] - JUNCTION_APPROACH, st[b - 1] + JUNCTION_APPROACH
        mask[(t >= lo) & (t <= hi)] = 1.0
    if level is None:
        level = 1.0 + np.clip(gaussian_filter1d(mask, 2.0 / step, mode="nearest"), 0.0, 1.0)
    lv = gaussian_filter1d(level, 1.0 / step, mode="nearest")[:, None]
    weak = gaussian_filter1d(ref, REFERENCE_SMOOTHING / step, axis=0, mode="nearest")
    out = ref + np.clip(lv, 0.0, 1.0) * (weak - ref)
    if np.any(lv > 1.0):
        strong = gaussian_filter1d(ref, JUNCTION_SMOOTHING / step, axis=0, mode="nearest")
        out += np.clip(lv - 1.0, 0.0, 1.0) * (strong - weak)
    out[0], out[-1] = ref[0], ref[-1]
    out = resample_polyline(out, 0.5)
    return out, level, _tags_at(st, vtag, np.linspace(0.0, st[-1], len(out)))


def _tags_at(stations: FloatArray, tags: IntArray, at: FloatArray) -> IntArray:
    """Tag of the vertex at or before each station ``at`` [m]."""
    i = np.clip(np.searchsorted(stations, at, side="right") - 1, 0, len(tags) - 1)
    return np.asarray(tags[i], dtype=np.int64)


class _Region:
    """A union of polygons (lane pieces and junction outlines) prepared for line queries."""

    def __init__(self, polys: list[FloatArray], kinds: IntArray, tags: IntArray) -> None:
        if not polys:
            raise GeometryError("route has no drivable area")
        self.counts = np.array([len(p) for p in polys], dtype=np.int64)
        self.offsets = np.concatenate(([0], np.cumsum(self.counts)))
        self.verts = np.concatenate(polys)
        self.nxt = np.arange(len(self.verts)) + 1
        self.nxt[self.offsets[1:] - 1] = self.offsets[:-1]
        lo = np.minimum.reduceat(self.verts, self.offsets[:-1], axis=0)
        hi = np.maximum.reduceat(self.verts, self.offsets[:-1], axis=0)
        self.centres = (lo + hi) / 2.0
        self.radii = np.hypot(*(hi - lo).T) / 2.0
        self.kinds = kinds
        self.tags = tags

    def components(self, origins: FloatArray, dirs: FloatArray, t_lo: FloatArray,
                   t_hi: FloatArray, tags: IntArray, *, reach: float | None = None
                   ) -> tuple[IntArray, FloatArray, FloatArray, IntArray, IntArray]:
        """Covered stretches of lines ``origins + t * dirs`` (unit ``dirs``), ``t_lo <= t <= t_hi``.

        Returns line index, start and end [m] of each connected covered stretch (gaps
        below :data:`_GAP` closed), sorted by line, then start, and the lane piece whose
        boundary each stretch starts and ends on (-1 where it ends on a junction outline
        or a limit). With ``reach``, junction outlines cover only within ``reach`` beyond
        the lane pieces on the same line. A line meets only the polygons whose tag (the
        route stretch they belong to) is within :data:`_TAG_REACH` of its own ``tags``, so
        that a route that passes a place twice does not merge both passes.
        """
        from scipy.spatial import cKDTree

        n = len(origins)
        ext = float(np.max(np.maximum(np.abs(t_lo), np.abs(t_hi)))) if n else 0.0
        hits = cKDTree(origins).query_ball_point(self.centres, self.radii + ext + 1e-6)
        per_poly = np.fromiter((len(h) for h in hits), dtype=np.int64, count=len(hits))
        pair_poly = np.repeat(np.arange(len(hits)), per_poly)
        pair_line = np.fromiter(chain.from_iterable(hits), dtype=np.int64,
                                count=int(per_poly.sum()))
        near = np.abs(self.tags[pair_poly] - tags[pair_line]) <= _TAG_REACH
        pair_poly, pair_line = pair_poly[near], pair_line[near]
        ne = self.counts[pair_poly]
        pe = np.repeat(np.arange(len(pair_poly)), ne)
        first = np.concatenate(([0], np.cumsum(ne)[:-1]))
        e = self.offsets[:-1][pair_poly][pe] + np.arange(len(pe)) - first[pe]
        r = pair_line[pe]
        ax, ay = self.verts[e, 0] - origins[r, 0], self.verts[e, 1] - origins[r, 1]
        f = self.nxt[e]
        bx, by = self.verts[f, 0] - origins[r, 0], self.verts[f, 1] - origins[r, 1]
        rx, ry = dirs[r, 0], dirs[r, 1]
        da = rx * ay - ry * ax
        db = rx * by - ry * bx
        cr = (da > 0) != (db > 0)
        pe, ax, ay, bx, by, rx, ry, da, db = (v[cr] for v in (pe, ax, ay, bx, by, rx, ry,
                                                             da, db))
        q = da / (da - db)
        t = (ax + q * (bx - ax)) * rx + (ay + q * (by - ay)) * ry
        # each polygon's crossings in order along the line, paired into covered intervals
        order = np.lexsort((t, pe))
        t, pe = t[order], pe[order]
        rank = np.arange(len(pe)) - np.searchsorted(pe, pe, side="left")
        i0 = np.flatnonzero(rank % 2 == 0)
        i0 = i0[i0 + 1 < len(pe)]
        i0 = i0[pe[i0 + 1] == pe[i0]]
        line = pair_line[pe[i0]]
        lo = np.maximum(t[i0], t_lo[line])
        hi = np.minimum(t[i0 + 1], t_hi[line])
        pid = pair_poly[pe[i0]]
        kind = self.kinds[pid]
        pid_lo = np.where((kind == _LANE) & (t[i0] > t_lo[line]), pid, -1)
        pid_hi = np.where((kind == _LANE) & (t[i0 + 1] < t_hi[line]), pid, -1)
        ok = hi > lo
        lo, hi, line, kind, pid_lo, pid_hi = (v[ok] for v in (lo, hi, line, kind, pid_lo,
                                                             pid_hi))
        if reach is not None:
            lane = kind == _LANE
            lane_lo, lane_hi = np.zeros(n), np.zeros(n)
            np.minimum.at(lane_lo, line[lane], lo[lane])
            np.maximum.at(lane_hi, line[lane], hi[lane])
            jn = ~lane
            lo[jn] = np.maximum(lo[jn], lane_lo[line[jn]] - reach)
            hi[jn] = np.minimum(hi[jn], lane_hi[line[jn]] + reach)
            ok = hi > lo
            lo, hi, line, pid_lo, pid_hi = (v[ok] for v in (lo, hi, line, pid_lo, pid_hi))
        order = np.lexsort((lo, line))
        lo, hi, line, pid_lo, pid_hi = (v[order] for v in (lo, hi, line, pid_lo, pid_hi))
        if not len(lo):
            return line, lo, hi, pid_lo, pid_hi
        big = 2.0 * ext + 1.0
        run = np.maximum.accumulate(hi + line * big) - line * big
        new = np.ones(len(lo), dtype=bool)
        new[1:] = (line[1:] != line[:-1]) | (lo[1:] > run[:-1] + _GAP)
        starts = np.flatnonzero(new)
        c_hi = np.maximum.reduceat(hi, starts)
        comp = np.cumsum(new) - 1
        end = hi == c_hi[comp]
        c_pid_hi = np.full(len(starts), -1, dtype=np.int64)
        c_pid_hi[comp[end]] = pid_hi[end]
        return line[starts], lo[starts], c_hi, pid_lo[starts], c_pid_hi

    def covers_segments(self, a: FloatArray, b: FloatArray, tags: IntArray
                        ) -> NDArray[np.bool_]:
        """Whether the region covers each segment ``a -> b`` (``(m, 2)`` each) entirely."""
        d = b - a
        length = np.hypot(*d.T)
        u = d / np.maximum(length, 1e-12)[:, None]
        line, lo, hi, _, _ = self.components(a, u, np.zeros(len(a)), length, tags)
        good = (lo <= _GAP) & (hi >= length[line] - _GAP)
        out = np.zeros(len(a), dtype=bool)
        out[line[good]] = True
        return out | (length < 1e-9)


def _extents(region: _Region, reference: FloatArray, tags: IntArray, *,
             cap: float = MAX_OFFSET
             ) -> tuple[FloatArray, FloatArray, IntArray, IntArray]:
    """Extent [m] of the region left and right of each reference vertex along its sweep line.

    The sweep line at vertex ``i`` is the normal of reference segment ``i`` (of the last
    segment at the last vertex). Along it, the polygons cover intervals (even-odd
    crossings); junction intervals are cut to :data:`JUNCTION_REACH` beyond the lane
    intervals on the same line. The union's connected stretch that holds the reference
    point (the nearest one where none does) gives the extents, at most ``cap``. Also
    returns the lane piece each extent ends on (-1 for none).
    """
    n = len(reference)
    normal = _sweep_normals(reference)
    # the end lines run along the ends of the first and last lane pieces: cast them 5 cm in
    origins = reference.copy()
    origins[0] += 0.05 * np.array([normal[0, 1], -normal[0, 0]])
    origins[-1] -= 0.05 * np.array([normal[-1, 1], -normal[-1, 0]])
    line, c_lo, c_hi, p_lo, p_hi = region.components(
        origins, normal, np.full(n, -cap), np.full(n, cap), tags, reach=JUNCTION_REACH)
    left = np.full(n, np.nan)
    right = np.full(n, np.nan)
    left_piece = np.full(n, -1, dtype=np.int64)
    right_piece = np.full(n, -1, dtype=np.int64)
    if len(line):
        miss = np.maximum(np.maximum(c_lo, -c_hi), 0.0)
        best = np.lexsort((miss, line))
        best = best[np.concatenate(([True], line[best][1:] != line[best][:-1]))]
        left[line[best]], right[line[best]] = c_hi[best], c_lo[best]
        left_piece[line[best]], right_piece[line[best]] = p_hi[best], p_lo[best]
    have = np.isfinite(left)
    if not have.any():
        raise GeometryError("the route's drivable region does not meet its reference line")
    if not have.all():
        s = polyline_stations(reference)
        left = np.interp(s, s[have], left[have])
        right = np.interp(s, s[have], right[have])
    return left, right, left_piece, right_piece


def _sweep_normals(reference: FloatArray) -> FloatArray:
    """Unit left normals ``(n, 2)`` of the sweep lines, as :meth:`Corridor.to_xy` draws them."""
    d = np.diff(reference, axis=0)
    head = np.arctan2(d[:, 1], d[:, 0])
    hv = np.concatenate((head, head[-1:]))
    return np.column_stack((-np.sin(hv), np.cos(hv)))


def _ray_offsets(region: _Region, reference: FloatArray, tags: IntArray,
                 extents: tuple[FloatArray, FloatArray, IntArray, IntArray]
                 ) -> tuple[FloatArray, FloatArray]:
    """Left and right boundary offsets ``(n,)`` [m] by casting sweep lines through a region.

    The ``extents`` of :func:`_extents`, kept within :data:`INNER_RADIUS_FRACTION` of the
    radius of curvature on the inner side of bends, and lowered where the boundary's
    straight chord between two sweep lines would leave the region (at reflex corners).
    """
    n = len(reference)
    left, right = extents[0].copy(), extents[1].copy()
    left_piece, right_piece = extents[2].copy(), extents[3].copy()
    normal = _sweep_normals(reference)
    d = np.diff(reference, axis=0)
    ds = np.hypot(*d.T)
    head = np.arctan2(d[:, 1], d[:, 0])
    # inner side of bends: sweep lines i and i + 1 cross about ds / dtheta from the reference
    dth = np.mod(np.diff(head) + np.pi, 2 * np.pi) - np.pi
    with np.errstate(divide="ignore"):
        radius = INNER_RADIUS_FRACTION * ds[:-1] / np.abs(dth)
    lim_l = np.full(n, np.inf)
    lim_r = np.full(n, np.inf)
    lturn = dth > 0
    for k in (0, 1):
        idx = np.arange(len(dth)) + k
        np.minimum.at(lim_l, idx[lturn], radius[lturn])
        np.minimum.at(lim_r, idx[~lturn], radius[~lturn])
    left_piece[left > lim_l] = -1
    right_piece[right < -lim_r] = -1
    left = np.minimum(left, lim_l)
    right = np.maximum(right, -lim_r)
    # a chord between two points on the boundary of one (convex) lane piece lies in it
    left = _fix_chords(region, reference, normal, left, left_piece, tags)
    right = -_fix_chords(region, reference, -normal, -right, right_piece, tags)
    left, right = left - BOUNDARY_MARGIN, right + BOUNDARY_MARGIN
    thin = left - right < _MIN_WIDTH
    if thin.any():  # a kink of the reference line where the region is narrow
        log.warning("route corridor: %d sweep lines kept %.2f m wide at the reference line",
                    int(thin.sum()), _MIN_WIDTH)
        mid = (left + right) / 2.0
        left = np.where(thin, mid + _MIN_WIDTH / 2.0, left)
        right = np.where(thin, mid - _MIN_WIDTH / 2.0, right)
    return left, right


def _fix_chords(region: _Region, reference: FloatArray, normal: FloatArray,
                offset: FloatArray, piece: IntArray, tags: IntArray, *, rounds: int = 12,
                steps: int = 6) -> FloatArray:
    """Offsets ``(n,)`` [m] along ``normal`` lowered until every chord between neighbouring
    boundary points lies in the region.

    A failing chord's two offsets are lowered together to a common height found by
    bisection between 0 and the lower of them; the neighbouring chords are checked again.
    Chords whose ends lie on the same convex piece (``piece``, -1 for none) are skipped.
    """
    off = offset.copy()
    cells = np.flatnonzero((piece[:-1] != piece[1:]) | (piece[:-1] < 0))
    for _ in range(rounds):
        pts = reference + off[:, None] * normal
        bad = cells[~region.covers_segments(pts[cells], pts[cells + 1], tags[cells])]
        if not len(bad):
            break
        hi = np.minimum(np.maximum(off[bad], 0.0), np.maximum(off[bad + 1], 0.0))
        lo = np.zeros(len(bad))
        a0, a1 = reference[bad], reference[bad + 1]
        n0, n1 = normal[bad], normal[bad + 1]
        for _ in range(steps):
            mid = (lo + hi) / 2.0
            ok = region.covers_segments(a0 + mid[:, None] * n0, a1 + mid[:, None] * n1,
                                        tags[bad])
            lo = np.where(ok, mid, lo)
            hi = np.where(ok, hi, mid)
        np.minimum.at(off, bad, lo)
        np.minimum.at(off, bad + 1, lo)
        cells = np.unique(np.clip(np.concatenate((bad - 1, bad, bad + 1)), 0, len(off) - 2))
    return off


def _lane_polygons(shape: FloatArray, width: float) -> list[FloatArray]:
    """A lane's area as convex pieces: a rectangle per shape segment and, at each bend,
    the wedge of the disc of radius ``width / 2`` on the bend's outer side.
    """
    pts = dedupe_polyline(np.asarray(shape, dtype=float))
    if len(pts) < 2:
        return []
    hw = width / 2.0
    d = np.diff(pts, axis=0)
    u = d / np.hypot(*d.T)[:, None]
    nrm = np.column_stack((-u[:, 1], u[:, 0])) * hw
    a, b = pts[:-1], pts[1:]
    quads = np.stack((a - nrm, b - nrm, b + nrm, a + nrm), axis=1)
    out = list(quads)
    turn = u[:-1, 0] * u[1:, 1] - u[:-1, 1] * u[1:, 0]
    for k in np.flatnonzero(np.abs(turn) > 1e-6):
        side = -1.0 if turn[k] > 0 else 1.0  # outer side of the bend
        a0 = np.arctan2(*(side * nrm[k])[::-1])
        a1 = np.arctan2(*(side * nrm[k + 1])[::-1])
        da = np.mod(a1 - a0 + np.pi, 2 * np.pi) - np.pi
        ang = a0 + da * np.linspace(0.0, 1.0, 4)
        arc = pts[k + 1] + hw * np.column_stack((np.cos(ang), np.sin(ang)))
        out.append(np.concatenate((pts[k + 1][None], arc)))
    return out


def _signed_area(poly: FloatArray) -> float:
    """Signed area [m^2] of a polygon ``(k, 2)`` (positive counter-clockwise)."""
    x, y = poly[:, 0], poly[:, 1]
    return float(np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y) / 2.0)


def _via_shape(network: RoadNetwork, via: tuple[str, ...]) -> FloatArray:
    shapes = [network.internal_lanes[v].shape for v in via]
    return dedupe_polyline(np.concatenate(shapes))


def _band(right_centre: FloatArray, right_width: float, left_centre: FloatArray,
          left_width: float) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Reference line and offsets of the band between two lane centre lines.

    Returns the midline ``(n, 2)`` between the centre lines and the left and right
    offsets ``(n,)`` [m] of the band's outer sides.
    """
    r = dedupe_polyline(right_centre)
    lft = dedupe_polyline(left_centre)
    if len(r) < 2 or len(lft) < 2:
        raise GeometryError("lane shape has fewer than two distinct points")
    if len(r) != len(lft):  # pair points at equal fractions of length, about 1 m apart
        n = max(len(r), len(lft), int(np.ceil(polyline_stations(r)[-1])) + 1)
        r, lft = _resample_fraction(r, n), _resample_fraction(lft, n)
    mid = (r + lft) / 2.0
    half = np.hypot(*(lft - r).T) / 2.0
    return mid, half + left_width / 2.0, -(half + right_width / 2.0)


def _resample_fraction(points: FloatArray, n: int) -> FloatArray:
    """``n`` points at equal fractions of the polyline's arc length."""
    s = polyline_stations(points)
    t = np.linspace(0.0, s[-1], n)
    return np.column_stack((np.interp(t, s, points[:, 0]), np.interp(t, s, points[:, 1])))


# ---- obstacle files -----------------------------------------------------------------------

#: SUMO's default vehicle dimensions [m] (vType ``DEFAULT_VEHTYPE``).
SUMO_DEFAULT_LENGTH = 5.0
SUMO_DEFAULT_WIDTH = 1.8


def read_obstacles(network: RoadNetwork, path: str | Path) -> Obstacles:
    """Static obstacles from a SUMO additional or route file.

    Reads ``<poly>`` elements (their ``shape``; closed or open rings) and vehicles with a
    ``<stop>`` on a lane (``lane`` and ``endPos``; SUMO puts the front bumper at ``endPos``),
    sized by their ``<vType>`` (SUMO's defaults 5.0 x 1.8 m otherwise) and oriented along
    the lane.

    Raises
    ------
    NetworkError
        The file is missing, not XML, or a stop names an unknown lane.
    GeometryError
        A polygon is malformed.
    """
    import xml.etree.ElementTree as ET

    p = Path(path)
    if not p.is_file():
        raise NetworkError(f"obstacle file not found: {p}")
    try:
        root = ET.parse(p).getroot()
    except ET.ParseError as err:
        raise NetworkError(f"cannot read obstacle file {p}: {err}") from err
    polys: list[FloatArray] = []
    ids: list[str] = []
    for el in root.iter("poly"):
        try:
            pts = np.array([[float(v) for v in xy.split(",")[:2]]
                            for xy in el.get("shape", "").split()])
        except ValueError as err:
            raise GeometryError(f"{p}: polygon '{el.get('id')}' has a bad shape") from err
        polys.append(pts)
        ids.append(el.get("id", f"poly{len(ids)}"))
    vtypes = {el.get("id"): el for el in root.iter("vType")}
    lanes = {ln.id: ln for lns in network.lanes for ln in lns}
    pos: list[FloatArray] = []
    head: list[float] = []
    lengths: list[float] = []
    widths: list[float] = []
    vids: list[str] = []
    for veh in root.iter("vehicle"):
        for stop in veh.iter("stop"):
            lane_id = stop.get("lane")
            if lane_id is None:
                continue
            if lane_id not in lanes:
                raise NetworkError(f"{p}: vehicle '{veh.get('id')}' stops on unknown lane "
                                   f"'{lane_id}'")
            lane = lanes[lane_id]
            vt = vtypes.get(veh.get("type", ""))
            length = float(vt.get("length", SUMO_DEFAULT_LENGTH)) if vt is not None \
                else SUMO_DEFAULT_LENGTH
            width = float(vt.get("width", SUMO_DEFAULT_WIDTH)) if vt is not None \
                else SUMO_DEFAULT_WIDTH
            end = float(stop.get("endPos", lane.length))
            xy, h = _lane_point(lane, end)
            pos.append(xy)
            head.append(h)
            lengths.append(length)
            widths.append(width)
            vids.append(veh.get("id", f"vehicle{len(vids)}"))
            break  # a vehicle stands at its first stop
    obstacles = Obstacles.from_polygons(polys, ids) if polys else Obstacles.empty()
    if pos:
        obstacles = obstacles + Obstacles.from_boxes(
            np.array(pos), np.array(head), np.array(lengths), np.array(widths),
            reference="front", ids=vids)
    return obstacles


def _lane_point(lane: Lane, pos: float) -> tuple[FloatArray, float]:
    """Point [m] and heading [rad] at ``pos`` [m] along a lane (scaled to its shape)."""
    shape = lane.shape
    st = polyline_stations(shape)
    u = float(np.clip(pos * st[-1] / lane.length if lane.length > 0 else pos, 0.0, st[-1]))
    i = int(np.clip(np.searchsorted(st, u, side="right") - 1, 0, len(st) - 2))
    d = shape[i + 1] - shape[i]
    t = (u - st[i]) / max(st[i + 1] - st[i], 1e-12)
    return shape[i] + t * d, float(np.arctan2(d[1], d[0]))
