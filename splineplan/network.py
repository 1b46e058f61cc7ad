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

import itertools
import logging
import math
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
from numba import njit
from numpy.typing import NDArray

from splineplan.control_polygon import SMOOTH_CENTRE_WEIGHT, min_turning_offsets, polygon_turns
from splineplan.corridor import UNBOUNDED, Corridor
from splineplan.errors import (
    GeometryError,
    NetworkError,
    ParameterError,
    UnknownEdgeError,
    VehicleClassError,
)
from splineplan.geometry import (
    FloatArray,
    dedupe_polyline,
    kernel_floats,
    kernel_ints,
    polyline_stations,
    resample_polyline,
)
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
    state
        SUMO's link state without a traffic light: ``M`` major, ``m`` minor, ``=`` equal,
        ``s`` stop sign, ``w`` all-way stop, ``o``/``O`` a light switched off (a light's
        links carry its initial state).
    """

    from_edge: str
    to_edge: str
    from_lane: int
    to_lane: int
    via: tuple[str, ...]
    allowed: frozenset[str]
    direction: str
    state: str = ""

    @property
    def internal_junction(self) -> bool:
        """Whether the link has an internal junction: it runs on more than one internal
        lane, and a vehicle may wait inside the junction between them."""
        return len(self.via) > 1


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
    to_nodes
        Per edge, the id of the junction it ends at.
    junction_shapes
        Junction outlines ``(k, 2)`` [m] by junction id (those SUMO draws, with three
        points or more).
    bounds
        ``(xmin, ymin, xmax, ymax)`` [m] of the lane shapes.
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
    to_nodes: tuple[str, ...] = ()
    junction_shapes: dict[str, FloatArray] = field(default_factory=dict)
    _graphs: dict[str, ClassGraph] = field(default_factory=dict, repr=False)
    #: bands of route corridors by the lanes they span (see :func:`route_corridor`)
    _bands: dict[tuple[str, ...], Any] = field(default_factory=dict, repr=False)
    #: the connection over each internal lane (see :meth:`connection_via`)
    _vias: dict[str, Connection] = field(default_factory=dict, repr=False)

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

    def to_node(self, edge_id: str) -> str | None:
        """The junction that normal edge ``edge_id`` ends at; ``None`` where the network
        does not record junctions."""
        return self.to_nodes[self.edge_index(edge_id)] if self.to_nodes else None

    def lanes_of(self, edge_id: str) -> tuple[Lane, ...]:
        """Lanes of a normal edge, rightmost first."""
        return self.lanes[self.edge_index(edge_id)]

    def allowed_lanes(self, edge_id: str, vclass: str) -> tuple[Lane, ...]:
        """The lanes of a normal edge that ``vclass`` may use, rightmost first (a route's
        corridor counts its lanes among these)."""
        return tuple(ln for ln in self.lanes_of(edge_id) if ln.allows(vclass))

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

    def lane(self, lane_id: str) -> Lane:
        """A lane of a normal or internal edge by id."""
        if lane_id.startswith(":"):
            return self.internal_lane(lane_id)
        edge, _, index = lane_id.rpartition("_")
        lanes = self.lanes_of(edge)
        try:
            return next(ln for ln in lanes if ln.index == int(index))
        except (StopIteration, ValueError):
            raise UnknownEdgeError(f"lane '{lane_id}' is not in network "
                                   f"{self.path.name}") from None

    def connection_via(self, internal_lane: str) -> Connection | None:
        """The connection that runs over an internal lane (``None``: none does)."""
        if not self._vias and self.connections:
            for c in self.connections:
                for via in c.via:
                    self._vias.setdefault(via, c)
        return self._vias.get(internal_lane)

    def stop_kind(self, from_edge: str, to_edge: str, vclass: str) -> str:
        """Whether a vehicle of ``vclass`` must come to a full stop before it goes from
        ``from_edge`` to ``to_edge``: ``"s"`` at a stop sign, ``"w"`` at an all-way stop
        (SUMO's link states), ``""`` where it need not."""
        states = {c.state for c in self.connections_between(from_edge, to_edge,
                                                            vclass=vclass)}
        return "w" if "w" in states else "s" if "s" in states else ""

    def dead_end(self, edge_id: str) -> bool:
        """Whether the road ends with edge ``edge_id``: no connection leaves it but
        turnarounds (a dead end's), which a car driving forward cannot take."""
        i = self.edge_index(edge_id)
        lo, hi = np.searchsorted(self._conn_from, [i, i + 1])
        return all(self.connections[k].direction == "t" for k in range(int(lo), int(hi)))

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

    def lane_after(self, from_edge: str, lane: int, to_edge: str, vclass: str, *,
                   via: str | None = None) -> int | None:
        """The lane of ``to_edge`` that lane ``lane`` of ``from_edge`` leads to, as SUMO's
        connections say; lanes counted from the right among those ``vclass`` may use
        (as a route's corridor counts them). ``None`` where no connection joins the edges.

        ``via``: the internal lane a vehicle is on, if it is in the junction already (its
        connection decides). Otherwise the connection from ``lane``, or from the nearest
        lane that has one (the vehicle changes to it before the junction); of several, the
        one to the lane nearest ``lane``'s place.
        """
        conns = self.connections_between(from_edge, to_edge, vclass=vclass)
        if not conns:
            return None
        src = [ln.index for ln in self.allowed_lanes(from_edge, vclass)]
        dst = [ln.index for ln in self.allowed_lanes(to_edge, vclass)]
        if not src or not dst:
            return None
        mine = [c for c in conns if via is not None and via in c.via]
        if not mine:
            here = src[min(max(lane, 0), len(src) - 1)]
            near = min(abs(c.from_lane - here) for c in conns)
            mine = [c for c in conns if abs(c.from_lane - here) == near]
        order = {idx: k for k, idx in enumerate(dst)}
        picks = [order[c.to_lane] for c in mine if c.to_lane in order]
        if not picks:
            return None
        return min(picks, key=lambda k: (abs(k - lane), k))

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
    root = _root_tag(p)  # before sumolib, whose parser leaves the file open on an error
    if root is not None and root != "net":
        raise NetworkError(f"{p} is not a SUMO network: its root element is <{root}>, a "
                           "network's is <net> (netconvert builds one)")
    try:
        # the SAX parser, whether or not lxml is installed (another package may bring it)
        net = sumolib.net.readNet(str(p), withInternal=True, withFoes=False, maxcache=0,
                                  lxml=False)
    except Exception as err:  # sumolib raises whatever its XML parser raises
        why = "it is not XML: " if root is None else ""
        raise NetworkError(f"cannot read SUMO network {p}: {why}{err}".splitlines()[0]) from err
    try:
        return _from_sumolib(p, net)
    except (KeyError, ValueError, IndexError, AttributeError) as err:
        raise NetworkError(f"{p} is not a usable SUMO network: {err}") from err


def _root_tag(path: Path) -> str | None:
    """The root element's name of an XML file (gzipped or not), or ``None`` if it is not
    XML."""
    import gzip
    import xml.etree.ElementTree as ET

    try:
        with (gzip.open(path) if path.suffix == ".gz" else path.open("rb")) as fh:
            for _, el in ET.iterparse(fh, events=("start",)):
                return str(el.tag)
    except (ET.ParseError, OSError, EOFError):
        return None
    return None


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
    to_nodes = tuple(e.getToNode().getID() for e in normal)
    junctions: dict[str, FloatArray] = {}
    for node in net.getNodes():
        outline = np.asarray([pt[:2] for pt in node.getShape()], dtype=float).reshape(-1, 2)
        if len(outline) >= 3:
            outline.setflags(write=False)
            junctions[node.getID()] = outline

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
                    direction=str(c.getDirection()), state=str(c.getState() or "")))
    conns.sort(key=lambda c: (index[c.from_edge], index[c.to_edge], c.from_lane, c.to_lane))
    conn_from = np.array([index[c.from_edge] for c in conns], dtype=np.int64)
    conn_to = np.array([index[c.to_edge] for c in conns], dtype=np.int64)

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
        to_nodes=to_nodes, junction_shapes=junctions, _index=index, _conn_from=conn_from,
        _conn_to=conn_to)


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

