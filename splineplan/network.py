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
    from_junctions
        Per edge, the id of the junction it starts at (empty where unknown).
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
    from_junctions: tuple[str, ...] = ()
    _cache: dict[Any, Any] = field(default_factory=dict, repr=False)

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
    from_junctions = tuple(e.getFromNode().getID() for e in normal)

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
        junction_shapes=junctions, to_junctions=to_junctions,
        from_junctions=from_junctions)


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
#: Where the route turns at a junction by at least :data:`OPPOSITE_MIN_TURN` [rad], the
#: lanes (that the class may use) of the opposite-direction edges of the two route edges
#: on the inner side of the turn count as drivable for this length [m] along them from
#: the junction: the paved corner a car cuts when it turns between narrow streets. Farther
#: along the street the oncoming lanes stay out of the corridor.
OPPOSITE_REACH = 6.0
OPPOSITE_MIN_TURN = np.radians(30.0)
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
# kinds of region parts: a lane, a junction outline, the first or last OPPOSITE_REACH of a lane
_LANE, _JUNCTION, _HEAD, _TAIL = 0, 1, 2, 3
_MIN_WIDTH = 0.05
_TAG_REACH = 2  # a stretch's lines meet its own pieces and those one junction either way


def route_corridor(network: RoadNetwork, route: Any, *, vclass: str | None = None) -> Corridor:
    """The drivable area of a route as a :class:`~splineplan.corridor.Corridor`.

    The drivable region of the route is the union of the lanes of each route edge from its
    rightmost to its leftmost lane that ``vclass`` may use, the junction (internal) lanes
    of the allowed connections between consecutive route edges, and the paved area of each
    junction passed through (SUMO's junction outline) within :data:`JUNCTION_REACH` of
    those junction lanes; where the route turns by at least :data:`OPPOSITE_MIN_TURN`,
    also the first or last :data:`OPPOSITE_REACH` from the junction of the lanes (that
    ``vclass`` may use) of the opposite-direction edges of the two route edges on the inner
    side of the turn, so that a car can turn between narrow streets. The reference line
    joins the midlines of the edges' lanes and of the junction lanes, smoothed more
    strongly through junctions; where the smoothed line
    leaves the region (or comes within :data:`REFERENCE_CLEARANCE` of its edge) it falls
    back, blended in and out, to a less smoothed and at last to the unsmoothed midline.
    The boundary offsets come from casting each sweep line (the normal of the reference
    line at every vertex, as :meth:`Corridor.to_xy` draws it) left and right through the
    region: the boundary is the end of the region's covered stretch that holds the
    reference point, at most :data:`MAX_OFFSET` away, kept within
    :data:`INNER_RADIUS_FRACTION` of the radius of curvature on the inner side of bends,
    lowered where the boundary between two sweep lines would leave the region, and
    :data:`BOUNDARY_MARGIN` inside. Junction stretches count towards the edge before them
    in ``edge_at``. The corridor covers the whole first edge (also when the route starts
    at ``start_pos > 0``). Lane pieces and midlines are cached on the network.

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
    parts: list[tuple[str, int, int]] = []  # (lane id or junction id, kind, tag)
    for i, eid in enumerate(edges):
        ref, lane_ids = _edge_band(network, eid, cls)
        mids.append(ref)
        in_junction.append(False)
        mid_tags.append(2 * i)
        firsts.append(ref[0])
        parts.extend((lid, _LANE, 2 * i) for lid in lane_ids)
        if i + 1 == len(edges):
            break
        jref, via_ids, jid = _junction_band(network, eid, edges[i + 1], cls)
        parts.extend((v, _LANE, 2 * i + 1) for v in via_ids)
        if jid:
            parts.append((jid, _JUNCTION, 2 * i + 1))
        parts.extend(_opposite_parts(network, eid, edges[i + 1], cls, ref, tag=2 * i + 1))
        if jref is not None:
            mids.append(jref)
            in_junction.append(True)
            mid_tags.append(2 * i + 1)
    region = _Region.of(network, parts)
    level = None
    for attempt in range(REFERENCE_ATTEMPTS):
        # where the smoothed reference line leaves the region (or nearly), smooth less there
        reference, level, ref_tags = _reference_line(mids, in_junction, mid_tags, level)
        if not level.any() or attempt + 1 == REFERENCE_ATTEMPTS:
            break
        nrm = REFERENCE_CLEARANCE * _sweep_normals(reference)
        bad = ~region.covers_segments(reference - nrm, reference + nrm, ref_tags,
                                      along=True)
        if not bad.any():
            break
        idx = np.flatnonzero(bad) * (len(level) - 1) // max(len(reference) - 1, 1)
        near = np.zeros(len(level), dtype=bool)
        near[idx] = True
        near = np.convolve(near, np.ones(17), mode="same") > 0  # +-4 m
        # the last attempt takes the unsmoothed midline where the line still fails
        step = 1.0 if attempt + 2 < REFERENCE_ATTEMPTS else 2.0
        level = np.where(near, np.maximum(level - step, 0.0), level)
    left, right = _ray_offsets(region, reference, ref_tags,
                               _extents(region, reference, ref_tags))
    s = polyline_stations(reference)
    probe = Corridor(reference, s, left, right)
    starts_s = probe.to_sl(np.array(firsts))[:, 0]
    starts_s[0] = 0.0
    starts_s = np.maximum.accumulate(np.clip(starts_s, 0.0, probe.length))
    return Corridor(reference, s, left, right, edges, starts_s)


def _edge_band(network: RoadNetwork, eid: str, vclass: str
               ) -> tuple[FloatArray, tuple[str, ...]]:
    """Midline ``(n, 2)`` [m] of an edge's lanes that ``vclass`` may use and the ids of the
    lanes from the rightmost to the leftmost of them (cached on the network)."""
    key = ("band", eid, vclass)
    hit = network._cache.get(key)
    if hit is None:
        all_lanes = network.lanes_of(eid)
        lanes = [ln for ln in all_lanes if ln.allows(vclass)]
        if not lanes:
            raise GeometryError(f"vehicle class '{vclass}' may use no lane of edge '{eid}'")
        ref, _, _ = _band(lanes[0].shape, lanes[0].width, lanes[-1].shape, lanes[-1].width)
        ref.setflags(write=False)
        ids = tuple(ln.id for ln in all_lanes[lanes[0].index:lanes[-1].index + 1])
        hit = network._cache[key] = (ref, ids)
    return hit  # type: ignore[no-any-return]


def _opposite_parts(network: RoadNetwork, eid: str, nxt: str, vclass: str,
                    ref: FloatArray, *, tag: int) -> list[tuple[str, int, int]]:
    """Region parts of the opposite-direction lanes at the junction from ``eid`` (midline
    ``ref``) to ``nxt``: where the route turns there by at least
    :data:`OPPOSITE_MIN_TURN`, the lanes ``vclass`` may use of the edges that run back
    along ``eid`` and ``nxt`` and lie on the inner side of the turn, cut to
    :data:`OPPOSITE_REACH` from the junction (as ``(lane id, _HEAD or _TAIL, tag)``)."""
    if not network.from_junctions:
        return []
    nref, _ = _edge_band(network, nxt, vclass)
    d_in, d_out = ref[-1] - ref[-2], nref[1] - nref[0]
    turn = float(np.arctan2(d_in[0] * d_out[1] - d_in[1] * d_out[0], d_in @ d_out))
    if abs(turn) < OPPOSITE_MIN_TURN:
        return []
    by_ends = network._cache.get("by_ends")
    if by_ends is None:
        by_ends = network._cache["by_ends"] = {}
        for o, fj_tj in enumerate(zip(network.from_junctions, network.to_junctions,
                                      strict=True)):
            by_ends.setdefault(fj_tj, []).append(o)
    i, j = network.edge_index(eid), network.edge_index(nxt)
    out: list[tuple[str, int, int]] = []
    # the edge back along eid starts at the junction, the one back along nxt ends there
    for k, kind, at, d in ((i, _HEAD, ref[-1], d_in), (j, _TAIL, nref[0], d_out)):
        for o in by_ends.get((network.to_junctions[k], network.from_junctions[k]), ()):
            if o in (i, j):
                continue
            lanes = [ln for ln in network.lanes[o] if ln.allows(vclass) and len(ln.shape) > 1]
            for ln in lanes:
                p = ln.shape[0] if kind == _HEAD else ln.shape[-1]
                side = d[0] * (p[1] - at[1]) - d[1] * (p[0] - at[0])
                if side * turn > 0:  # on the inner side of the turn
                    out.append((ln.id, kind, tag))
    return out


def _junction_band(network: RoadNetwork, eid: str, nxt: str, vclass: str
                   ) -> tuple[FloatArray | None, tuple[str, ...], str]:
    """Midline ``(n, 2)`` [m] of the junction lanes from ``eid`` to ``nxt`` (None where
    there are none), their ids, and the id of the junction whose outline counts (or ``''``);
    cached on the network."""
    key = ("junction", eid, nxt, vclass)
    hit = network._cache.get(key)
    if hit is None:
        conns = [c for c in network.connections_between(eid, nxt, vclass=vclass) if c.via]
        via_ids = tuple(dict.fromkeys(v for c in conns for v in c.via))
        jid = network.to_junctions[network.edge_index(eid)] if network.to_junctions else ""
        outline = network.junction_shapes.get(jid)
        if outline is None or abs(_signed_area(outline)) <= 1e-6:
            jid = ""
        ref = None
        if conns:
            conns.sort(key=lambda c: (c.from_lane, c.to_lane))
            rshape = _via_shape(network, conns[0].via)
            lshape = _via_shape(network, conns[-1].via)
            if len(rshape) >= 2 and len(lshape) >= 2:
                rw = network.internal_lanes[conns[0].via[0]].width
                lw = network.internal_lanes[conns[-1].via[0]].width
                ref = _band(rshape, rw, lshape, lw)[0]
                ref.setflags(write=False)
        hit = network._cache[key] = (ref, via_ids, jid)
    return hit  # type: ignore[no-any-return]


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
    # of two coinciding vertices keep the later: a segment takes the tag of its start
    keep = np.concatenate((np.hypot(*np.diff(pts, axis=0).T) > 1e-9, [True]))
    pts, flag, vtag = pts[keep], flag[keep], vtag[keep]
    if len(pts) < 2:
        raise GeometryError("route has a reference line of zero length")
    st = polyline_stations(pts)
    ref = resample_polyline(pts, 0.5)
    t = np.linspace(0.0, st[-1], len(ref))
    if len(ref) < 5:
        return ref, np.zeros(len(ref)), _tags_at(st, vtag, t)
    step = st[-1] / (len(ref) - 1)
    if level is None:
        mask = np.zeros(len(ref))
        runs = np.flatnonzero(np.diff(np.concatenate(([0], flag.astype(int), [0]))))
        for a, b in zip(runs[::2], runs[1::2], strict=True):
            lo, hi = st[a] - JUNCTION_APPROACH, st[b - 1] + JUNCTION_APPROACH
            mask[(t >= lo) & (t <= hi)] = 1.0
        level = 1.0 + np.clip(gaussian_filter1d(mask, 2.0 / step, mode="nearest"), 0.0, 1.0)
    lv = gaussian_filter1d(level, 1.0 / step, mode="nearest")[:, None]
    weak = gaussian_filter1d(ref, REFERENCE_SMOOTHING / step, axis=0, mode="nearest")
    out = ref + np.clip(lv, 0.0, 1.0) * (weak - ref)
    if np.any(lv > 1.0):
        strong = gaussian_filter1d(ref, JUNCTION_SMOOTHING / step, axis=0, mode="nearest")
        out += np.clip(lv - 1.0, 0.0, 1.0) * (strong - weak)
    out[0], out[-1] = ref[0], ref[-1]
    # smoothing cuts corners: carry each point's tag through it, not its station
    ref_tags = _tags_at(st, vtag, t)
    so = polyline_stations(out)
    res = resample_polyline(out, 0.5)
    u = np.linspace(0.0, so[-1], len(res))
    i = np.clip(np.searchsorted(so, u, side="right") - 1, 0, len(so) - 2)
    frac = (u - so[i]) / np.maximum(so[i + 1] - so[i], 1e-12)
    return res, level, ref_tags[i + (frac > 0.5)]


def _tags_at(stations: FloatArray, tags: IntArray, at: FloatArray) -> IntArray:
    """Tag of the vertex at or before each station ``at`` [m]."""
    i = np.clip(np.searchsorted(stations, at, side="right") - 1, 0, len(tags) - 1)
    return np.asarray(tags[i], dtype=np.int64)


#: Longest lane piece [m]: longer straight lane stretches are cut, so that a spatial grid
#: culls the pieces a sweep line can meet.
_PIECE_LENGTH = 8.0
#: Cell size [m] of the grid over a route's pieces.
_CELL = 8.0
#: Longest stretch [m] of a ray that counts as a closed gap where it runs nearly along
#: the edges of two pieces (see :meth:`_Region.components`).
_MAX_GAP_ALONG = 0.25
#: A boundary chord between two sweep lines counts as inside the region where it is once
#: moved this far [m] towards the reference line.
_CHORD_TOLERANCE = 0.01


def _lane_pieces(network: RoadNetwork, lane_id: str, kind: int = _LANE
                 ) -> tuple[FloatArray, IntArray, IntArray]:
    """A lane's area as convex pieces (cached on the network); with ``kind`` ``_HEAD`` or
    ``_TAIL`` only its first or last :data:`OPPOSITE_REACH` along its centre line.

    Returns the pieces' vertices concatenated ``(v, 2)`` [m], their vertex counts ``(p,)``
    and, per piece, the index of the convex part of the lane it is cut from ``(p,)``.
    """
    key = ("pieces", lane_id, kind)
    hit = network._cache.get(key)
    if hit is None:
        lane = network.internal_lanes.get(lane_id)
        if lane is None:
            edge = lane_id.rsplit("_", 1)[0]
            lane = next(ln for ln in network.lanes_of(edge) if ln.id == lane_id)
        shape = np.asarray(lane.shape, dtype=float)
        if kind in (_HEAD, _TAIL):
            shape = _cut_polyline(shape if kind == _HEAD else shape[::-1], OPPOSITE_REACH)
        hit = _convex_pieces(shape, lane.width)
        for a in hit:
            a.setflags(write=False)
        network._cache[key] = hit
    return hit  # type: ignore[no-any-return]


def _cut_polyline(points: FloatArray, length: float) -> FloatArray:
    """The first ``length`` [m] of a polyline ``(n, 2)``."""
    st = polyline_stations(points)
    if st[-1] <= length:
        return points
    k = int(np.searchsorted(st, length))
    f = (length - st[k - 1]) / max(st[k] - st[k - 1], 1e-12)
    end = points[k - 1] + f * (points[k] - points[k - 1])
    return np.concatenate((points[:k], end[None]))


def _convex_pieces(shape: FloatArray, width: float) -> tuple[FloatArray, IntArray, IntArray]:
    """A lane's area as convex pieces: a rectangle per shape segment (cut into pieces of at
    most :data:`_PIECE_LENGTH`) and, at each bend, the wedge of the disc of radius
    ``width / 2`` on the bend's outer side. Returns vertices ``(v, 2)`` [m], vertex counts
    ``(p,)`` and the convex part each piece is cut from ``(p,)``.
    """
    pts = dedupe_polyline(np.asarray(shape, dtype=float))
    if len(pts) < 2:
        z = np.zeros(0, dtype=np.int64)
        return np.zeros((0, 2)), z, z
    hw = width / 2.0
    d = np.diff(pts, axis=0)
    length = np.hypot(*d.T)
    u = d / length[:, None]
    nrm = np.column_stack((-u[:, 1], u[:, 0])) * hw
    cuts = np.maximum(np.ceil(length / _PIECE_LENGTH), 1).astype(np.int64)
    seg = np.repeat(np.arange(len(d)), cuts)
    k = np.arange(len(seg)) - np.repeat(np.cumsum(cuts) - cuts, cuts)
    a = pts[seg] + d[seg] * (k / cuts[seg])[:, None]
    b = pts[seg] + d[seg] * ((k + 1) / cuts[seg])[:, None]
    n = nrm[seg]
    quads = np.stack((a - n, b - n, b + n, a + n), axis=1).reshape(-1, 2)
    turn = u[:-1, 0] * u[1:, 1] - u[:-1, 1] * u[1:, 0]
    bends = np.flatnonzero(np.abs(turn) > 1e-6)
    side = np.where(turn[bends] > 0, -1.0, 1.0)[:, None]  # outer side of the bend
    n0, n1 = side * nrm[bends], side * nrm[bends + 1]
    a0 = np.arctan2(n0[:, 1], n0[:, 0])
    a1 = np.arctan2(n1[:, 1], n1[:, 0])
    da = np.mod(a1 - a0 + np.pi, 2 * np.pi) - np.pi
    ang = a0[:, None] + da[:, None] * np.linspace(0.0, 1.0, 4)[None]
    arc = pts[bends + 1][:, None] + hw * np.stack((np.cos(ang), np.sin(ang)), axis=2)
    wedges = np.concatenate((pts[bends + 1][:, None], arc), axis=1).reshape(-1, 2)
    verts = np.concatenate((quads, wedges))
    counts = np.concatenate((np.full(len(seg), 4), np.full(len(bends), 5))).astype(np.int64)
    part = np.concatenate((seg, len(d) + np.arange(len(bends)))).astype(np.int64)
    return verts, counts, part


class _Region:
    """A union of polygons (convex lane pieces and junction outlines) prepared for line
    queries through a uniform grid over their bounding boxes."""

    def __init__(self, verts: FloatArray, counts: IntArray, kinds: IntArray, tags: IntArray,
                 parts: IntArray) -> None:
        if not len(counts):
            raise GeometryError("route has no drivable area")
        self.verts = verts
        self.counts = counts
        self.offsets = np.concatenate(([0], np.cumsum(counts)))
        self.nxt = np.arange(len(verts)) + 1
        self.nxt[self.offsets[1:] - 1] = self.offsets[:-1]
        self.edge_len = np.hypot(*(verts[self.nxt] - verts).T)
        self.lo = np.minimum.reduceat(verts, self.offsets[:-1], axis=0)
        self.hi = np.maximum.reduceat(verts, self.offsets[:-1], axis=0)
        self.kinds = kinds
        self.tags = tags
        self.parts = parts  # convex part of a lane each piece belongs to (-1: junction)
        self._grids: dict[float, tuple[IntArray, IntArray, IntArray]] = {}

    @classmethod
    def of(cls, network: RoadNetwork, parts: list[tuple[str, int, int]]) -> _Region:
        """The region of ``(lane or junction id, kind, tag)`` parts of a route."""
        verts: list[FloatArray] = []
        counts: list[IntArray] = []
        kinds: list[IntArray] = []
        tags: list[IntArray] = []
        owner: list[IntArray] = []
        base = 0
        for pid, kind, tag in parts:
            if kind != _JUNCTION:
                v, c, p = _lane_pieces(network, pid, kind)
                owner.append(p + base)
                base += int(p.max()) + 1 if len(p) else 0
            else:
                v = network.junction_shapes[pid]
                c = np.array([len(v)], dtype=np.int64)
                owner.append(np.array([-1], dtype=np.int64))
            verts.append(v)
            counts.append(c)
            kinds.append(np.full(len(c), kind, dtype=np.int64))
            tags.append(np.full(len(c), tag, dtype=np.int64))
        if not verts:
            raise GeometryError("route has no drivable area")
        return cls(np.concatenate(verts), np.concatenate(counts), np.concatenate(kinds),
                   np.concatenate(tags), np.concatenate(owner))

    def _grid(self, reach: float) -> tuple[IntArray, IntArray, IntArray]:
        """Cell keys (sorted, unique), CSR starts and pieces of a grid in which each piece
        is listed in every cell its bounding box grown by ``reach`` [m] overlaps."""
        g = self._grids.get(reach)
        if g is None:
            c0 = np.floor((self.lo - reach) / _CELL).astype(np.int64)
            c1 = np.floor((self.hi + reach) / _CELL).astype(np.int64)
            nx, ny = c1[:, 0] - c0[:, 0] + 1, c1[:, 1] - c0[:, 1] + 1
            cnt = nx * ny
            piece = np.repeat(np.arange(len(cnt)), cnt)
            k = np.arange(len(piece)) - np.repeat(np.cumsum(cnt) - cnt, cnt)
            cx = c0[piece, 0] + k % nx[piece]
            cy = c0[piece, 1] + k // nx[piece]
            key = _cell_key(cx, cy)
            order = np.argsort(key, kind="stable")
            key, piece = key[order], piece[order]
            first = np.concatenate(([True], key[1:] != key[:-1]))
            ukeys = key[first]
            starts = np.concatenate((np.flatnonzero(first), [len(key)]))
            g = self._grids[reach] = (ukeys, starts, piece)
        return g

    def _pairs(self, a: FloatArray, b: FloatArray, tags: IntArray
               ) -> tuple[IntArray, IntArray]:
        """(line, piece) pairs whose bounding boxes overlap, segments ``a -> b`` ``(n, 2)``."""
        mid = (a + b) / 2.0
        half = float(np.max(np.abs(b - a))) / 2.0 if len(a) else 0.0
        reach = float(np.ceil(half + 1e-6))
        ukeys, starts, piece = self._grid(reach)
        key = _cell_key(*np.floor(mid / _CELL).astype(np.int64).T)
        pos = np.clip(np.searchsorted(ukeys, key), 0, len(ukeys) - 1)
        found = ukeys[pos] == key
        c_lo = np.where(found, starts[pos], 0)
        cnt = np.where(found, starts[pos + 1] - starts[pos], 0)
        line = np.repeat(np.arange(len(a)), cnt)
        k = np.arange(len(line)) - np.repeat(np.cumsum(cnt) - cnt, cnt)
        poly = piece[c_lo[line] + k]
        lo = np.minimum(a, b) - 1e-9
        hi = np.maximum(a, b) + 1e-9
        keep = np.abs(self.tags[poly] - tags[line]) <= _TAG_REACH
        keep &= lo[line, 0] <= self.hi[poly, 0]
        keep &= lo[line, 1] <= self.hi[poly, 1]
        keep &= hi[line, 0] >= self.lo[poly, 0]
        keep &= hi[line, 1] >= self.lo[poly, 1]
        return line[keep], poly[keep]

    def components(self, origins: FloatArray, dirs: FloatArray, t_lo: FloatArray,
                   t_hi: FloatArray, tags: IntArray, *, reach: float | None = None,
                   along: bool = False
                   ) -> tuple[IntArray, FloatArray, FloatArray, IntArray, IntArray]:
        """Covered stretches of lines ``origins + t * dirs`` (unit ``dirs``), ``t_lo <= t <= t_hi``.

        Returns line index, start and end [m] of each connected covered stretch, sorted by
        line, then start, and the convex lane part whose boundary each stretch starts and
        ends on (-1 where it ends on a junction outline or a limit). Gaps along a line
        under :data:`_GAP` count as closed; with ``along``, also longer ones (up to
        :data:`_MAX_GAP_ALONG`) that are under :data:`_GAP` across, measured normal to the
        pieces' edges, so that a ray that runs nearly along two pieces' common side does
        not stop there. With ``reach``, junction outlines cover only within ``reach`` beyond
        the lane pieces on the same line. A line meets only the polygons whose tag (the
        route stretch they belong to) is within :data:`_TAG_REACH` of its own ``tags``, so
        that a route that passes a place twice does not merge both passes.
        """
        n = len(origins)
        z = np.zeros(0, dtype=np.int64)
        if not n:
            return z, np.zeros(0), np.zeros(0), z, z
        ext = float(np.max(np.maximum(np.abs(t_lo), np.abs(t_hi))))
        pair_line, pair_poly = self._pairs(origins + t_lo[:, None] * dirs,
                                           origins + t_hi[:, None] * dirs, tags)
        ne = self.counts[pair_poly]
        pe = np.repeat(np.arange(len(pair_poly)), ne)
        e = np.arange(len(pe)) - np.repeat(np.cumsum(ne) - ne, ne) + self.offsets[pair_poly][pe]
        r = pair_line[pe]
        ox, oy, rx, ry = origins[r, 0], origins[r, 1], dirs[r, 0], dirs[r, 1]
        f = self.nxt[e]
        ax, ay = self.verts[e, 0] - ox, self.verts[e, 1] - oy
        bx, by = self.verts[f, 0] - ox, self.verts[f, 1] - oy
        da = rx * ay - ry * ax
        db = rx * by - ry * bx
        cr = np.flatnonzero((da > 0) != (db > 0))
        pe, e, da, db = pe[cr], e[cr], da[cr], db[cr]
        ax, ay, bx, by, rx, ry = ax[cr], ay[cr], bx[cr], by[cr], rx[cr], ry[cr]
        q = da / (da - db)
        t = (ax + q * (bx - ax)) * rx + (ay + q * (by - ay)) * ry
        sin = np.abs(da - db) / np.maximum(self.edge_len[e], 1e-12)
        # each polygon's crossings in order along the line, paired into covered intervals;
        # crossings come grouped by pair, convex pieces with two of them
        nc = np.bincount(pe, minlength=len(pair_poly))
        first = np.concatenate(([0], np.cumsum(nc)[:-1]))
        two = np.flatnonzero(nc == 2)
        i0 = first[two]
        swap = i0[t[i0] > t[i0 + 1]]
        for v in (t, sin):
            v[swap], v[swap + 1] = v[swap + 1], v[swap].copy()
        many = nc > 2
        if many.any():  # junction outlines: sort their crossings
            sub = np.flatnonzero(many[pe])
            order = sub[np.lexsort((t[sub], pe[sub]))]
            t[sub], sin[sub] = t[order], sin[order]
            rank = np.arange(len(pe)) - first[pe]
            extra = sub[(rank[sub] % 2 == 0) & (rank[sub] + 1 < nc[pe[sub]])]
            i0 = np.sort(np.concatenate((i0, extra)))
        line = pair_line[pe[i0]]
        lo = np.maximum(t[i0], t_lo[line])
        hi = np.minimum(t[i0 + 1], t_hi[line])
        s_lo, s_hi = sin[i0], sin[i0 + 1]
        pid = pair_poly[pe[i0]]
        kind = self.kinds[pid]
        part = self.parts[pid]
        pid_lo = np.where((kind != _JUNCTION) & (t[i0] > t_lo[line]), part, -1)
        pid_hi = np.where((kind != _JUNCTION) & (t[i0 + 1] < t_hi[line]), part, -1)
        ok = hi > lo
        lo, hi, line, kind, pid_lo, pid_hi, s_lo, s_hi = (
            v[ok] for v in (lo, hi, line, kind, pid_lo, pid_hi, s_lo, s_hi))
        if reach is not None:
            lane = kind == _LANE
            lane_lo, lane_hi = np.zeros(n), np.zeros(n)
            np.minimum.at(lane_lo, line[lane], lo[lane])
            np.maximum.at(lane_hi, line[lane], hi[lane])
            jn = kind == _JUNCTION
            lo[jn] = np.maximum(lo[jn], lane_lo[line[jn]] - reach)
            hi[jn] = np.minimum(hi[jn], lane_hi[line[jn]] + reach)
            ok = hi > lo
            lo, hi, line, pid_lo, pid_hi, s_lo, s_hi = (
                v[ok] for v in (lo, hi, line, pid_lo, pid_hi, s_lo, s_hi))
        if not len(lo):
            return line, lo, hi, pid_lo, pid_hi
        big = 2.0 * ext + 1.0
        order = np.argsort(line * big + lo, kind="stable")
        lo, hi, line, pid_lo, pid_hi, s_lo, s_hi = (
            v[order] for v in (lo, hi, line, pid_lo, pid_hi, s_lo, s_hi))
        run = np.maximum.accumulate(hi + line * big) - line * big
        gap: FloatArray | float = _GAP
        if along:
            gap = np.clip(_GAP / np.maximum(np.maximum(s_lo[1:], s_hi[:-1]), 1e-3),
                          _GAP, _MAX_GAP_ALONG)
        new = np.ones(len(lo), dtype=bool)
        new[1:] = (line[1:] != line[:-1]) | (lo[1:] > run[:-1] + gap)
        starts = np.flatnonzero(new)
        c_hi = np.maximum.reduceat(hi, starts)
        comp = np.cumsum(new) - 1
        end = hi == c_hi[comp]
        c_pid_hi = np.full(len(starts), -1, dtype=np.int64)
        c_pid_hi[comp[end]] = pid_hi[end]
        return line[starts], lo[starts], c_hi, pid_lo[starts], c_pid_hi

    def covers_segments(self, a: FloatArray, b: FloatArray, tags: IntArray, *,
                        along: bool = False) -> NDArray[np.bool_]:
        """Whether the region covers each segment ``a -> b`` (``(m, 2)`` each) entirely
        (``along`` as in :meth:`components`)."""
        d = b - a
        length = np.hypot(*d.T)
        u = d / np.maximum(length, 1e-12)[:, None]
        line, lo, hi, _, _ = self.components(a, u, np.zeros(len(a)), length, tags,
                                             along=along)
        good = (lo <= _GAP) & (hi >= length[line] - _GAP)
        out = np.zeros(len(a), dtype=bool)
        out[line[good]] = True
        return out | (length < 1e-9)


def _cell_key(cx: IntArray, cy: IntArray) -> IntArray:
    """One integer per grid cell."""
    return np.asarray((cx + (1 << 30)) * (1 << 31) + (cy + (1 << 30)), dtype=np.int64)


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
        origins, normal, np.full(n, -cap), np.full(n, cap), tags, reach=JUNCTION_REACH,
        along=True)
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
                levels: int = 8, refine: int = 8) -> FloatArray:
    """Offsets ``(n,)`` [m] along ``normal`` lowered until every chord between neighbouring
    boundary points lies in the region.

    Chords are checked moved in by :data:`_CHORD_TOLERANCE` (the ends of those that
    leave the region by less are moved in by as much at the end). A failing chord keeps
    its lower end where lowering the higher end (in ``levels``
    steps, down to the lower end's height) makes it lie in the region; otherwise both
    ends come down together to the highest of ``levels`` common heights between 0 and the
    lower end at which it does; then ``refine`` steps towards the next higher candidate
    sharpen the choice. The neighbouring chords are checked again. Chords whose
    ends lie on the same convex lane part (``piece``, -1 for none) are skipped.
    """
    off = offset.copy()
    cells = np.flatnonzero((piece[:-1] != piece[1:]) | (piece[:-1] < 0))
    checked = cells
    frac = np.arange(levels) / levels
    done = np.zeros(len(off), dtype=bool)
    for _ in range(rounds):
        if not len(cells):
            break
        pts = reference + np.maximum(off - _CHORD_TOLERANCE, 0.0)[:, None] * normal
        bad = cells[~region.covers_segments(pts[cells], pts[cells + 1], tags[cells])]
        if not len(bad):
            break
        o0 = np.maximum(off[bad], 0.0)
        o1 = np.maximum(off[bad + 1], 0.0)
        low = np.minimum(o0, o1)
        # candidates per chord: the higher end lowered, then both ends together
        h_hi = low[:, None] + (np.maximum(o0, o1) - low)[:, None] * frac[None]
        h0 = np.concatenate((np.where((o0 > o1)[:, None], h_hi, low[:, None]),
                             low[:, None] * frac[None]), axis=1)
        h1 = np.concatenate((np.where((o0 > o1)[:, None], low[:, None], h_hi),
                             low[:, None] * frac[None]), axis=1)
        m = len(bad)
        rep = np.repeat(bad, 2 * levels)
        g0 = np.maximum(h0.reshape(-1, 1) - _CHORD_TOLERANCE, 0.0)
        g1 = np.maximum(h1.reshape(-1, 1) - _CHORD_TOLERANCE, 0.0)
        ok = region.covers_segments(reference[rep] + g0 * normal[rep],
                                    reference[rep + 1] + g1 * normal[rep + 1],
                                    tags[rep]).reshape(m, 2 * levels)
        ok[:, levels] = True  # the reference line itself (both at 0) as the last resort
        h0 = np.concatenate((h0[:, :levels][:, ::-1], h0[:, levels:][:, ::-1]), axis=1)
        h1 = np.concatenate((h1[:, :levels][:, ::-1], h1[:, levels:][:, ::-1]), axis=1)
        ok = np.concatenate((ok[:, :levels][:, ::-1], ok[:, levels:][:, ::-1]), axis=1)
        pick = np.argmax(ok, axis=1)
        rows = np.arange(m)
        lo0, lo1 = h0[rows, pick], h1[rows, pick]
        up0 = np.where(pick > 0, h0[rows, pick - 1], o0)
        up1 = np.where(pick > 0, h1[rows, pick - 1], o1)
        # refine between the chosen candidate and the next higher one
        w = np.arange(refine, 0, -1) / (refine + 1.0)
        f0 = lo0[:, None] + (up0 - lo0)[:, None] * w[None]
        f1 = lo1[:, None] + (up1 - lo1)[:, None] * w[None]
        rep = np.repeat(bad, refine)
        fine = region.covers_segments(
            reference[rep] + np.maximum(f0.reshape(-1, 1) - _CHORD_TOLERANCE, 0.0)
            * normal[rep],
            reference[rep + 1] + np.maximum(f1.reshape(-1, 1) - _CHORD_TOLERANCE, 0.0)
            * normal[rep + 1], tags[rep]).reshape(m, refine)
        got = fine.any(axis=1)
        sel = np.argmax(fine, axis=1)
        lo0 = np.where(got, f0[rows, sel], lo0)
        lo1 = np.where(got, f1[rows, sel], lo1)
        np.minimum.at(off, bad, lo0)
        np.minimum.at(off, bad + 1, lo1)
        done[bad[pick == 2 * levels - 1]] = True  # down to the reference line: final
        cells = np.unique(np.clip(np.concatenate((bad - 1, bad, bad + 1)), 0, len(off) - 2))
        cells = cells[~done[cells]]
    # chords were checked moved in by the tolerance: where the chord itself leaves the
    # region, move its ends in by as much
    pts = reference + off[:, None] * normal
    out = checked[~region.covers_segments(pts[checked], pts[checked + 1], tags[checked])]
    off[out] = np.minimum(off[out], np.maximum(off[out] - _CHORD_TOLERANCE, 0.0))
    off[out + 1] = np.minimum(off[out + 1], np.maximum(off[out + 1] - _CHORD_TOLERANCE, 0.0))
    return off


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
