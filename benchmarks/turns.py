"""Junction turns as a car uses them, built from the network file alone (sumolib and
shapely, none of the planner's geometry): the turns of a network, the drivable area of a
turn, and the start pose and goal region the kinematic oracle and the planner share.

A turn is a pair of normal edges ``(from_edge, to_edge)`` joined by a connection that the
vehicle class may use and that is not a turnaround. Its drivable area is the union of

- the lanes of both edges that the class may use (each a band of its width about its
  centre line, flat-ended),
- SUMO's outline of the junction between them (``<junction shape=...>``),
- the internal lanes of the connections between the two edges that the class may use.

and, as paved, the outlines of the junctions before ``from_edge`` and after ``to_edge``
with their internal lanes into ``from_edge`` and out of ``to_edge`` (on a short edge the
car reaches onto them), the wedges between a lane's square end and a junction outline
that meets it at an angle (:func:`lane_join`), and the spot where the car starts (its
footprint and 3 m behind it: on a short edge its rear can stand beyond the paving). Gaps
narrower than 0.2 m between these parts (neighbouring lanes drawn a little apart) count
as paved.

The car starts :data:`LEAD` metres before the end of ``from_edge`` (at its start where it
is shorter), midway across its allowed lanes and along them, and must bring its centre to
the goal: the allowed lanes of ``to_edge`` over the 3 m that end :data:`REACH` metres after
its start (:data:`BUMPER` before its end where it is shorter).
"""

from __future__ import annotations

import math
import random
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import shapely
from shapely.geometry import LineString, Polygon
from shapely.ops import substring, unary_union

#: Stations [m] of the start before the end of the incoming edge, and of the goal's end
#: after the start of the outgoing edge; the goal is :data:`GOAL_DEPTH` [m] deep.
LEAD = 20.0
REACH = 20.0
GOAL_DEPTH = 3.0
#: Lanes beyond the turn's window kept in the oracle's area [m] (its raster stays small).
SLACK = 8.0
#: The goal ends at least this far [m] before the end of a short outgoing edge, so that
#: the car's front stays on it.
BUMPER = 2.5


@dataclass(frozen=True)
class Turn:
    """One junction turn: the two edges, the junction, and its geometry (shapely)."""

    from_edge: str
    to_edge: str
    junction: str
    area: Any  #: the drivable area (both edges in full, junction, internal lanes)
    window: Any  #: the area cut to the turn's stretch, for the oracle's raster
    start: tuple[float, float, float]  #: x, y [m], heading [rad]
    start_pos: float  #: station [m] of the start on ``from_edge``
    goal: Any  #: the goal region (polygon)
    end_pos: float  #: position [m] of the goal's far end along ``to_edge``


def _sumo(path: Path) -> Any:
    import sumolib

    return sumolib.net.readNet(str(path), withInternal=True)


def _allowed(lane: Any, vclass: str) -> bool:
    return bool(lane.allows(vclass))


def lane_band(shape: Any, width: float) -> Any:
    """A lane's area: its centre line ``shape`` (points of x, y [m]) widened by half
    ``width`` [m] each side, mitred at its bends (as SUMO draws it), square at its ends."""
    line = LineString([p[:2] for p in shape])
    return line.buffer(width / 2.0, cap_style="flat", join_style="mitre", mitre_limit=3.0)


def _conns(snet: Any, a: Any, b: Any, vclass: str) -> list[Any]:
    """Connections from edge ``a`` to edge ``b`` that ``vclass`` may use (lanes, via lanes
    and the connection's own permissions)."""
    out = []
    for c in a.getOutgoing().get(b, []):
        if not (_allowed(c.getFromLane(), vclass) and _allowed(c.getToLane(), vclass)):
            continue
        allowed = getattr(c, "_allowed", None)
        if allowed and vclass not in allowed and "all" not in allowed:
            continue
        vias = _via_lanes(snet, c)
        if all(_allowed(v, vclass) for v in vias):
            out.append(c)
    return out


def _via_lanes(snet: Any, c: Any) -> list[Any]:
    out: list[Any] = []
    vid = c.getViaLaneID()
    while vid and len(out) < 16:
        lane = snet.getLane(vid)
        out.append(lane)
        nxt = lane.getOutgoing()
        vid = nxt[0].getViaLaneID() if nxt else ""
    return out


def turns_of(path: Path, vclass: str = "passenger") -> list[tuple[str, str]]:
    """Every turn of the network (sorted): connected edge pairs that ``vclass`` may use,
    with internal lanes, not turnarounds."""
    snet = _sumo(path)
    out = set()
    for a in snet.getEdges():
        if a.getFunction() != "":
            continue
        for b in a.getOutgoing():
            if b.getFunction() != "" or b.getID() == a.getID():
                continue
            cs = _conns(snet, a, b, vclass)
            if cs and any(c.getViaLaneID() for c in cs) and \
                    not all(c.getDirection() == "t" for c in cs):
                out.add((a.getID(), b.getID()))
    return sorted(out)