def route_corridor(network: RoadNetwork, route: Any, *, vclass: str | None = None,
                   car: CarShape | None = None) -> Corridor:
    """The drivable area of a route as a :class:`~splineplan.corridor.Corridor`.

    On each route edge the area spans from the right side of its rightmost lane that
    ``vclass`` may use to the left side of its leftmost such lane (lanes between them
    count as drivable). Through a junction it spans from those lanes to the allowed lanes
    of the next route edge, each side a kerb curve rounded as SUMO rounds a junction's
    corners (:func:`_junction_band`), so that a turn has the room of both roads and not
    only of one internal lane; where the turn is too sharp for that, it spans the internal
    lanes of the allowed connections, from the rightmost to the leftmost. Either is then
    cut to the junction's paving (SUMO's outline, the lanes beside it and its internal
    lanes) and holds at least the internal lanes of the route's connections
    (:func:`_clip_to_paved`). Over the last
    :data:`APPROACH_LENGTH` metres of each edge but the first, the keep offsets hold the
    vehicle's centre to the lanes that connect to the next route edge (SUMO maps a vehicle
    into the junction, and its signals and right of way hold, only from those). The
    reference line runs midway between the two boundaries. Junction stretches count
    towards the edge before them in ``edge_at``; ``edge_ends`` and ``junction_at`` tell
    them apart. The corridor covers the whole first edge (also when the route starts at
    ``start_pos > 0``).

    Parameters
    ----------
    route
        A :class:`splineplan.route.Route` (anything with ``edges`` and ``vclass``).
    vclass
        Vehicle class; defaults to the route's.
    car
        The car: through a junction turn that it can make only on a path that
        :func:`turn_fits` found by a search (:func:`turn_path`), the corridor's reference
        follows that path, its sides :data:`PATH_ROOM` beyond the car's, cut to the
        paving.
    """
    cls = vclass if vclass is not None else getattr(route, "vclass", "passenger")
    check_vclass(cls)
    edges = tuple(route.edges)
    if not edges:
        raise GeometryError("route has no edges")
    pieces: list[tuple[FloatArray, FloatArray, FloatArray]] = []
    keep: list[tuple[FloatArray, FloatArray, FloatArray]] = []  # lanes to keep to
    keep_edge: list[int] = []  # the route edge of each
    starts: list[int] = []  # index into pieces where each edge's own stretch begins
    for i, eid in enumerate(edges):
        lanes = list(network.allowed_lanes(eid, cls))
        if not lanes:
            raise GeometryError(f"vehicle class '{cls}' may use no lane of edge '{eid}'")
        starts.append(len(pieces))
        conns = ([c for c in network.connections_between(eid, edges[i + 1], vclass=cls)
                  if c.via] if i + 1 < len(edges) else [])
        # the lanes that lead on to the next edge: SUMO maps a vehicle into the junction,
        # and its signals and right of way hold, only from those
        into = {c.from_lane for c in conns}
        src = [ln for ln in lanes if ln.index in into] or lanes
        pieces.append(_edge_band(network, lanes[0], lanes[-1]))
        if i > 0 and (src[0] is not lanes[0] or src[-1] is not lanes[-1]):
            keep.append(_approach_band(src, APPROACH_LENGTH))
            keep_edge.append(i)
        if i + 1 < len(edges):
            if not conns:
                continue  # no internal lanes: the stretches are joined straight
            path = (searched_path(network, eid, edges[i + 1], cls, car)
                    if car is not None else None)
            if path is not None and car is not None:
                half = car.width / 2.0 + PATH_ROOM
                pieces.append((path[:, :2], np.full(len(path), half),
                               np.full(len(path), -half)))
                continue
            dst = list(network.allowed_lanes(edges[i + 1], cls))
            fillet = _cached_junction_band(network, lanes, dst) if dst else None
            if fillet is not None:
                pieces.append(fillet)
                continue
            conns.sort(key=lambda c: (c.from_lane, c.to_lane))
            right, left = conns[0], conns[-1]
            rshape = _via_shape(network, right.via)
            lshape = _via_shape(network, left.via)
            rw = network.internal_lanes[right.via[0]].width
            lw = network.internal_lanes[left.via[0]].width
            if len(rshape) >= 2 and len(lshape) >= 2:
                pieces.append(_band(rshape, rw, lshape, lw))
    pieces, starts = _trim_overlaps(pieces, starts)
    # The reference line is the pieces' midlines joined and smoothed, so that where the
    # drivable width changes (a one-lane junction into a two-lane edge) it bends gently
    # instead of stepping sideways. Each piece's offsets are carried over through its
    # midline (projected onto the reference, plus the band's half widths) rather than by
    # projecting its outer boundaries, which fold on the inner side of tight bends.
    reference = _smooth_polyline(dedupe_polyline(np.concatenate([p[0] for p in pieces])),
                                 REFERENCE_SMOOTHING)
    probe = Corridor.from_reference(reference, np.full(len(reference), 1e3),
                                    np.full(len(reference), -1e3))
    windows = _piece_windows(probe, pieces)
    left_off, right_off = _union_offsets(probe, pieces, windows)
    left_off, right_off = _limit_to_curvature(probe, left_off, right_off)
    own = [windows[k] for k in starts]
    starts_s = _project_each(probe, np.array([pieces[k][0][0] for k in starts]), own)
    starts_s[0] = 0.0
    starts_s = np.maximum.accumulate(np.clip(starts_s, 0.0, probe.length))
    # each edge's own stretch ends where its band's midline ends (a junction follows)
    ends_s = _project_each(probe, np.array([pieces[k][0][-1] for k in starts]), own)
    ends_s = np.clip(ends_s, starts_s, np.append(starts_s[1:], probe.length))
    # each junction's stretch within the paving of it and of the junctions beside it (a
    # short edge between two junctions lies in both stretches), holding its internal lanes;
    # and how far that paving reaches beyond it
    paved_left, paved_right = np.full_like(left_off, -np.inf), np.full_like(right_off, np.inf)
    for i in range(len(edges) - 1):
        _clip_to_paved(probe, left_off, right_off, ends_s[i], starts_s[i + 1],
                       _paving(network, edges[max(i - 1, 0):i + 3], cls),
                       _internal_paving(network, edges[i], edges[i + 1], cls),
                       (paved_left, paved_right))
    paved_left, paved_right = np.maximum(paved_left, left_off), np.minimum(paved_right, right_off)
    keep_left = keep_right = None
    if keep:
        keep_left, keep_right = _union_offsets(probe, keep,
                                               [windows[starts[i]] for i in keep_edge],
                                               fill=False)
        keep_left = np.minimum(keep_left, left_off)
        keep_right = np.maximum(keep_right, right_off)
    return Corridor(probe.reference, probe.s, left_off, right_off, edges, starts_s, 0.0,
                    keep_left, keep_right, ends_s, paved_left, paved_right)


#: Length [m] of the lanes before and after a junction that count as its paving (see
#: :func:`_junction_quads`), and the stations [m] beyond the junction's own stretch over
#: which the corridor is clipped to it.
PAVING_REACH = 12.0
PAVING_PAD = 3.0
#: Gaps [m] between paved pieces along a corridor's normal that count as paved (lanes
#: drawn a few centimetres apart).
PAVING_GAP = 0.3
#: Length [m] by which a lane's ends reach into the junctions (see :func:`_lane_quads`).
PAVING_CAP = 0.5
#: Distance [m] from the reference line within which the paving is searched.
PAVING_RANGE = 30.0
#: Farthest [m] a corridor's paved offsets (:meth:`~splineplan.corridor.Corridor.paved`)
#: reach beyond its sides (of 100 random Monaco routes, 60 were feasible without them, 64
#: with 0.5 m, 70 with 1 m, 69 with 2 m).
PAVED_REACH = 1.0
#: How far [m] the paved offsets keep inside the paving's edge (its pieces are joined
#: across gaps of up to :data:`PAVING_GAP`, and its curved kerbs are polygons).
PAVED_INSET = 0.05


def _paving(network: RoadNetwork, edges: tuple[str, ...], vclass: str
            ) -> tuple[FloatArray, FloatArray, IntArray]:
    """The paving of the junctions between consecutive ``edges`` (see
    :func:`_junction_quads`), as :func:`_packed`; once per network (read-only)."""
    paving: tuple[FloatArray, FloatArray, IntArray] = _kept(
        network, ("paving", *edges, vclass),
        lambda: _packed([q for a, b in itertools.pairwise(edges)
                         for q in _junction_quads(network, a, b, vclass)]))
    return paving


def _internal_paving(network: RoadNetwork, from_edge: str, to_edge: str, vclass: str
                     ) -> tuple[FloatArray, FloatArray, IntArray]:
    """The internal lanes between two edges (see :func:`_internal_quads`), as
    :func:`_packed`; once per network (read-only)."""
    paving: tuple[FloatArray, FloatArray, IntArray] = _kept(
        network, ("internal", from_edge, to_edge, vclass),
        lambda: _packed(_internal_quads(network, from_edge, to_edge, vclass, caps=False)))
    return paving


def _junction_quads(network: RoadNetwork, from_edge: str, to_edge: str, vclass: str
                    ) -> list[FloatArray]:
    """The paving of the junction between two route edges as polygons: SUMO's outline of
    the junction, the last and first :data:`PAVING_REACH` metres of the two edges' allowed
    lanes (see :func:`_lane_quads`) and the internal lanes of the allowed connections
    between them."""
    polys: list[FloatArray] = []
    node = network.to_node(from_edge)
    outline = network.junction_shapes.get(node) if node is not None else None
    if outline is not None:
        polys.append(outline)
    elif node is not None:
        log.warning("junction '%s' (from edge '%s' to edge '%s') has no shape in %s: its "
                    "paving is the lanes and internal lanes alone", node, from_edge, to_edge,
                    network.path.name)
    for ln in network.lanes_of(from_edge):
        if ln.allows(vclass):
            tail = _tail(ln.shape, PAVING_REACH)
            polys += _lane_quads(tail, ln.width, ahead=outline is None)
            polys += _end_cap(tail, ln.width, outline)
    for ln in network.lanes_of(to_edge):
        if ln.allows(vclass):
            head = _tail(ln.shape[::-1], PAVING_REACH)
            polys += _lane_quads(head[::-1], ln.width, back=outline is None)
            polys += _end_cap(head, ln.width, outline)
    return polys + _internal_quads(network, from_edge, to_edge, vclass)


def _end_cap(centre: FloatArray, width: float, outline: FloatArray | None
             ) -> list[FloatArray]:
    """The :data:`PAVING_CAP` by which a lane ending at a junction (``centre`` runs
    towards the junction) reaches into it, cut to the convex hull of the junction's
    outline and the lane's end: it covers the wedge SUMO leaves between a lane's square
    end and an outline that meets it at an angle, and not the ground beside the
    outline. ``[]`` where there is no outline (the lanes' own caps serve)."""
    pts = dedupe_polyline(centre)
    if outline is None or len(pts) < 2 or len(outline) < 3:
        return []
    d = pts[-1] - pts[-2]
    d = d / float(np.hypot(*d))
    n = width / 2.0 * np.array([-d[1], d[0]])
    end = pts[-1]
    cap = np.array([end - n, end + PAVING_CAP * d - n, end + PAVING_CAP * d + n, end + n])
    from scipy.spatial import ConvexHull, QhullError

    cloud = np.vstack((np.asarray(outline, dtype=float), end - n, end + n))
    try:
        hull = cloud[ConvexHull(cloud).vertices]  # counter-clockwise
    except QhullError:
        return []
    out = _clip_convex(cap, hull)
    return [out] if len(out) >= 3 else []


def _clip_convex(poly: FloatArray, hull: FloatArray) -> FloatArray:
    """``poly`` ``(k, 2)`` cut to the convex polygon ``hull`` (counter-clockwise)
    (Sutherland-Hodgman)."""
    out = poly
    for a, b in zip(hull, np.roll(hull, -1, axis=0), strict=True):
        if len(out) == 0:
            break
        e = b - a
        side = e[0] * (out[:, 1] - a[1]) - e[1] * (out[:, 0] - a[0])  # > 0: inside
        nxt: list[FloatArray] = []
        for k in range(len(out)):
            p, q, sp, sq = out[k], out[(k + 1) % len(out)], side[k], side[(k + 1) % len(out)]
            if sp >= 0.0:
                nxt.append(p)
            if (sp >= 0.0) != (sq >= 0.0):
                nxt.append(p + (q - p) * (sp / (sp - sq)))
        out = np.array(nxt).reshape(-1, 2)
    return out


def _internal_quads(network: RoadNetwork, from_edge: str, to_edge: str, vclass: str, *,
                    caps: bool = True) -> list[FloatArray]:
    """The internal lanes of the allowed connections between two edges, as polygons;
    without ``caps``, square at their ends as SUMO draws them (see :func:`_lane_quads`)."""
    return [q for c in network.connections_between(from_edge, to_edge, vclass=vclass)
            for v in c.via
            for q in _lane_quads(network.internal_lanes[v].shape,
                                 network.internal_lanes[v].width, back=caps, ahead=caps)]


def _packed(polys: list[FloatArray]) -> tuple[FloatArray, FloatArray, IntArray]:
    """Polygons (of three points or more) as x ``(v,)``, y ``(v,)`` [m] of their vertices,
    polygon after polygon, and where each starts ``(k + 1,)``: what
    :func:`_paved_spans` takes."""
    polys = [p for p in polys if len(p) >= 3]
    offsets = np.concatenate(([0], np.cumsum([len(p) for p in polys]))).astype(np.int64)
    pts = np.concatenate(polys) if polys else np.zeros((0, 2))
    return kernel_floats(pts[:, 0]), kernel_floats(pts[:, 1]), offsets


def _tail(shape: FloatArray, length: float) -> FloatArray:
    """The last ``length`` [m] of a polyline."""
    pts = dedupe_polyline(shape)
    if len(pts) < 2:
        return pts
    s = polyline_stations(pts)
    if s[-1] <= length:
        return pts
    return _cut_polyline(pts, 1.0 - length / s[-1], 1.0)


def _lane_quads(centre: FloatArray, width: float, *, back: bool = True,
                ahead: bool = True) -> list[FloatArray]:
    """A lane as quadrilaterals ``(4, 2)``, one per segment of its centre line, each
    extended along it to the mitre of the bend at its ends (at most half the width), and
    the lane's ends by :data:`PAVING_CAP` (SUMO's junction outlines and the lanes' ends
    meet at slightly different angles: the sliver between them is paved); not its start
    without ``back``, not its end without ``ahead`` (see :func:`_end_cap`)."""
    pts = dedupe_polyline(centre)
    if len(pts) < 2:
        return []
    d = np.diff(pts, axis=0)
    d /= np.hypot(*d.T)[:, None]
    # the extension at each inner vertex: half the width times tan(turn / 2)
    cos_t = np.clip(np.einsum("ij,ij->i", d[:-1], d[1:]), -1.0, 1.0)
    ext = np.minimum(width / 2.0 * np.tan(np.arccos(cos_t) / 2.0), width / 2.0)
    before = np.concatenate(([PAVING_CAP if back else 0.0], ext))
    after = np.concatenate((ext, [PAVING_CAP if ahead else 0.0]))
    a = pts[:-1] - before[:, None] * d
    b = pts[1:] + after[:, None] * d
    n = width / 2.0 * np.column_stack((-d[:, 1], d[:, 0]))
    return [np.array([a[k] - n[k], b[k] - n[k], b[k] + n[k], a[k] + n[k]])
            for k in range(len(d))]


def _clip_to_paved(probe: Corridor, left: FloatArray, right: FloatArray, s0: float,
                   s1: float, paving: tuple[FloatArray, FloatArray, IntArray],
                   lanes: tuple[FloatArray, FloatArray, IntArray],
                   paved: tuple[FloatArray, FloatArray]) -> None:
    """Offsets ``left``, ``right`` (in place) between stations ``s0`` and ``s1`` [m] (and
    :data:`PAVING_PAD` beyond) cut to the paved stretch of the normal that holds the
    corridor's middle, where one does (the rounded kerbs of a junction band can reach
    beyond SUMO's junction outline), and widened to the stretch of the junction's
    ``lanes`` (its internal lanes, which SUMO's vehicles drive) that holds it. The
    offsets ``paved`` (left, right; in place) widen to that paved stretch, at most
    :data:`PAVED_REACH` beyond the cut offsets."""
    offsets = paving[2]
    if len(offsets) < 2:
        return
    i0 = int(np.searchsorted(probe.s, s0 - PAVING_PAD, side="left"))
    i1 = int(np.searchsorted(probe.s, s1 + PAVING_PAD, side="right"))
    if i1 <= i0:
        return
    # the reference's points and the headings of the segments from them
    cx = kernel_floats(probe.reference[i0:i1, 0])
    cy = kernel_floats(probe.reference[i0:i1, 1])
    h = probe.heading_at(probe.s[i0:i1])
    tx, ty = np.cos(h), np.sin(h)
    mid = (left[i0:i1] + right[i0:i1]) / 2.0
    plo, phi = _paved_spans(cx, cy, tx, ty, mid, *_kernel_polygons(paving), PAVING_GAP)
    pok = np.isfinite(plo)
    lft = np.where(pok, np.minimum(left[i0:i1], phi), left[i0:i1])
    rgt = np.where(pok, np.maximum(right[i0:i1], plo), right[i0:i1])
    if len(lanes[2]) > 1:
        lo, hi = _paved_spans(cx, cy, tx, ty, mid, *_kernel_polygons(lanes), PAVING_GAP)
        ok = np.isfinite(lo)
        lft = np.where(ok, np.maximum(lft, hi), lft)
        rgt = np.where(ok, np.minimum(rgt, lo), rgt)
    left[i0:i1], right[i0:i1] = lft, rgt
    pl, pr = paved[0][i0:i1], paved[1][i0:i1]
    paved[0][i0:i1] = np.where(pok, np.maximum(pl, np.minimum(phi - PAVED_INSET,
                                                              lft + PAVED_REACH)), pl)
    paved[1][i0:i1] = np.where(pok, np.minimum(pr, np.maximum(plo + PAVED_INSET,
                                                              rgt - PAVED_REACH)), pr)


def _kernel_polygons(polys: tuple[FloatArray, FloatArray, IntArray]
                     ) -> tuple[FloatArray, FloatArray, IntArray]:
    """Packed polygons (:func:`_packed`, kept read-only) as :func:`_paved_spans` takes them."""
    return kernel_floats(polys[0]), kernel_floats(polys[1]), kernel_ints(polys[2])