def random_turns(path: Path, n: int, seed: int, vclass: str = "passenger"
                 ) -> list[tuple[str, str]]:
    """``n`` turns of the network drawn without replacement (seeded)."""
    every = turns_of(path, vclass)
    return random.Random(seed).sample(every, min(n, len(every)))


class TurnBuilder:
    """Builds :class:`Turn` s of one network (the network read once)."""

    def __init__(self, path: Path, vclass: str = "passenger") -> None:
        self.snet = _sumo(path)
        self.path = Path(path)
        self.vclass = vclass

    def turn(self, from_edge: str, to_edge: str) -> Turn:
        snet, vclass = self.snet, self.vclass
        a, b = snet.getEdge(from_edge), snet.getEdge(to_edge)
        junction = a.getToNode()
        la = [ln for ln in a.getLanes() if _allowed(ln, vclass)]
        lb = [ln for ln in b.getLanes() if _allowed(ln, vclass)]
        parts = [lane_band(ln.getShape(), ln.getWidth()) for ln in la + lb]
        for node in (junction, a.getFromNode(), b.getToNode()):
            outline = node.getShape()
            if len(outline) >= 3:
                parts.append(Polygon([p[:2] for p in outline]).buffer(0))
        # the wedges between the lanes' square ends and the junctions' outlines
        ends = ([(ln, a.getFromNode(), False) for ln in la]
                + [(ln, junction, True) for ln in la] + [(ln, junction, False) for ln in lb]
                + [(ln, b.getToNode(), True) for ln in lb])
        joins = (lane_join(ln.getShape(), ln.getWidth(), node.getShape(), at_end)
                 for ln, node, at_end in ends)
        parts += [j for j in joins if j is not None]
        vias = [v for c in _conns(snet, a, b, vclass) for v in _via_lanes(snet, c)]
        # the junctions at the far ends: the internal lanes into the incoming edge and
        # out of the outgoing one (a short edge's car reaches onto them)
        vias += [v for e in a.getIncoming() for c in _conns(snet, e, a, vclass)
                 for v in _via_lanes(snet, c)]
        vias += [v for e in b.getOutgoing() for c in _conns(snet, b, e, vclass)
                 for v in _via_lanes(snet, c)]
        parts += [lane_band(v.getShape(), v.getWidth()) for v in vias if len(v.getShape()) >= 2]
        area = _closed(unary_union(parts))
        # the start: LEAD before the end of the incoming edge, midway across its lanes
        ra, rl = LineString([p[:2] for p in la[0].getShape()]), \
            LineString([p[:2] for p in la[-1].getShape()])
        frac = max(1.0 - LEAD / ra.length, 0.0)
        p0 = np.array(ra.interpolate(frac, normalized=True).coords[0])
        p1 = np.array(rl.interpolate(frac, normalized=True).coords[0])
        q0 = np.array(ra.interpolate(min(frac + 0.5 / ra.length, 1.0), normalized=True)
                      .coords[0])
        q = q0 - np.array(ra.interpolate(max(frac - 0.5 / ra.length, 0.0), normalized=True)
                          .coords[0])
        xy = (p0 + p1) / 2.0
        start = (float(xy[0]), float(xy[1]), float(np.arctan2(q[1], q[0])))
        start_pos = frac * a.getLength()
        # the car stands where it starts (on a short edge its rear can be off the paving)
        spot = footprints(np.array([xy[0] - 1.5 * math.cos(start[2])]),
                          np.array([xy[1] - 1.5 * math.sin(start[2])]),
                          np.array([start[2]]), 4.5 + 3.0, 1.8)[0]
        area = area.union(spot)
        # the goal: the outgoing lanes' stretch ending REACH into the edge
        rb, lbl = (LineString([p[:2] for p in ln.getShape()]) for ln in (lb[0], lb[-1]))
        g1 = min(REACH, max(rb.length - BUMPER, GOAL_DEPTH)) / rb.length
        g1 = min(g1, 1.0)
        g0 = max(g1 - GOAL_DEPTH / rb.length, 0.0)
        goal = _span(rb, lb[0].getWidth(), lbl, lb[-1].getWidth(), g0, g1)
        # the oracle's window: the lanes' stretches about the turn, the junction, the vias
        win = [substring(LineString([p[:2] for p in ln.getShape()]),
                         max(frac - SLACK / max(ln.getLength(), 1e-9), 0.0), 1.0,
                         normalized=True).buffer(ln.getWidth() / 2.0, cap_style="flat")
               for ln in la]
        win += [substring(LineString([p[:2] for p in ln.getShape()]), 0.0,
                          min(g1 + SLACK / max(ln.getLength(), 1e-9), 1.0),
                          normalized=True).buffer(ln.getWidth() / 2.0, cap_style="flat")
                for ln in lb]
        core = win + [p for p in parts[len(la) + len(lb):] if p.intersects(win[0])
                      or p.intersects(win[-1])]
        window = area.intersection(unary_union([*core, spot]).buffer(SLACK))
        shapely.prepare(area)
        return Turn(from_edge, to_edge, junction.getID(), area, window, start, start_pos,
                    goal, g1 * b.getLength())