@njit(cache=True)
def _paved_spans(cx: FloatArray, cy: FloatArray, tx: FloatArray, ty: FloatArray,
                 mid: FloatArray, px: FloatArray, py: FloatArray, offsets: IntArray,
                 gap: float) -> tuple[FloatArray, FloatArray]:  # pragma: no cover - compiled
    """Per station (the point ``(cx, cy)``, the road's direction ``(tx, ty)``): the lateral
    offsets [m] of the union of the polygons along the normal (their parts closer than
    ``gap`` joined) that holds offset ``mid``; NaN where none does. Each polygon's part is
    found by the even-odd rule from its edges' crossings of the normal, within
    :data:`PAVING_RANGE` of the station (polygons whose bounding box is farther are
    skipped)."""
    m = len(cx)
    lo = np.full(m, np.nan)
    hi = np.full(m, np.nan)
    n_poly = len(offsets) - 1
    most = 0
    box = np.empty((n_poly, 4))
    for k in range(n_poly):
        most = max(most, offsets[k + 1] - offsets[k])
        v0, v1 = offsets[k], offsets[k + 1]
        box[k, 0], box[k, 1] = px[v0:v1].min(), py[v0:v1].min()
        box[k, 2], box[k, 3] = px[v0:v1].max(), py[v0:v1].max()
    cross = np.empty(most + 1)
    a_s = np.empty(n_poly * (most // 2 + 1))
    b_s = np.empty(n_poly * (most // 2 + 1))
    reach = PAVING_RANGE
    for j in range(m):
        cnt = 0
        # the normal's stretch within reach: its bounding box
        ex, ey = abs(ty[j]) * reach, abs(tx[j]) * reach
        for k in range(n_poly):
            if (box[k, 0] > cx[j] + ex or box[k, 2] < cx[j] - ex
                    or box[k, 1] > cy[j] + ey or box[k, 3] < cy[j] - ey):
                continue
            v0, v1 = offsets[k], offsets[k + 1]
            nc = 0
            for v in range(v0, v1):
                w = v + 1 if v + 1 < v1 else v0
                ua = (px[v] - cx[j]) * tx[j] + (py[v] - cy[j]) * ty[j]
                ub = (px[w] - cx[j]) * tx[j] + (py[w] - cy[j]) * ty[j]
                if (ua > 0.0) != (ub > 0.0):
                    la = (py[v] - cy[j]) * tx[j] - (px[v] - cx[j]) * ty[j]
                    lb = (py[w] - cy[j]) * tx[j] - (px[w] - cx[j]) * ty[j]
                    x = la + (lb - la) * ua / (ua - ub)
                    q = nc  # insertion sort: a few crossings per polygon
                    while q > 0 and cross[q - 1] > x:
                        cross[q] = cross[q - 1]
                        q -= 1
                    cross[q] = x
                    nc += 1
            for q in range(0, nc - 1, 2):
                a_s[cnt], b_s[cnt] = cross[q], cross[q + 1]
                cnt += 1
        if cnt == 0:
            continue
        order = np.argsort(a_s[:cnt])
        ca, cb = a_s[order[0]], b_s[order[0]]
        for q in range(1, cnt + 1):
            if q < cnt and a_s[order[q]] <= cb + gap:
                cb = max(cb, b_s[order[q]])
                continue
            if ca - 1e-9 <= mid[j] <= cb + 1e-9:
                lo[j], hi[j] = ca, cb
                break
            if q < cnt:
                ca, cb = a_s[order[q]], b_s[order[q]]
    return lo, hi


def _kept(network: RoadNetwork, key: tuple[str, ...], make: Callable[[], Any]) -> Any:
    """What ``make()`` builds of the network's geometry, once per network (``key``); its
    arrays read-only, as the corridors of many routes share them."""
    if key not in network._bands:
        value = make()
        for a in value if value is not None else ():
            a.setflags(write=False)
        network._bands[key] = value
    return network._bands[key]


def _edge_band(network: RoadNetwork, right: Lane, left: Lane
               ) -> tuple[FloatArray, FloatArray, FloatArray]:
    """:func:`_band` between two lanes of an edge, once per network (read-only)."""
    band: tuple[FloatArray, FloatArray, FloatArray] = _kept(
        network, ("edge", right.id, left.id),
        lambda: _band(right.shape, right.width, left.shape, left.width))
    return band


def _cached_junction_band(network: RoadNetwork, incoming: list[Lane], outgoing: list[Lane]
                          ) -> tuple[FloatArray, FloatArray, FloatArray] | None:
    """:func:`_junction_band`, once per network and lanes (read-only)."""
    band: tuple[FloatArray, FloatArray, FloatArray] | None = _kept(
        network, ("junction", incoming[0].id, incoming[-1].id, outgoing[0].id,
                  outgoing[-1].id),
        lambda: _junction_band(incoming, outgoing))
    return band


#: Narrowest drivable width [m] a route corridor keeps around its reference line, where
#: the network's lane shapes leave less (shapes that overlap or cross at a join).
MIN_CORRIDOR_WIDTH = 3.0


#: Distance [m] from the line of a piece's end within which the next piece's points behind
#: that end count as an overlap (see :func:`_trim_overlaps`).
TRIM_LATERAL = 5.0


def _trim_overlaps(
    pieces: list[tuple[FloatArray, FloatArray, FloatArray]], starts: list[int],
) -> tuple[list[tuple[FloatArray, FloatArray, FloatArray]], list[int]]:
    """Pieces without the parts that lie behind the end of the piece before them.

    Some networks draw consecutive edges (and the junction lane between them) overlapping:
    the next lane starts metres behind the end of the previous one. Joined as they are,
    the reference line would run backwards there. A piece's points behind the previous
    piece's end (across the normal at its last point) and within :data:`TRIM_LATERAL` of
    its line are dropped, and the piece starts where it crosses that normal; a junction
    piece with fewer than two points left is dropped entirely; an edge's own piece keeps at
    least its last two points. Points behind but farther to the side stay: there the road
    turns back (a hairpin junction), it does not overlap.
    """
    own = set(starts)
    out: list[tuple[FloatArray, FloatArray, FloatArray]] = []
    new_starts: list[int] = []
    for k, (ref, lo, ro) in enumerate(pieces):
        if out:
            prev = out[-1][0]
            end, d = prev[-1], prev[-1] - prev[-2]
            d = d / max(float(np.hypot(*d)), 1e-12)
            # behind the end and beside the previous piece: the overlap; far to the side,
            # a piece that turns back (a hairpin) and keeps its points
            rel = ref - end
            along = rel @ d
            ahead = (along > -0.05) | (np.abs(rel[:, 0] * d[1] - rel[:, 1] * d[0])
                                       > TRIM_LATERAL)
            if ahead.sum() < 2:
                if k not in own:
                    continue
                ahead[-2:] = True
            j = int(np.argmax(ahead))
            if j > 0 and along[j] > -0.05 > along[j - 1]:
                # the piece starts where it crosses the previous end's normal, so that the
                # corridor has no gap to bridge between the two
                f = (-0.05 - along[j - 1]) / (along[j] - along[j - 1])
                ref = np.vstack((ref[j - 1] + f * (ref[j] - ref[j - 1]), ref[ahead]))
                lo = np.concatenate(([lo[j - 1] + f * (lo[j] - lo[j - 1])], lo[ahead]))
                ro = np.concatenate(([ro[j - 1] + f * (ro[j] - ro[j - 1])], ro[ahead]))
            else:
                ref, lo, ro = ref[ahead], lo[ahead], ro[ahead]
        if k in own:
            new_starts.append(len(out))
        out.append((ref, lo, ro))
    return out, new_starts


#: Stations [m] around a piece's place on the reference line within which its points are
#: projected (see :func:`_piece_windows`).
WINDOW_SLACK = 20.0


def _piece_windows(probe: Corridor, pieces: list[tuple[FloatArray, FloatArray, FloatArray]]
                   ) -> list[tuple[float, float]]:
    """Per piece, the stations ``(lo, hi)`` [m] of the reference line it was joined into.

    The reference runs through the pieces' midlines in order, so each piece's place on it
    follows from the midlines' lengths (scaled to the reference's length, which smoothing
    shortens at corners), give or take :data:`WINDOW_SLACK`. A route that passes the same
    place twice (a loop, a road and its return beside it) projects each piece onto its own
    pass, not onto the nearest.
    """
    spans = []
    at = 0.0
    prev_end: FloatArray | None = None
    for ref, _, _ in pieces:
        if prev_end is not None:
            at += float(np.hypot(*(ref[0] - prev_end)))
        length = float(polyline_stations(dedupe_polyline(ref))[-1]) if len(ref) > 1 else 0.0
        spans.append((at, at + length))
        at += length
        prev_end = ref[-1]
    scale = probe.length / max(at, 1e-9)
    return [(scale * a - WINDOW_SLACK, scale * b + WINDOW_SLACK) for a, b in spans]


def _project(probe: Corridor, points: FloatArray, window: tuple[float, float],
             sl: FloatArray | None = None) -> FloatArray:
    """Stations and offsets ``(n, 2)`` of points on the reference line, onto the part of it
    within the station ``window`` where the nearest part lies outside (``sl``: the points'
    projections onto the whole line, if known)."""
    sl = probe.to_sl(points) if sl is None else sl
    lo, hi = max(window[0], 0.0), min(window[1], probe.length)
    if hi - lo < 1.0 or np.all((sl[:, 0] >= lo) & (sl[:, 0] <= hi)):
        return sl
    part = probe.slice(lo, hi)
    out = part.to_sl(points)
    out[:, 0] += part.offset
    return out


def _project_each(probe: Corridor, points: FloatArray, windows: list[tuple[float, float]]
                  ) -> FloatArray:
    """Stations ``(n,)`` [m] of points, each within its own window (see :func:`_project`):
    one query for all, again per point only where the nearest part lies outside."""
    st = probe.to_sl(points)[:, 0]
    for k, (lo, hi) in enumerate(windows):
        if not max(lo, 0.0) <= st[k] <= min(hi, probe.length):
            st[k] = _project(probe, points[k:k + 1], (lo, hi))[0, 0]
    return st


def _union_offsets(
    probe: Corridor, pieces: list[tuple[FloatArray, FloatArray, FloatArray]],
    windows: list[tuple[float, float]], *, fill: bool = True,
) -> tuple[FloatArray, FloatArray]:
    """Left and right offsets ``(n,)`` [m] of the union of the pieces' bands.

    Each piece covers the stations its midline projects onto, within its window (see
    :func:`_piece_windows`); stations no piece covers (a join without junction lanes) are
    interpolated between their neighbours, or with ``fill=False`` left unbounded
    (:data:`~splineplan.corridor.UNBOUNDED`).
    """
    n = len(probe.s)
    left = np.full(n, -np.inf)
    right = np.full(n, np.inf)
    dense = []
    for ref0, lo0, ro0 in pieces:
        s0 = polyline_stations(ref0)  # densely, so that the lateral offsets follow the bends
        u = np.linspace(0.0, s0[-1], max(2, int(np.ceil(s0[-1] / 0.5)) + 1))
        ref = np.column_stack((np.interp(u, s0, ref0[:, 0]), np.interp(u, s0, ref0[:, 1])))
        dense.append((ref, np.interp(u, s0, lo0), np.interp(u, s0, ro0)))
    # one projection for all pieces; again within its window where a piece needs it
    at = np.cumsum([0] + [len(d[0]) for d in dense])
    sl_all = probe.to_sl(np.concatenate([d[0] for d in dense])) if dense else np.zeros((0, 2))
    for k, ((ref, lo, ro), window) in enumerate(zip(dense, windows, strict=True)):
        sl = _project(probe, ref, window, sl_all[at[k]:at[k + 1]])
        s = np.maximum.accumulate(sl[:, 0])
        keep = np.concatenate(([True], np.diff(s) > 1e-6))
        s, lft, rgt = s[keep], (sl[:, 1] + lo)[keep], (sl[:, 1] + ro)[keep]
        # the stations within 0.25 m of the piece's (probe.s is sorted)
        i0 = int(np.searchsorted(probe.s, s[0] - 0.25, side="left"))
        i1 = max(int(np.searchsorted(probe.s, s[-1] + 0.25, side="right")), i0)
        if len(s) == 1:
            lft_i, rgt_i = np.full(i1 - i0, lft[0]), np.full(i1 - i0, rgt[0])
        else:
            lft_i, rgt_i = np.interp(probe.s[i0:i1], s, lft), np.interp(probe.s[i0:i1], s, rgt)
        left[i0:i1] = np.maximum(left[i0:i1], lft_i)
        right[i0:i1] = np.minimum(right[i0:i1], rgt_i)
    covered = np.isfinite(left)
    if not fill:
        return (np.where(covered, left, UNBOUNDED), np.where(covered, right, -UNBOUNDED))
    if not covered.any():
        raise GeometryError("route corridor: no lane projects onto the reference line")
    left = np.interp(probe.s, probe.s[covered], left[covered])
    right = np.interp(probe.s, probe.s[covered], right[covered])
    return left, right


def _limit_to_curvature(probe: Corridor, left: FloatArray, right: FloatArray
                        ) -> tuple[FloatArray, FloatArray]:
    """Offsets kept within the reference's radius of curvature on the inner side of bends.

    Beyond that radius the (s, l) frame folds over itself. Where this (or lane shapes
    that cross) leaves less than :data:`MIN_CORRIDOR_WIDTH`, the corridor is widened
    symmetrically about its middle to that width, within the same radius limits.
    """
    from scipy.ndimage import gaussian_filter1d

    h = np.unwrap(probe._heading)
    ds = np.maximum(np.diff(probe.s), 1e-9)
    kappa = np.gradient(h) / ds
    kappa = np.concatenate((kappa, kappa[-1:]))
    kappa = gaussian_filter1d(kappa, 2.0, mode="nearest")
    with np.errstate(divide="ignore"):
        radius = np.where(np.abs(kappa) > 1e-6, 0.9 / np.abs(kappa), np.inf)
    left = np.where(kappa > 0, np.minimum(left, radius), left)
    right = np.where(kappa < 0, np.maximum(right, -radius), right)
    narrow = left - right < MIN_CORRIDOR_WIDTH
    if narrow.any():
        log.debug("route corridor: widened to %.1f m at %d stations",
                  MIN_CORRIDOR_WIDTH, int(narrow.sum()))
        mid = np.clip((left + right) / 2.0, -radius + MIN_CORRIDOR_WIDTH / 2.0,
                      radius - MIN_CORRIDOR_WIDTH / 2.0)
        mid = np.where(np.isfinite(mid), mid, (left + right) / 2.0)
        half = MIN_CORRIDOR_WIDTH / 2.0
        left = np.where(narrow, np.maximum(left, mid + half), left)
        right = np.where(narrow, np.minimum(right, mid - half), right)
    return left, right


#: Standard deviation [m] of the Gaussian that smooths a route corridor's reference line.
REFERENCE_SMOOTHING = 2.0


def _smooth_polyline(points: FloatArray, sigma: float) -> FloatArray:
    """Polyline resampled every 0.5 m and smoothed by a Gaussian of ``sigma`` [m].

    The end points stay where they are.
    """
    from scipy.ndimage import gaussian_filter1d

    pts = resample_polyline(points, 0.5)
    if len(pts) < 5:
        return pts
    out = gaussian_filter1d(pts, sigma / 0.5, axis=0, mode="nearest")
    out[0], out[-1] = pts[0], pts[-1]
    return out


#: Stretch [m] before a junction over which the vehicle's centre keeps to the lanes that
#: connect to the next route edge (at most half the edge; not on the route's first edge,
#: where the vehicle may already stand in another lane).
APPROACH_LENGTH = 30.0


def _approach_band(src: list[Lane], approach: float
                   ) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Band across the lanes ``src`` over their last ``approach`` metres (at most half)."""
    length = float(polyline_stations(dedupe_polyline(src[0].shape))[-1])
    cut = max(1.0 - approach / max(length, 1e-9), 0.5)
    return _band(_cut_polyline(src[0].shape, cut, 1.0), src[0].width,
                 _cut_polyline(src[-1].shape, cut, 1.0), src[-1].width)


def _cut_polyline(points: FloatArray, f0: float, f1: float) -> FloatArray:
    """The part of a polyline between fractions ``f0 < f1`` of its length."""
    pts = dedupe_polyline(points)
    s = polyline_stations(pts)
    a, b = f0 * s[-1], f1 * s[-1]
    inner = pts[(s > a + 1e-9) & (s < b - 1e-9)]
    ends = np.column_stack((np.interp([a, b], s, pts[:, 0]), np.interp([a, b], s, pts[:, 1])))
    return np.vstack((ends[:1], inner, ends[1:]))


#: Largest heading change [rad] through a junction that :func:`_junction_band` rounds.
MAX_FILLET_TURN = np.deg2rad(150.0)


def _junction_band(incoming: list[Lane], outgoing: list[Lane]
                   ) -> tuple[FloatArray, FloatArray, FloatArray] | None:
    """Band through a junction from lanes of one edge to lanes of the next (each list from
    the rightmost to the leftmost lane).

    Each side is the curve SUMO rounds a kerb with: a cubic Bezier from the incoming
    band's side, where it ends, to the outgoing band's side, where it starts, tangent to
    both (a circular arc where the two ends are symmetric about the corner). It lies in the
    triangle of the two ends and the corner, which is paved: the edges end at the
    junction's outline. ``None`` where the turn is sharper than :data:`MAX_FILLET_TURN`
    or the sides would cross (the internal lanes' band serves there).
    """
    ends = []
    for lane, side, at_end in ((incoming[0], -1.0, True), (incoming[-1], 1.0, True),
                               (outgoing[0], -1.0, False), (outgoing[-1], 1.0, False)):
        shape = dedupe_polyline(lane.shape)
        if len(shape) < 2:
            return None
        a, b = (shape[-2], shape[-1]) if at_end else (shape[0], shape[1])
        d = (b - a) / float(np.hypot(*(b - a)))
        p = b if at_end else a
        ends.append((p + side * lane.width / 2.0 * np.array([-d[1], d[0]]), d))
    (r0, dr0), (l0, dl0), (r1, dr1), (l1, dl1) = ends
    turn = abs(float(np.arctan2(dr0[0] * dr1[1] - dr0[1] * dr1[0], dr0 @ dr1)))
    if turn > MAX_FILLET_TURN:
        return None
    right = _kerb_curve(r0, dr0, r1, dr1, turn)
    left = _kerb_curve(l0, dl0, l1, dl1, turn)
    if right is None or left is None:
        return None
    normal = np.column_stack((-(right[1:] - right[:-1])[:, 1], (right[1:] - right[:-1])[:, 0]))
    if np.any(np.einsum("ij,ij->i", left[1:] - right[1:], normal) <= 0.0):
        return None  # the sides cross: not a band
    return _band(right, 0.0, left, 0.0)


#: Handles of :func:`_kerb_curve` relative to a circular arc's: a little longer, so that the
#: curve keeps nearer the corner, as SUMO's own rounded kerbs do (measured against the lanes
#: and junction outlines of ten grid routes: 5.5 m^2 of corridor off the paved area at 1.0,
#: 1.2 m^2 at 1.1, 1.8 m^2 at 1.2).
KERB_HANDLE = 1.1


def _kerb_curve(p0: FloatArray, d0: FloatArray, p1: FloatArray, d1: FloatArray,
                turn: float, n: int = 25) -> FloatArray | None:
    """Cubic Bezier ``(n, 2)`` from ``p0`` leaving along ``d0`` to ``p1`` arriving along
    ``d1`` (unit vectors), its handles sized so that it is a circular arc of angle ``turn``
    [rad] when the ends are symmetric; ``None`` if ``p1`` is not ahead of ``p0``."""
    chord = p1 - p0
    length = float(np.hypot(*chord))
    if length < 1e-6:
        return np.vstack((p0, p1))
    if chord @ d0 <= 0.0 or chord @ d1 <= 0.0:
        return None
    handle = length / 3.0
    if turn > 1e-6:
        handle = length * (2.0 / 3.0) * np.tan(turn / 4.0) / np.sin(turn / 2.0)
    handle *= KERB_HANDLE
    t = np.linspace(0.0, 1.0, n)[:, None]
    c0, c1 = p0 + handle * d0, p1 - handle * d1
    return ((1 - t) ** 3 * p0 + 3 * (1 - t) ** 2 * t * c0 + 3 * (1 - t) * t ** 2 * c1
            + t ** 3 * p1)


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
    if len(r) < 2 and len(lft) < 2:
        raise GeometryError("lane shape has fewer than two distinct points")
    # one side a point (a junction band's inner kerb where the two edges' sides meet):
    # the band fans out from it
    r = np.repeat(r, 2, axis=0) if len(r) == 1 else r
    lft = np.repeat(lft, 2, axis=0) if len(lft) == 1 else lft
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
    if root.tag == "net":
        raise NetworkError(f"obstacle file {p} is a SUMO network, not an additional or route "
                           "file with <poly> shapes or stopped vehicles")
    polys: list[FloatArray] = []
    ids: list[str] = []
    for el in root.iter("poly"):
        pid = el.get("id", f"poly{len(ids)}")
        try:
            pts = np.array([[float(v) for v in xy.split(",")[:2]]
                            for xy in el.get("shape", "").split()], dtype=float).reshape(-1, 2)
        except ValueError as err:
            raise GeometryError(f"{p}: polygon '{pid}' has a bad shape "
                                f"{el.get('shape', '')[:40]!r} (x,y pairs of numbers "
                                "expected)") from err
        try:
            Obstacles.from_polygons([pts], [pid])
        except GeometryError as err:
            raise GeometryError(f"{p}: {err}") from err
        polys.append(pts)
        ids.append(pid)
    vtypes = {el.get("id"): el for el in root.iter("vType")}
    lanes = {ln.id: ln for lns in network.lanes for ln in lns}
    pos: list[FloatArray] = []
    head: list[float] = []
    lengths: list[float] = []
    widths: list[float] = []
    vids: list[str] = []
    for veh in root.iter("vehicle"):
        vid = veh.get("id", f"vehicle{len(vids)}")
        for stop in veh.iter("stop"):
            lane_id = stop.get("lane")
            if lane_id is None:
                continue
            if lane_id not in lanes:
                raise NetworkError(f"{p}: vehicle '{vid}' stops on unknown lane "
                                   f"'{lane_id}'")
            lane = lanes[lane_id]
            vt = vtypes.get(veh.get("type", ""))
            where = f"{p}: vehicle '{vid}'"
            length = _positive_attr(vt, "length", SUMO_DEFAULT_LENGTH, f"{where}'s vType")
            width = _positive_attr(vt, "width", SUMO_DEFAULT_WIDTH, f"{where}'s vType")
            end = _float_attr(stop, "endPos", lane.length, f"{where}'s stop")
            xy, h = _lane_point(lane, end)
            pos.append(xy)
            head.append(h)
            lengths.append(length)
            widths.append(width)
            vids.append(vid)
            break  # a vehicle stands at its first stop
    obstacles = Obstacles.from_polygons(polys, ids) if polys else Obstacles.empty()
    if pos:
        obstacles = obstacles + Obstacles.from_boxes(
            np.array(pos), np.array(head), np.array(lengths), np.array(widths),
            reference="front", ids=vids)
    return obstacles


def _float_attr(el: Any, name: str, default: float, where: str) -> float:
    """Attribute ``name`` of an XML element as a finite float (``default`` if absent)."""
    text = None if el is None else el.get(name)
    if text is None:
        return default
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not math.isfinite(value):
        raise NetworkError(f"{where}: {name} must be a number, got {text!r}")
    return value


def _positive_attr(el: Any, name: str, default: float, where: str) -> float:
    """As :func:`_float_attr`, and above 0."""
    value = _float_attr(el, name, default, where)
    if value <= 0:
        raise NetworkError(f"{where}: {name} must be positive, got {value:g}")
    return value


def _lane_point(lane: Lane, pos: float) -> tuple[FloatArray, float]:
    """Point [m] and heading [rad] at ``pos`` [m] along a lane (scaled to its shape)."""
    shape = lane.shape
    st = polyline_stations(shape)
    u = float(np.clip(pos * st[-1] / lane.length if lane.length > 0 else pos, 0.0, st[-1]))
    i = int(np.clip(np.searchsorted(st, u, side="right") - 1, 0, len(st) - 2))
    d = shape[i + 1] - shape[i]
    t = (u - st[i]) / max(st[i + 1] - st[i], 1e-12)
    return shape[i] + t * d, float(np.arctan2(d[1], d[0]))


# ---- whether a car can make a junction turn ------------------------------------------------

@dataclass(frozen=True)
class CarShape:
    """What level 1 needs of the vehicle to tell a turn it can make: its footprint
    ``length`` x ``width`` [m] and the turning radius [m] of its centre."""

    length: float = 4.5
    width: float = 1.8
    min_turn_radius: float = 4.2

    def __post_init__(self) -> None:
        for name in ("length", "width", "min_turn_radius"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise ParameterError(f"CarShape.{name} must be a positive number of metres, "
                                     f"got {value!r}")

    @property
    def outer_reach(self) -> float:
        """How far [m] the footprint reaches outside the centre's arc on the turning
        radius (its outer front corner)."""
        radius = self.min_turn_radius
        return math.hypot(radius + self.width / 2.0, self.length / 2.0) - radius

    @property
    def swept_width(self) -> float:
        """Width [m] of the band the footprint sweeps on the turning radius."""
        return self.outer_reach + self.width / 2.0


#: Turns whose internal lanes bend on no radius below this many turning radii, and whose
#: lanes are wider than the car's swept width, are made without a test (see
#: :func:`turn_fits`).
EASY_RADIUS = 1.0
#: Where the car may stand on the incoming lanes before the junction, and on the outgoing
#: lanes after it [m] (within :data:`PAVING_REACH`), for :func:`turn_fits`.
FIT_BEFORE = (0.0, 4.0)
FIT_AFTER = (0.0, 4.0)
#: Radii of the arcs tried, in turning radii.
FIT_RADII = (1.0, 1.25, 1.6)
#: Heading change [rad] below which a turn counts as straight on (made where its lanes are).
FIT_STRAIGHT = np.deg2rad(25.0)


def turn_fits(network: RoadNetwork, from_edge: str, to_edge: str, vclass: str,
              car: CarShape) -> bool:
    """Whether ``car`` can make the turn from ``from_edge`` to ``to_edge`` within the
    turn's paving (the allowed lanes of both edges near the junction, SUMO's outline of
    the junction and the internal lanes of the allowed connections), once per network
    and car.

    First a cheap geometric test: the car drives forward on a path of an arc, a
    straight and an arc (a Dubins path turning one way, at 1, 1.25 or 1.6 turning radii)
    from a pose on a connection's incoming lane (its centre or either side the car fits
    in, at the lane's end or 4 m before it, heading along the lane or turned by
    :data:`FIT_HEADINGS`) to a pose on its outgoing lane (at its start or 4 m into it);
    the turn fits where one such path keeps the footprint on the paving, each side to
    within :data:`FIT_SLACK` (checked along five normals across the car every 0.5 m of
    the path). Turns without internal lanes fit without a test; turns of less than
    :data:`FIT_STRAIGHT` and turns whose internal lanes bend gently enough
    (:data:`EASY_RADIUS`) need no paths, but the lanes' own sharp bends near the junction
    must fit (:func:`_kinks_fit`). Where no such path keeps to the paving, a search
    (:func:`turn_path`) looks for one that swings wide or changes its radius, as a driver
    does at the turning limit; the turn fits where it finds one (:func:`searched_path`
    then names it). On 200 random Monaco turns the two agree with the kinematic oracle on
    191 (the Dubins paths alone on 180; see ``benchmarks/RESULTS.md``).
    """
    key = ("fits", from_edge, to_edge, vclass, repr(car))
    if key not in network._bands:
        network._bands[key] = _turn_fits(network, from_edge, to_edge, vclass, car)
    fits: bool = network._bands[key]
    return fits


def _turn_fits(network: RoadNetwork, from_edge: str, to_edge: str, vclass: str,
               car: CarShape) -> bool:
    conns = [c for c in network.connections_between(from_edge, to_edge, vclass=vclass)
             if c.via]
    if not conns:
        return True
    if not any(_kinks_fit(network, from_edge, to_edge, c, car) for c in conns):
        return False
    pairs = sorted({(c.from_lane, c.to_lane) for c in conns})
    radius = car.min_turn_radius
    swept = car.swept_width
    turn = 0.0
    for c in conns:
        via = _via_shape(network, c.via)
        lane = network.internal_lanes[c.via[0]]
        r_min, dtheta = _bend(via)
        if r_min >= EASY_RADIUS * radius and lane.width >= swept:
            return True
        turn = dtheta
    if abs(turn) < FIT_STRAIGHT:
        return True
    paving = _kernel_polygons(_paving(network, (from_edge, to_edge), vclass))
    # the poses of each connection's lanes
    poses = [(start, end) for i, j in pairs
             for back, ahead in itertools.product(FIT_BEFORE, FIT_AFTER)
             for start, end in itertools.product(
                 _turned(_lane_poses(network.lanes_of(from_edge)[i], car, end=True, at=back)),
                 _lane_poses(network.lanes_of(to_edge)[j], car, end=False, at=ahead))]
    side = 1.0 if turn > 0 else -1.0
    batch: list[FloatArray] = []
    for scale, ((p0, d0), (p1, d1)) in itertools.product(FIT_RADII, poses):
        path = _dubins_one_way(p0, d0, p1, d1, scale * radius, side, abs(turn))
        if path is not None:
            batch.append(path)
        if len(batch) >= FIT_BATCH:
            if _any_path_paved(batch, paving, car):
                return True
            batch = []
    if batch and _any_path_paved(batch, paving, car):
        return True
    found = turn_path(network, from_edge, to_edge, vclass, car) is not None
    network._bands[("limit", from_edge, to_edge, vclass, repr(car))] = found
    return found


#: Where the search of :func:`turn_path` starts on an incoming lane, before its end, and
#: the stretch of an outgoing lane [m] after its start where it may end.
PATH_BEFORE = 8.0
PATH_AFTER = (2.0, 8.0)


#: Room [m] each side of the car that a corridor gives around a searched path through a
#: junction (see :func:`route_corridor`), before it is cut to the paving.
PATH_ROOM = 0.3


def searched_path(network: RoadNetwork, from_edge: str, to_edge: str, vclass: str,
                  car: CarShape) -> FloatArray | None:
    """The path of :func:`turn_path` where the car makes the turn only on it (it fits by
    no simpler test of :func:`turn_fits`), else ``None``."""
    if not (turn_fits(network, from_edge, to_edge, vclass, car)
            and network._bands.get(("limit", from_edge, to_edge, vclass, repr(car)))):
        return None
    return turn_path(network, from_edge, to_edge, vclass, car)


def turn_path(network: RoadNetwork, from_edge: str, to_edge: str, vclass: str,
              car: CarShape) -> FloatArray | None:
    """A path the car can drive through the turn's paving (:func:`turn_fits`' paving),
    found by a search (:func:`splineplan.turnpath.search`): poses ``(n, 3)`` (x, y [m],
    heading [rad]) from :data:`PATH_BEFORE` metres before the end of a connection's
    incoming lane (on its centre line or as far to either side as the car fits) to its
    outgoing lane, within :data:`PATH_AFTER` of its start, heading along it; ``None``
    where there is none. Once per network and car."""
    key = ("path", from_edge, to_edge, vclass, repr(car))
    if key not in network._bands:
        network._bands[key] = _turn_path(network, from_edge, to_edge, vclass, car)
    path: FloatArray | None = network._bands[key]
    return path


def _turn_path(network: RoadNetwork, from_edge: str, to_edge: str, vclass: str,
               car: CarShape) -> FloatArray | None:
    from splineplan.turnpath import search

    conns = [c for c in network.connections_between(from_edge, to_edge, vclass=vclass)
             if c.via]
    if not conns:
        return None
    starts, goals, tol = [], [], []
    for i in sorted({c.from_lane for c in conns}):
        lane = network.lanes_of(from_edge)[i]
        for p, d in _lane_poses(lane, car, end=True, at=PATH_BEFORE):
            starts.append((p[0], p[1], math.atan2(d[1], d[0])))
    for j in sorted({c.to_lane for c in conns}):
        lane = network.lanes_of(to_edge)[j]
        room = max((lane.width - car.width) / 2.0, 0.25)
        for at in np.arange(PATH_AFTER[0], PATH_AFTER[1] + 1e-9, 0.5):
            for p, d in _lane_poses(lane, car, end=False, at=float(at))[:1]:
                goals.append((p[0], p[1], math.atan2(d[1], d[0])))
                tol.append(room)
    if not starts or not goals:
        return None
    polys = _paving(network, (from_edge, to_edge), vclass)
    return search(polys, np.array(starts), np.array(goals), np.array(tol),
                  length=car.length, width=car.width, kappa_max=1.0 / car.min_turn_radius)


def _kinks_fit(network: RoadNetwork, from_edge: str, to_edge: str, conn: Connection,
               car: CarShape) -> bool:
    """Whether ``car`` can follow the sharp bends of the connection's lanes within
    :data:`BEND_LEAD` of the junction (which :func:`sharp_runs` leaves to the junction):
    the runs of bends (:func:`_bend_runs`) of the incoming lane's last and the outgoing
    lane's first ``2 * BEND_LEAD`` metres, joined through the internal lanes, that lie
    on a lane alone, each tested as :func:`bend_fits` tests an edge's
    (:func:`_run_fits`) within the narrower lane. Runs that reach into the internal
    lanes are the turn's, which :func:`turn_fits`' paths judge on the junction's
    paving, and so are bends within :data:`KINK_GAP` of the junction."""
    lane_in = network.lanes_of(from_edge)[conn.from_lane]
    lane_out = network.lanes_of(to_edge)[conn.to_lane]
    tail = _tail(lane_in.shape, 2.0 * BEND_LEAD)
    head = _tail(lane_out.shape[::-1], 2.0 * BEND_LEAD)[::-1]
    line = dedupe_polyline(np.concatenate((tail, _via_shape(network, conn.via), head)))
    if len(line) < 3:
        return True
    st = polyline_stations(line)
    a, b = polyline_stations(tail)[-1], st[-1] - polyline_stations(head)[-1]
    lane = replace(lane_in, width=min(lane_in.width, lane_out.width))
    for first, last, turn in _sharp(line, st, lane.width - car.swept_width, car):
        # a lane's own bend, not the turn's, and far enough from the junction's outline
        gap = a - st[last] if st[last] < a - 1e-6 else st[first] - b
        if gap >= KINK_GAP and not _run_fits(line, st, [lane], float(st[first]),
                                             float(st[last]), turn, car):
            return False
    return True


#: Distance [m] from the junction below which a lane's bend is left to the junction's
#: outline by :func:`_kinks_fit` (beside it the junction gives the car's body room). Of
#: the 24 Monaco turns that the test refuses without it, the kinematic oracle drives the 6
#: whose bend lies 0.3-2.3 m from the junction, and none of the 18 whose bend lies
#: 1.9 m or further.
KINK_GAP = 1.75


def _turned(poses: list[tuple[FloatArray, FloatArray]]) -> list[tuple[FloatArray, FloatArray]]:
    """Each pose (point, unit direction) with its direction as it is and turned by each
    of :data:`FIT_HEADINGS`: a driver may come to the junction swung out or already
    turning in."""
    out = []
    for p, d in poses:
        for a in FIT_HEADINGS:
            c, s = math.cos(a), math.sin(a)
            out.append((p, np.array([c * d[0] - s * d[1], s * d[0] + c * d[1]])))
    return out


#: Headings [rad] relative to the lane at which :func:`turn_fits` lets the car reach the
#: junction (on 200 random Monaco turns these raise its agreement with the kinematic
#: oracle from 176 to 179, on the city's 125 turns from 123 to all).
FIT_HEADINGS = (0.0, 0.2, -0.2)
#: Paths checked together by :func:`_turn_fits` (most turns that fit pass in the first).
FIT_BATCH = 12
#: How far [m] each side of the footprint may reach beyond the paving in :func:`turn_fits`:
#: its paths are fewer than a driver's (no swinging out the other way first, no
#: changing radius), so a turn it refuses by less than this is given the benefit.
FIT_SLACK = 0.25


def _bend(shape: FloatArray) -> tuple[float, float]:
    """The least radius [m] over 2 m of a polyline, and its heading change [rad]
    (counter-clockwise positive)."""
    pts = resample_polyline(shape, 0.5)
    if len(pts) < 3:
        return math.inf, 0.0
    d = np.diff(pts, axis=0)
    h = np.unwrap(np.arctan2(d[:, 1], d[:, 0]))
    k = min(4, len(h) - 1)
    change = np.abs(h[k:] - h[:-k]) if k > 0 else np.zeros(1)
    worst = float(change.max()) if len(change) else 0.0
    r_min = (k * 0.5) / worst if worst > 1e-9 else math.inf
    return r_min, float(h[-1] - h[0])


def _lane_poses(lane: Lane, car: CarShape, *, end: bool, at: float = 0.0
                ) -> list[tuple[FloatArray, FloatArray]]:
    """Poses (point, unit direction) ``at`` metres along a lane before its end (or after
    its start): on its centre line and as far to either side as the car fits in it."""
    shape = dedupe_polyline(lane.shape)
    if len(shape) < 2:
        return []
    st = polyline_stations(shape)
    u = float(np.clip(st[-1] - at if end else at, 0.0, st[-1]))
    i = int(np.clip(np.searchsorted(st, u, side="right") - 1, 0, len(st) - 2))
    d = (shape[i + 1] - shape[i]) / max(float(st[i + 1] - st[i]), 1e-12)
    p = shape[i] + (u - st[i]) * d
    n = np.array([-d[1], d[0]])
    room = max((lane.width - car.width) / 2.0 - 0.05, 0.0)
    offsets = (0.0, room, -room) if room > 0.05 else (0.0,)
    return [(p + o * n, d) for o in offsets]


def _dubins_one_way(p0: FloatArray, d0: FloatArray, p1: FloatArray, d1: FloatArray,
                    radius: float, side: float, turn: float, step: float = 0.5
                    ) -> FloatArray | None:
    """Poses ``(n, 3)`` (x, y [m], heading [rad]) every ``step`` [m] along the path from
    ``p0`` heading ``d0`` to ``p1`` heading ``d1``: an arc of ``radius`` turning to the
    left (``side`` 1) or right (-1), a straight, an arc the same way; ``None`` where its
    arcs turn more than ``turn`` [rad] plus a quarter turn together (a loop)."""
    n0, n1 = side * np.array([-d0[1], d0[0]]), side * np.array([-d1[1], d1[0]])
    c0, c1 = p0 + radius * n0, p1 + radius * n1
    gap = c1 - c0
    dist = float(np.hypot(*gap))
    h0, h1 = math.atan2(d0[1], d0[0]), math.atan2(d1[1], d1[0])
    phi = math.atan2(gap[1], gap[0]) if dist > 1e-9 else h1
    a0 = (side * (phi - h0)) % (2.0 * math.pi)
    a1 = (side * (h1 - phi)) % (2.0 * math.pi)
    if a0 > 2.0 * math.pi - 1e-6:
        a0 = 0.0
    if a1 > 2.0 * math.pi - 1e-6:
        a1 = 0.0
    if a0 + a1 > turn + math.pi / 2.0:
        return None
    parts: list[FloatArray] = []
    for centre, start_h, angle in ((c0, h0, a0), (None, phi, dist), (c1, phi, a1)):
        length = angle * radius if centre is not None else angle
        m = max(math.ceil(length / step), 1)
        u = np.linspace(0.0, length, m + 1)[1:]
        if centre is None:
            start = parts[-1][-1, :2] if parts else p0
            xy = start + np.outer(u, [math.cos(start_h), math.sin(start_h)])
            h = np.full(len(u), start_h)
        else:
            h = start_h + side * u / radius
            xy = centre + radius * np.column_stack((np.cos(h - side * math.pi / 2.0),
                                                    np.sin(h - side * math.pi / 2.0)))
        parts.append(np.column_stack((xy, h)))
    return np.vstack([np.array([[p0[0], p0[1], h0]]), *parts])


#: Fractions of the car's length at which :func:`_any_path_paved` checks its width.
_FIT_NORMALS = (-0.5, -0.25, 0.0, 0.25, 0.5)


def _any_path_paved(paths: list[FloatArray], paving: tuple[FloatArray, FloatArray, IntArray],
                    car: CarShape) -> bool:
    """Whether the footprint along some path stays on the paving: along five normals
    across the car, the paved stretch that holds the car's axis covers its width."""
    poses = np.vstack(paths)
    fr = np.array(_FIT_NORMALS) * car.length
    tx, ty = np.cos(poses[:, 2]), np.sin(poses[:, 2])
    cx = (poses[:, 0:1] + tx[:, None] * fr).ravel()
    cy = (poses[:, 1:2] + ty[:, None] * fr).ravel()
    tx, ty = np.repeat(tx, len(fr)), np.repeat(ty, len(fr))
    lo, hi = _paved_spans(kernel_floats(cx), kernel_floats(cy), kernel_floats(tx),
                          kernel_floats(ty), np.zeros(len(cx)), *paving, PAVING_GAP)
    half = car.width / 2.0 - FIT_SLACK
    ok = (lo <= -half) & (hi >= half)  # NaN: not paved
    per_pose = ok.reshape(-1, len(fr)).all(axis=1)
    at = np.cumsum([0] + [len(p) for p in paths])
    return any(bool(per_pose[a:b].all()) for a, b in itertools.pairwise(at))


def bend_fits(network: RoadNetwork, edge_id: str, vclass: str, car: CarShape) -> bool:
    """Whether ``car`` can follow the bends of edge ``edge_id`` within its allowed lanes,
    once per network and car.

    Networks made from OpenStreetMap draw some bends of narrow streets as kinks of 70
    degrees or more between straight pieces, which no car of the turning radius can follow
    inside a lane of 3.2 m. A cheap test, not a search: for each sharp run of vertices
    turning one way (:func:`sharp_runs`), the polygon of least turning
    (:func:`~splineplan.control_polygon.min_turning_offsets`, points every metre from
    :data:`BEND_LEAD` before the run to as far after it) within the room the car's swept
    width leaves on the allowed lanes must turn within :data:`BEND_SLACK` times the
    turning limit. On Monaco's 1,001 runs that the test
    looks at, it agrees with the kinematic oracle on 901 (``benchmarks/RESULTS.md``).
    """
    key = ("bend", edge_id, vclass, repr(car))
    if key not in network._bands:
        network._bands[key] = _bend_fits(network, edge_id, vclass, car)
    fits: bool = network._bands[key]
    return fits


#: Stretch [m] before and after a bend over which :func:`bend_fits` lets the car take it.
BEND_LEAD = 12.0
#: Heading change [rad] at a vertex below which :func:`_bend_runs` does not count it.
BEND_VERTEX = np.deg2rad(3.0)
#: Longest straight [m] between two vertices turning the same way in one run of
#: :func:`_bend_runs`.
BEND_GAP = 12.0
#: Share of the turning limit up to which :func:`bend_fits`' polygon may turn (its
#: vertices a metre apart measure a turn coarsely; the kinematic oracle agrees best here).
BEND_SLACK = 1.3
#: Spacing [m] of the polygon's points in :func:`bend_fits`.
BEND_STEP = 1.0


def _bend_fits(network: RoadNetwork, edge_id: str, vclass: str, car: CarShape) -> bool:
    lanes = list(network.allowed_lanes(edge_id, vclass))
    ref, st, runs = sharp_runs(lanes, car)
    for first, last, turn in runs:
        if not _run_fits(ref, st, lanes, float(st[first]), float(st[last]), turn, car):
            log.debug("edge '%s': the bend of %.0f degrees at %.0f m is too tight for %s",
                      edge_id, np.degrees(abs(turn)), st[first], car)
            return False
    return True


def sharp_runs(lanes: list[Lane], car: CarShape
               ) -> tuple[FloatArray, FloatArray, list[tuple[int, int, float]]]:
    """The runs of an edge's bends that :func:`bend_fits` tests, from its allowed
    ``lanes``: the rightmost one's centre line ``(n, 2)`` [m], its stations ``(n,)`` [m],
    and the runs of :func:`_bend_runs` that turn by more than :data:`FIT_STRAIGHT`, would
    not fit a single kink of their turn at twice the turning radius
    (:func:`_kink_radius`), and lie at least :data:`BEND_LEAD` from the edge's ends
    (beside a junction the junction may give the room: the benefit of the doubt)."""
    ref = dedupe_polyline(lanes[0].shape) if lanes else np.zeros((0, 2))
    if len(ref) < 3:
        return ref, np.zeros(len(ref)), []
    st = polyline_stations(ref)
    return ref, st, _sharp(ref, st, sum(ln.width for ln in lanes) - car.swept_width, car)


def _sharp(ref: FloatArray, st: FloatArray, play: float, car: CarShape
           ) -> list[tuple[int, int, float]]:
    """The runs of :func:`_bend_runs` of the polyline ``ref`` (stations ``st``) that
    :func:`sharp_runs` keeps, with ``play`` [m] of lateral room for the car's centre."""
    return [(first, last, turn) for first, last, turn in _bend_runs(ref)
            if abs(turn) >= FIT_STRAIGHT
            and _kink_radius(play, abs(turn)) < 2.0 * car.min_turn_radius
            and st[first] >= BEND_LEAD and st[-1] - st[last] >= BEND_LEAD]


def _run_fits(ref: FloatArray, st: FloatArray, lanes: list[Lane], s_first: float,
              s_last: float, turn: float, car: CarShape) -> bool:
    """Whether the polygon of least turning through the stretch of the rightmost allowed
    lane's centre line ``ref`` (stations ``st``) from ``s_first - BEND_LEAD`` to ``s_last +
    BEND_LEAD`` [m], moved sideways within the room the car's swept width leaves on the
    allowed ``lanes``, turns within ``BEND_SLACK`` times the turning limit. ``turn``
    [rad]: the run's heading change (its sign says which side is outside)."""
    s = np.arange(s_first - BEND_LEAD, s_last + BEND_LEAD + 1e-9, BEND_STEP)
    i = np.clip(np.searchsorted(st, s, side="right") - 1, 0, len(st) - 2)
    d = ref[i + 1] - ref[i]
    d /= np.hypot(*d.T)[:, None]
    normal = np.column_stack((-d[:, 1], d[:, 0]))
    width = sum(ln.width for ln in lanes)
    # points on the middle of the allowed lanes (the rightmost one's centre moved left)
    origin = ref[i] + (s - st[i])[:, None] * d + (width - lanes[0].width) / 2.0 * normal
    outer = width / 2.0 - car.outer_reach
    inner = width / 2.0 - car.width / 2.0
    lo, hi = (-outer, inner) if turn > 0 else (-inner, outer)
    if lo > hi:
        return False
    m = len(s)
    kappa = 1.0 / car.min_turn_radius
    lat = min_turning_offsets(origin, normal, np.full(m, lo), np.full(m, hi), np.zeros(m),
                              SMOOTH_CENTRE_WEIGHT, kappa)
    return float(polygon_turns(origin + lat[:, None] * normal)[0].max()) <= BEND_SLACK * kappa


def _bend_runs(shape: FloatArray) -> list[tuple[int, int, float]]:
    """Runs of a polyline's inner vertices that turn the same way, each by more than
    :data:`BEND_VERTEX`, at most :data:`BEND_GAP` apart: ``(first, last, turn)``, the
    indices of the first and last vertex and the heading change [rad] over the run."""
    d = np.diff(shape, axis=0)
    h = np.arctan2(d[:, 1], d[:, 0])
    turns = (np.diff(h) + np.pi) % (2.0 * np.pi) - np.pi  # at vertices 1 .. n - 2
    st = polyline_stations(shape)
    runs: list[tuple[int, int, float]] = []
    for k, t in enumerate(turns, start=1):
        if abs(t) <= BEND_VERTEX:
            continue
        if runs and np.sign(runs[-1][2]) == np.sign(t) and st[k] - st[runs[-1][1]] <= BEND_GAP:
            first, _, total = runs[-1]
            runs[-1] = (first, k, total + float(t))
        else:
            runs.append((k, k, float(t)))
    return runs


def _kink_radius(play: float, turn: float) -> float:
    """The largest radius [m] of an arc through a single kink of ``turn`` [rad] that stays
    within ``play`` [m] of lateral room (the centre's band, the car's swept width taken
    off): the arc touches the outer side on both legs and the inner corner at its middle."""
    if play <= 0.0:
        return 0.0
    return play / max(1.0 - math.cos(turn / 2.0), 1e-12)