#: Length [m] over which a lane's band reaches on into the junction at its end (see
#: :func:`lane_join`): the allowance the planner makes too (``network.PAVING_CAP``); 1.0
#: or 1.5 m give the same benchmark figures.
JOIN = 0.5


def lane_join(shape: list[tuple[float, ...]], width: float,
              outline: list[tuple[float, ...]], at_end: bool) -> Any:
    """Where a lane meets a junction (at its end, or at its start with ``at_end=False``):
    its band continued :data:`JOIN` metres past its square end, cut to the convex hull
    of the junction's outline and the lane's end; ``None`` where the junction has no
    outline.

    SUMO cuts a lane square to its centre line but draws the junction's outline along
    the other roads' kerbs, so where the two meet at an angle they leave a wedge between
    them (on Monaco up to about 1 m along the kerb and 1.1 m across the lane, with the
    junction paved on beyond it): the lane's kerbs run on to the outline, and the wedge
    is road.
    """
    if len(outline) < 3 or len(shape) < 2:
        return None
    pts = np.array([p[:2] for p in shape], dtype=float)
    if not at_end:
        pts = pts[::-1]
    d = pts[-1] - pts[-2]
    d = d / max(float(np.hypot(*d)), 1e-12)
    n = np.array([-d[1], d[0]]) * width / 2.0
    end = pts[-1]
    ahead = end + JOIN * d
    reach = Polygon([end - n, ahead - n, ahead + n, end + n])
    hull = shapely.MultiPoint([p[:2] for p in outline] + [tuple(end - n), tuple(end + n)]
                              ).convex_hull
    return reach.intersection(hull)


#: Gaps [m] between the lanes' bands narrower than twice this are paved (SUMO draws
#: neighbouring lanes a few centimetres apart or overlapping).
CLOSE = 0.1


def _closed(area: Any) -> Any:
    """``area`` without gaps narrower than ``2 CLOSE`` (a morphological closing with
    mitred joins, which keeps the corners)."""
    return area.buffer(CLOSE, join_style="mitre").buffer(-CLOSE, join_style="mitre")


def _span(right: LineString, rw: float, left: LineString, lw: float, f0: float,
          f1: float) -> Polygon:
    """The band from the right side of ``right`` to the left side of ``left`` between
    fractions ``f0 < f1`` of their lengths."""
    fs = np.linspace(f0, f1, 6)
    pr = np.array([right.interpolate(f, normalized=True).coords[0] for f in fs])
    pl = np.array([left.interpolate(f, normalized=True).coords[0] for f in fs])
    d = pl - pr
    n = np.linalg.norm(d, axis=1, keepdims=True)
    if np.all(n < 1e-6):  # one lane: its own normal
        t = np.gradient(pr, axis=0)
        u = np.column_stack((-t[:, 1], t[:, 0])) / np.linalg.norm(t, axis=1, keepdims=True)
    else:
        u = d / np.maximum(n, 1e-9)
    outer_r = pr - u * rw / 2.0
    outer_l = pl + u * lw / 2.0
    return Polygon(np.vstack((outer_r, outer_l[::-1]))).buffer(0)


def footprints(x: np.ndarray, y: np.ndarray, heading: np.ndarray, length: float,
               width: float) -> Any:
    """The car's rectangles at the poses, as a shapely array."""
    c, s = np.cos(heading), np.sin(heading)
    hl, hw = length / 2.0, width / 2.0
    corners = np.array([[hl, hw], [-hl, hw], [-hl, -hw], [hl, -hw]])
    px = x[:, None] + c[:, None] * corners[:, 0] - s[:, None] * corners[:, 1]
    py = y[:, None] + s[:, None] * corners[:, 0] + c[:, None] * corners[:, 1]
    return shapely.polygons(np.stack((px, py), axis=-1))


def outside(turn: Turn, x: np.ndarray, y: np.ndarray, heading: np.ndarray, *,
            length: float = 4.5, width: float = 1.8) -> float:
    """How far [m] the footprints at the poses reach outside the turn's area, from the
    start until the centre first reaches the goal (0 where they stay inside)."""
    in_goal = shapely.contains_xy(turn.goal, x, y)
    end = int(np.argmax(in_goal)) + 1 if in_goal.any() else len(x)
    fps = footprints(x[:end], y[:end], heading[:end], length, width)
    out = shapely.difference(fps, turn.area)
    worst = 0.0
    for k in np.flatnonzero(~shapely.is_empty(out)):
        pts = shapely.get_coordinates(shapely.segmentize(shapely.boundary(fps[k]), 0.05))
        d = shapely.distance(turn.area, shapely.points(pts))
        worst = max(worst, float(d.max()))
    return worst
