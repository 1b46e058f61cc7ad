"""Pictures of networks, routes and plans (matplotlib, Agg backend).

Imported by no planning code. Each function draws on a given axes or writes a file.

Choices that make the pictures readable (see README.md, "Figures"):

- a route is shown zoomed to itself with some of the network around it
  (:func:`route_view`), with an overview of the whole network in a corner when the view
  is much smaller than the network;
- the planned route is a wide translucent band under the driven path, which is a thin
  line coloured by speed; legend entries look like what is drawn;
- a plan on a corridor longer than :data:`ROAD_FRAME_FROM` is drawn in the road's own frame
  (station along the road against lateral offset), in stacked panels of at most
  :data:`PANEL_LENGTH` metres, at true scale; shorter plans are drawn in x-y;
- speed colours always span 0 .. ``s_max``, so the same colour is the same speed in every
  picture.
"""

from __future__ import annotations

import itertools
import logging
import math
import textwrap
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from os import PathLike
from pathlib import Path
from typing import TYPE_CHECKING, Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
from matplotlib.collections import LineCollection, PolyCollection
from matplotlib.colors import Normalize
from matplotlib.figure import Figure
from matplotlib.legend_handler import HandlerBase
from matplotlib.lines import Line2D
from matplotlib.patches import Patch, Rectangle

if TYPE_CHECKING:
    from splineplan.corridor import Corridor
    from splineplan.network import CarShape, RoadNetwork
    from splineplan.obstacles import Obstacles
    from splineplan.roadmap import Roadmap
    from splineplan.route import Route

log = logging.getLogger(__name__)

#: A route's view is its bounding box grown by this fraction of its larger side ...
ROUTE_PAD_FRACTION = 0.2
#: ... and by at least this much [m] on each side.
ROUTE_PAD_MIN = 150.0
#: An overview of the whole network is added when the view shows less than this fraction
#: of the network's bounding box (by area).
OVERVIEW_BELOW = 0.25
#: A road-frame figure whose road turns by more than this [rad] gets a map of the road in
#: x-y on top.
BENDS_FROM = 0.35
#: Corridors longer than this [m] are drawn in the road's frame, in stacked panels ...
ROAD_FRAME_FROM = 200.0
#: ... of at most this much road [m] each.
PANEL_LENGTH = 125.0

#: The planned route: a wide translucent band (colour, line width [pt], alpha).
ROUTE_BAND = ("tab:blue", 9.0, 0.35)
#: Colour map of speed [m/s] (0 .. s_max).
SPEED_CMAP = "viridis"


def plot_network(network: RoadNetwork, ax: Any = None, *, color: str = "0.75",
                 linewidth: float = 0.8, fit: bool = True) -> Any:
    """Draw every lane centre line of ``network`` on ``ax`` (a new one if ``None``).

    With ``fit`` the axes' limits are set to the whole network.
    """
    if ax is None:
        _, ax = plt.subplots(figsize=(8, 8))
    ax.add_collection(LineCollection(_lane_lines(network), colors=color, linewidths=linewidth,
                                     label="lanes", zorder=1, gid="lanes"))
    if fit:
        xmin, ymin, xmax, ymax = network.bounds
        pad = 0.03 * max(xmax - xmin, ymax - ymin, 1.0)
        ax.set_xlim(xmin - pad, xmax + pad)
        ax.set_ylim(ymin - pad, ymax + pad)
    ax.set_aspect("equal")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    return ax


def route_view(points: Any, network_bounds: tuple[float, float, float, float], *,
               pad_fraction: float = ROUTE_PAD_FRACTION,
               pad_min: float = ROUTE_PAD_MIN) -> tuple[float, float, float, float]:
    """Axes limits ``(xmin, xmax, ymin, ymax)`` [m] that show ``points`` ``(n, 2)`` in context.

    The points' bounding box grown on each side by ``pad_fraction`` of its larger side and
    at least ``pad_min`` [m], cut to the network's bounding box (with a 3 % margin), so a
    route on a large network is seen closely and a route across a small one shows it all.
    """
    pts = np.asarray(points, dtype=float).reshape(-1, 2)
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    pad = max(pad_fraction * float(np.max(hi - lo)), pad_min)
    nx0, ny0, nx1, ny1 = network_bounds
    m = 0.03 * max(nx1 - nx0, ny1 - ny0, 1.0)
    x0, x1 = max(lo[0] - pad, nx0 - m), min(hi[0] + pad, nx1 + m)
    y0, y1 = max(lo[1] - pad, ny0 - m), min(hi[1] + pad, ny1 + m)
    # never cut the points themselves (a route may run outside the network's bounds)
    return (min(x0, lo[0]), max(x1, hi[0]), min(y0, lo[1]), max(y1, hi[1]))


def plot_route(network: RoadNetwork, route: Route, ax: Any = None, *,
               path: str | PathLike[str] | None = None, title: str | None = None,
               also_show: Any = None, legend: bool = True) -> Any:
    """Draw ``route`` on the network around it; write it to ``path`` if given.

    The view is :func:`route_view` of the route (and of the points ``also_show`` ``(n, 2)``,
    e.g. a driven path); the network is drawn in light grey, the route as a wide
    translucent band along the centre of each edge's lanes and the junction lanes between
    them, start and goal marked. When the view is a small part of the network, an overview
    (gid ``overview``) shows the whole network with the route and the view's outline.
    With ``legend=False`` the caller adds the legend (after drawing more). Returns the
    axes; the route band has gid ``route``.
    """
    from splineplan.network import route_corridor

    ref = route_corridor(network, route).reference
    pts = ref if also_show is None or len(also_show) == 0 else np.concatenate(
        (ref, np.asarray(also_show, dtype=float).reshape(-1, 2)))
    view = route_view(pts, network.bounds)
    if ax is None:
        ratio = (view[3] - view[2]) / max(view[1] - view[0], 1e-9)
        ax = Figure(figsize=(9.0, float(np.clip(7.6 * ratio + 1.8, 4.5, 10.5))),
                    layout="constrained").add_subplot()
    plot_network(network, ax, color="0.78", linewidth=0.9, fit=False)
    ax.set_xlim(view[0], view[1])
    ax.set_ylim(view[2], view[3])
    ax.set_aspect("equal", adjustable="box")
    c, lw, alpha = ROUTE_BAND
    ax.plot(ref[:, 0], ref[:, 1], color=c, linewidth=lw, alpha=alpha, zorder=3,
            solid_capstyle="round", solid_joinstyle="round", gid="route",
            label=f"planned route ({len(route.edges)} edges, {route.length:.0f} m)")
    ax.plot(*ref[0], marker="o", color="tab:green", mec="k", markersize=10, zorder=6,
            linestyle="none", gid="start", label=f"start: {route.edges[0]}")
    ax.plot(*ref[-1], marker="*", color="tab:red", mec="k", markersize=15, zorder=6,
            linestyle="none", gid="goal", label=f"goal: {route.edges[-1]}")
    ax.set_title(title or f"{network.path.name}: {route.edges[0]} -> {route.edges[-1]} "
                 f"({route.vclass}, by {route.weight})")
    _draw_overview(ax, network, ref, view, pts)
    if legend:
        _legend([ax])
    if path is not None:
        _save(ax, path)
    return ax


def _lane_lines(network: RoadNetwork) -> list[Any]:
    segs = [ln.shape for lanes in network.lanes for ln in lanes if len(ln.shape) >= 2]
    segs += [ln.shape for ln in network.internal_lanes.values() if len(ln.shape) >= 2]
    return segs


def _draw_overview(ax: Any, network: RoadNetwork, ref: Any,
                   view: tuple[float, float, float, float], pts: Any) -> None:
    """The whole network in a corner of ``ax``, with the route and the view's outline."""
    nx0, ny0, nx1, ny1 = network.bounds
    nw, nh = max(nx1 - nx0, 1.0), max(ny1 - ny0, 1.0)
    vw, vh = view[1] - view[0], view[3] - view[2]
    if vw * vh >= OVERVIEW_BELOW * nw * nh:
        return
    # the inset, in fractions of the axes, keeps the network's aspect: h / w in axes
    # fractions is the network's height / width over the view's
    side = 0.32
    ratio = (nh / nw) * (vw / vh)
    w, h = (side / ratio, side) if ratio > 1.0 else (side, side * ratio)
    frac = (np.asarray(pts, dtype=float) - [view[0], view[2]]) / [vw, vh]
    corners = [(0.01, 0.01), (0.99 - w, 0.01), (0.01, 0.99 - h), (0.99 - w, 0.99 - h)]
    hits = [int(np.sum((frac[:, 0] >= x - 0.03) & (frac[:, 0] <= x + w + 0.03)
                       & (frac[:, 1] >= y - 0.03) & (frac[:, 1] <= y + h + 0.03)))
            for x, y in corners]
    x, y = corners[int(np.argmin(hits))]
    ins = ax.inset_axes((x, y, w, h), gid="overview", zorder=10)
    ins.add_collection(LineCollection(_lane_lines(network), colors="0.6", linewidths=0.3))
    ins.plot(ref[:, 0], ref[:, 1], color=ROUTE_BAND[0], lw=2.0)
    ins.add_patch(Rectangle((view[0], view[2]), vw, vh, fill=False, ec="k", lw=1.0))
    ins.set_xlim(nx0, nx1)
    ins.set_ylim(ny0, ny1)
    ins.set_aspect("equal", adjustable="datalim")
    ins.set_xticks([])
    ins.set_yticks([])
    ins.set_facecolor("white")
    ins.text(0.02, 0.98, "whole network", transform=ins.transAxes, ha="left", va="top",
             fontsize="x-small")


class _GradientLine(HandlerBase):
    """Legend entry of a line coloured by a colour map along its length, as it is drawn."""

    def create_artists(self, legend: Any, orig_handle: Any, xdescent: float, ydescent: float,
                       width: float, height: float, fontsize: float, trans: Any) -> list[Any]:
        x = np.linspace(-xdescent, width - xdescent, 13)
        y = np.full_like(x, height / 2.0 - ydescent)
        pts = np.column_stack((x, y))
        lc = LineCollection(list(np.stack((pts[:-1], pts[1:]), axis=1)), cmap=orig_handle.cmap,
                            norm=Normalize(0.0, 1.0), transform=trans,
                            linewidths=orig_handle.get_linewidth())
        lc.set_array(np.linspace(0.15, 0.95, 12))
        return [lc]


def _speed_line(xy: Any, speed: Any, s_max: float, *, lw: float, gid: str, zorder: float,
                label: str | None) -> LineCollection:
    """A polyline ``(n, 2)`` coloured by speed [m/s] on the fixed scale 0 .. ``s_max``."""
    pts = np.asarray(xy, dtype=float)
    v = np.asarray(speed, dtype=float)
    lc = LineCollection(list(np.stack((pts[:-1], pts[1:]), axis=1)), cmap=SPEED_CMAP,
                        norm=Normalize(vmin=0.0, vmax=float(s_max)), linewidths=lw,
                        zorder=zorder, gid=gid, label=label, capstyle="round")
    lc.set_array((v[:-1] + v[1:]) / 2.0)
    return lc


def _speed_scale(s_max: float | None, speed: Any) -> float:
    """Top of the speed colour scale [m/s]: ``s_max`` when known, else the default
    ``TrajectoryParams.s_max`` (or the fastest sample, if faster)."""
    if s_max is not None and s_max > 0:
        return float(s_max)
    from splineplan.trajectory_params import TrajectoryParams

    v = np.asarray(speed, dtype=float)
    return max(TrajectoryParams().s_max, float(np.max(v)) if len(v) else 0.0)


# ---- the paper's figures 2 and 4, and the speed profile -----------------------------------

#: Colours of the planning figures (road, obstacles, roadmap, chosen path).
PLAN_COLOURS = {
    "road": "#eeeeee",
    "edge": "#333333",
    "obstacle": "#555555",
    "sweep": "#9e9e9e",
    "interval": "#2e7d32",
    "graph": "#1f77b4",
    "path": "#d62728",
}


@dataclass(frozen=True)
class _Frame:
    """Where a plan figure draws: x-y [m], or the road's frame (station, lateral offset)."""

    corridor: Corridor
    road: bool

    def sl(self, s: Any, l: Any) -> Any:  # noqa: E741
        """Points ``(..., 2)`` at stations ``s`` and lateral offsets ``l`` of the corridor."""
        if self.road:
            s_arr, l_arr = np.broadcast_arrays(np.asarray(s, float), np.asarray(l, float))
            return np.stack((s_arr, l_arr), axis=-1)
        return self.corridor.to_xy(s, l)

    def xy(self, points: Any) -> Any:
        """Points ``(..., 2)`` given in x-y [m], in this frame."""
        pts = np.asarray(points, dtype=float)
        if not self.road or pts.size == 0:
            return pts
        return self.corridor.to_sl(pts.reshape(-1, 2)).reshape(pts.shape)


def plot_roadmap(
    roadmap: Roadmap | Sequence[Roadmap],
    corridor: Corridor,
    obstacles: Obstacles,
    ax: Any = None,
    *,
    path: str | PathLike[str] | None = None,
    title: str | None = "Roadmap: sweep lines, free intervals and the widest path",
    frame: str = "auto",
) -> Any:
    """The paper's Fig. 2: sweep lines, free intervals, the roadmap graph, the chosen path.

    Sweep lines cross the road at each station of the graph; the free intervals are those
    of the grown obstacles (so a vertex anywhere on one keeps the ego clear); arcs join the
    vertices of consecutive lines; the chosen widest-then-shortest path is drawn on top
    with its bottleneck (narrowest vertex) marked. Several roadmaps (one per road segment,
    each with stations from its segment's start) are drawn together along ``corridor``.

    Parameters
    ----------
    roadmap
        One :class:`~splineplan.roadmap.Roadmap` or a sequence of them.
    corridor, obstacles
        The road and obstacles the roadmap was planned on.
    ax
        Axes to draw into; a new figure when ``None``.
    path
        Where to save the figure (format from the suffix), if given.
    frame
        ``"xy"``, ``"road"`` (station against lateral offset, stacked panels of at most
        :data:`PANEL_LENGTH` m when ``ax`` is ``None``) or ``"auto"`` (the road's frame
        for corridors longer than :data:`ROAD_FRAME_FROM` m).

    Returns
    -------
    The axes (the first panel's; all are in ``ax.figure.axes``); artists carry gids
    ``sweep_lines``, ``free_intervals``, ``roadmap_arcs``, ``roadmap_vertices``,
    ``widest_path``, ``bottleneck``.
    """
    maps = _roadmap_list(roadmap)
    axes, fr = _plan_axes(ax, corridor, frame)
    sweep: list[Any] = []
    intervals: list[Any] = []
    for rm in maps:
        shift = _station_shift(rm, corridor)
        first = np.unique(rm.graph_line, return_index=True)[1]
        s_line = rm.graph_s[first] + shift
        lo, hi = corridor.bounds_at(s_line)
        sweep.extend(np.stack((fr.sl(s_line, lo), fr.sl(s_line, hi)), axis=1))
        s_v = rm.graph_s + shift
        intervals.extend(np.stack((fr.sl(s_v, rm.graph_lo), fr.sl(s_v, rm.graph_hi)), axis=1))
    arcs = np.concatenate([fr.xy(rm.graph_xy[rm.arcs]) for rm in maps])
    gxy = fr.xy(np.concatenate([rm.graph_xy for rm in maps]))
    pxy = fr.xy(np.concatenate([rm.xy for rm in maps]))
    worst = min(maps, key=lambda rm: rm.bottleneck_width)
    bxy = fr.xy(worst.xy[worst.bottleneck_index][None])[0]
    st = fr.xy(maps[0].start_xy[None])[0]
    d = maps[0].params.d
    for a in axes:
        _draw_road(a, fr)
        _draw_obstacles(a, obstacles, fr)
        a.add_collection(LineCollection(sweep, colors=PLAN_COLOURS["sweep"], linewidths=0.5,
                                        linestyles="--", gid="sweep_lines", zorder=2,
                                        label=f"sweep lines (every {d:g} m)"))
        a.add_collection(LineCollection(intervals, colors=PLAN_COLOURS["interval"],
                                        linewidths=2.0, gid="free_intervals", zorder=3,
                                        alpha=0.6, label="free intervals (grown obstacles)"))
        a.add_collection(LineCollection(list(arcs), colors=PLAN_COLOURS["graph"],
                                        linewidths=0.6, gid="roadmap_arcs", zorder=4,
                                        alpha=0.7, label="roadmap arcs"))
        a.scatter(gxy[:, 0], gxy[:, 1], s=6, color=PLAN_COLOURS["graph"], zorder=5,
                  gid="roadmap_vertices", label="roadmap vertices (interval midpoints)")
        a.plot(pxy[:, 0], pxy[:, 1], color=PLAN_COLOURS["path"], lw=2.0, zorder=6,
               gid="widest_path", label="chosen widest path")
        a.plot([bxy[0]], [bxy[1]], marker="*", ms=14, color="gold", mec="k", ls="none",
               zorder=7, gid="bottleneck",
               label=f"bottleneck: free width {worst.bottleneck_width:.2f} m")
        a.plot([st[0]], [st[1]], marker="o", ms=7, color="k", ls="none", zorder=7,
               gid="start", label="start")
    _finish(axes, fr, title, path)
    return axes[0]


def plot_trajectory(
    trajectory: Any,
    corridor: Corridor,
    obstacles: Obstacles,
    roadmap: Roadmap | Sequence[Roadmap] | None = None,
    ax: Any = None,
    *,
    path: str | PathLike[str] | None = None,
    footprint_every: float | None = None,
    vehicle_size: tuple[float, float] | None = None,
    s_max: float | None = None,
    cmap: str = SPEED_CMAP,
    title: str | None = "Trajectory coloured by speed",
    frame: str = "auto",
) -> Any:
    """The paper's Fig. 4: road segment, obstacles, roadmap and the trajectory by speed.

    Parameters
    ----------
    trajectory
        A :class:`~splineplan.trajectory.Trajectory` or anything with the sample arrays
        ``x, y, heading, speed`` ``(n,)`` (e.g. :class:`splineplan.io.TrajectorySamples`).
    corridor, obstacles
        The road and the obstacles.
    roadmap
        The level-2 roadmap(s), drawn as their chosen path's vertices, if given.
    ax
        Axes to draw into; a new figure when ``None``.
    path
        Where to save the figure, if given.
    footprint_every
        Draw the vehicle's outline every so many metres [m] along the curve.
    vehicle_size
        Length and width [m] of the outline (default: the roadmap's vehicle, else 4.5 x 1.8).
    s_max
        Top of the speed colour scale [m/s], the trajectory's speed limit (default:
        :func:`_speed_scale`); the scale starts at 0, so colours mean the same speed in
        every picture.
    cmap
        Colour map of the speed.
    frame
        ``"xy"``, ``"road"`` or ``"auto"``, as in :func:`plot_roadmap`.

    Returns
    -------
    The axes (the first panel's); the curve is a LineCollection with gid
    ``trajectory_speed`` (colour scale 0 .. ``s_max``, with a colour bar), over a thin
    Line2D with gid ``trajectory`` whose data are the trajectory's points in the frame
    drawn (x and y in ``"xy"``).
    """
    maps = _roadmap_list(roadmap) if roadmap is not None else []
    axes, fr = _plan_axes(ax, corridor, frame)
    x = np.asarray(trajectory.x, dtype=float)
    y = np.asarray(trajectory.y, dtype=float)
    v = np.asarray(trajectory.speed, dtype=float)
    top = _speed_scale(s_max, v)
    pts = fr.xy(np.column_stack((x, y)))
    rms = [fr.xy(rm.xy) for rm in maps]
    cp = getattr(trajectory, "control_points", None)
    cp = fr.xy(np.asarray(cp, dtype=float)) if cp is not None and len(cp) else None
    feet = None
    if footprint_every:
        if vehicle_size is None:
            vehicle_size = ((maps[0].params.vehicle_length, maps[0].params.vehicle_width)
                            if maps else (4.5, 1.8))
        feet = fr.xy(_footprints(trajectory, footprint_every, vehicle_size))
    lc = None
    for a in axes:
        _draw_road(a, fr)
        _draw_obstacles(a, obstacles, fr)
        for i, r in enumerate(rms):
            a.plot(r[:, 0], r[:, 1], ls=":", marker="o", ms=3, lw=0.8,
                   color=PLAN_COLOURS["graph"], zorder=4, gid="roadmap_path",
                   label="roadmap (level 2)" if i == 0 else None)
        if cp is not None:
            a.plot(cp[:, 0], cp[:, 1], ls="none", marker="x", ms=4, color="#7b1fa2",
                   zorder=5, gid="control_points", label="spline control points")
        if feet is not None:
            a.add_collection(PolyCollection(list(feet), facecolors="none",
                                            edgecolors="#424242", linewidths=0.5, zorder=5,
                                            gid="footprints",
                                            label=f"vehicle every {footprint_every:g} m"))
        a.plot(pts[:, 0], pts[:, 1], color="k", lw=0.6, zorder=6, gid="trajectory")
        lc = _speed_line(pts, v, top, lw=3.0, gid="trajectory_speed", zorder=7,
                         label="trajectory (level 3), coloured by speed")
        lc.set_cmap(cmap)
        a.add_collection(lc)
        a.plot([pts[0, 0]], [pts[0, 1]], marker="o", color="k", ms=6, ls="none", zorder=8,
               gid="start", label="start")
        a.plot([pts[-1, 0]], [pts[-1, 1]], marker="s", color="k", ms=6, ls="none", zorder=8,
               gid="end", label="end")
    cb = axes[0].figure.colorbar(lc, ax=list(axes), fraction=0.03, pad=0.02)
    cb.set_label("speed [m/s]")
    _finish(axes, fr, title, path)
    return axes[0]


def plot_turn(
    network: RoadNetwork,
    plan: Any,
    *,
    junction: str | None = None,
    margin: float = 25.0,
    s_max: float | None = None,
    kappa_max: float | None = None,
    car: CarShape | None = None,
    path: str | PathLike[str] | None = None,
    title: str | None = None,
) -> Any:
    """A junction turn as the planner took it: the drivable area (the planner's corridor)
    over SUMO's paving (the junction's outline, the route's lanes and the internal lanes
    of its connections), level 2's roadmap, the footprint swept along the curve, the curve
    coloured by speed and the limits it breaks; beside it, the curvature along the curve
    against the turning limit, with the stretch inside the junction shaded.

    Parameters
    ----------
    network
        The network the plan was made on.
    plan
        A :class:`~splineplan.pipeline.Plan` (route, corridor, roadmaps, trajectory).
    junction
        Id of the junction to draw (default: the first one the route crosses).
    margin
        Room [m] around the junction's outline in the view.
    s_max, kappa_max
        Top of the speed colour scale [m/s] and the turning limit [1/m] (defaults: those of
        :class:`~splineplan.trajectory.TrajectoryParams`).
    car
        The car whose turn it is (default :class:`~splineplan.network.CarShape`'s): where
        level 1 found the turn only by its search, that path is drawn.

    Returns
    -------
    The figure; artists with gids ``drivable_area``, ``paved_area`` (the junctions'
    paving beside the corridor's lanes, where the corridor knows it), ``junction``,
    ``lanes``,
    ``internal_lanes``, ``searched_path`` (where level 1 found the turn only by its
    search), ``swept``, ``trajectory_speed``, ``violations`` (where the curve breaks a
    limit), ``curvature`` and ``kappa_max``.
    """
    from splineplan.network import CarShape, searched_path
    from splineplan.trajectory import TrajectoryParams

    tp = TrajectoryParams()
    top = s_max if s_max is not None else tp.s_max
    kmax = kappa_max if kappa_max is not None else tp.kappa_max
    tr, corridor, edges = plan.trajectory, plan.corridor, tuple(plan.route.edges)
    jid = junction if junction is not None or len(edges) < 2 else network.to_node(edges[0])
    shape = network.junction_shapes.get(jid) if jid is not None else None
    fig = Figure(figsize=(11.0, 5.6), layout="constrained")
    ax, axk = fig.subplots(1, 2, width_ratios=(1.35, 1.0))
    wide = corridor.paved()
    if wide is not None:
        paving = wide.polygon()
        ax.fill(paving[:, 0], paving[:, 1], color="#dcedc8", zorder=-1, gid="paved_area",
                label="junction paving, taken where the lanes give no feasible curve")
    area = corridor.polygon()
    ax.fill(area[:, 0], area[:, 1], color="#e3f2fd", zorder=0, gid="drivable_area",
            label="drivable area (the planner's corridor)")
    lanes = [_lane_outline(ln.shape, ln.width) for e in edges
             for ln in network.lanes[network.edge_index(e)]]
    ax.add_collection(PolyCollection(lanes, facecolors="none", edgecolors="0.45",
                                     linewidths=0.7, zorder=1, gid="lanes",
                                     label="lanes of the route (SUMO)"))
    via = {v for c in network.connections if c.from_edge in edges and c.to_edge in edges
           for v in c.via}
    inner = [_lane_outline(network.internal_lanes[v].shape, network.internal_lanes[v].width)
             for v in sorted(via) if v in network.internal_lanes]
    if inner:
        ax.add_collection(PolyCollection(inner, facecolors="none", edgecolors="0.3",
                                         linewidths=0.7, linestyles="--", zorder=1,
                                         gid="internal_lanes",
                                         label="internal lanes of the turn (SUMO)"))
    if shape is not None and len(shape) >= 3:
        ring = np.vstack((shape, shape[:1]))
        ax.plot(ring[:, 0], ring[:, 1], color="#333333", lw=1.4, zorder=2, gid="junction",
                label=f"junction {jid} (SUMO's outline)")
    found = next((searched_path(network, a, b, plan.route.vclass, car or CarShape())
                  for a, b in itertools.pairwise(edges) if network.to_node(a) == jid), None)
    if found is not None:
        ax.plot(found[:, 0], found[:, 1], color="#6a1b9a", lw=1.2, ls=(0, (4, 2)), zorder=5,
                gid="searched_path",
                label="path level 1 searched for the car (at its turning limit)")
    for i, rm in enumerate(plan.roadmaps):
        ax.plot(rm.xy[:, 0], rm.xy[:, 1], ls="none", marker="o", ms=2.5,
                color=PLAN_COLOURS["graph"], zorder=4, gid="roadmap_path",
                label="roadmap (level 2)" if i == 0 else None)
    size = ((plan.roadmaps[0].params.vehicle_length, plan.roadmaps[0].params.vehicle_width)
            if plan.roadmaps else (4.5, 1.8))
    ax.add_collection(PolyCollection(list(_footprints(tr, 0.5, size)), facecolors="#ff9800",
                                     edgecolors="none", alpha=0.06, zorder=3, gid="swept",
                                     label="footprint swept along the curve"))
    pts = np.column_stack((tr.x, tr.y))
    lc = _speed_line(pts, np.asarray(tr.speed, dtype=float), top, lw=2.5,
                     gid="trajectory_speed", zorder=6,
                     label="trajectory (level 3), coloured by speed")
    lc.set_cmap(SPEED_CMAP)
    ax.add_collection(lc)
    broken = list(getattr(tr, "violations", ()))
    if broken:
        ax.plot([v.x for v in broken], [v.y for v in broken], ls="none", marker="X", ms=9,
                color="#d32f2f", zorder=8, gid="violations",
                label="limit broken (worst point)")
    if shape is not None and len(shape) >= 3:
        lo, hi = shape.min(axis=0) - margin, shape.max(axis=0) + margin
    else:
        lo, hi = pts.min(axis=0), pts.max(axis=0)
    ax.set_xlim(lo[0], hi[0])
    ax.set_ylim(lo[1], hi[1])
    ax.set_aspect("equal", adjustable="box")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    cb = fig.colorbar(lc, ax=ax, fraction=0.04, pad=0.01)
    cb.set_label(f"speed [m/s] (0 .. s_max = {top:.1f})")
    ax.legend(loc="upper left", fontsize="x-small", framealpha=0.85)
    # curvature along the curve, the junction's stretch shaded
    st = corridor.to_sl(pts)[:, 0]
    inside = np.array([corridor.junction_at(float(x)) is not None for x in st])
    axk.plot(tr.s, np.abs(tr.curvature), color="#1565c0", lw=1.5, gid="curvature",
             label="|curvature| of the curve")
    axk.axhline(kmax, color="#c62828", ls="--", lw=1.2, gid="kappa_max",
                label=f"turning limit 1/R = {kmax:.3f} 1/m")
    if inside.any():
        axk.fill_between(tr.s, 0, 1, where=inside, transform=axk.get_xaxis_transform(),
                         color="0.85", zorder=0, gid="in_junction", label="inside a junction")
    for v in broken:
        if v.kind == "curvature":
            axk.plot([v.s], [v.value], marker="X", ms=9, color="#d32f2f", ls="none")
    seen = np.flatnonzero(np.all((pts >= lo) & (pts <= hi), axis=1))
    axk.set_xlim(*((float(tr.s[seen[0]]), float(tr.s[seen[-1]])) if len(seen) > 1
                   else (float(tr.s[0]), float(tr.s[-1]))))
    axk.set_ylim(0.0, max(1.3 * kmax, 1.05 * float(np.max(np.abs(tr.curvature)))))
    axk.set_xlabel("distance along the trajectory s [m]")
    axk.set_ylabel("|curvature| [1/m]")
    axk.grid(True, lw=0.3, alpha=0.5)
    axk.legend(loc="upper right", fontsize="x-small")
    why = "; ".join(v.describe().split(",")[0] for v in broken) if broken else "feasible"
    fig.suptitle(title or f"{' -> '.join(edges)}: {why}", fontsize="medium")
    if path is not None:
        _save(ax, path)
    return fig


def _lane_outline(centre: Any, width: float) -> Any:
    """A lane's outline ``(k, 2)`` [m]: its centre line offset by half its width to each
    side (normals averaged at the vertices)."""
    c = np.asarray(centre, dtype=float)
    d = np.diff(c, axis=0)
    n = np.column_stack((-d[:, 1], d[:, 0])) / np.maximum(np.hypot(*d.T), 1e-9)[:, None]
    normal = np.vstack((n[:1], (n[:-1] + n[1:]) / 2.0, n[-1:]))
    normal /= np.maximum(np.hypot(*normal.T), 1e-9)[:, None]
    return np.vstack((c + normal * width / 2.0, (c - normal * width / 2.0)[::-1]))


def plot_speed_profile(
    trajectory: Any,
    params: Any,
    ax: Any = None,
    *,
    path: str | PathLike[str] | None = None,
    title: str | None = "Speed profile along the trajectory",
) -> Any:
    """Speed along the curve with its limits: cornering (equation 1), the steering rate
    and ``s_max``. The shaded allowed speed takes a point's cornering speed from the
    sharpest curvature within :data:`~splineplan.trajectory.CORNER_REACH`, as the plan
    does; the cornering line is equation (1) at the point itself.

    Parameters
    ----------
    trajectory
        Anything with ``s``, ``speed`` and ``curvature`` arrays ``(n,)``.
    params
        :class:`~splineplan.trajectory.TrajectoryParams` or a mapping with ``mu``, ``g``
        and ``s_max`` (and ``wheelbase`` and ``max_steering_rate``, if the plan had them).
    ax
        Axes to draw into; a new figure when ``None``.
    path
        Where to save the figure, if given.

    Returns
    -------
    The axes; lines with gids ``speed``, ``cornering_limit`` (``sqrt(mu g / |kappa|)``,
    NaN where it exceeds 1.5 ``s_max``), ``steering_limit`` (likewise; where the params
    have the car's steering) and ``s_max``.
    """
    from splineplan.speed import allowed_speed, nearby_curvature, towed_speed_limit
    from splineplan.trajectory import CORNER_REACH

    mu, g, s_max = (_param(params, k) for k in ("mu", "g", "s_max"))
    s = np.asarray(trajectory.s, dtype=float)
    v = np.asarray(trajectory.speed, dtype=float)
    kappa = np.abs(np.asarray(trajectory.curvature, dtype=float))
    with np.errstate(divide="ignore"):
        corner = np.sqrt(mu * g / kappa)
    top = 1.5 * s_max
    corner = np.where(corner <= top, corner, np.nan)
    steer = np.full(len(s), np.nan)
    try:
        wheelbase, rate = (_param(params, k) for k in ("wheelbase", "max_steering_rate"))
    except (KeyError, AttributeError):  # a plan saved before the car's steering was kept
        pass
    else:
        steer = towed_speed_limit(s, np.asarray(trajectory.curvature, dtype=float),
                                  wheelbase=wheelbase, max_steering_rate=rate)
        steer = np.where(steer <= top, steer, np.nan)
    # the plan takes a point's cornering speed from the sharpest curvature within
    # CORNER_REACH of it: the allowed area does so too, the line shows equation (1) itself
    allowed = np.fmin(allowed_speed(nearby_curvature(s, kappa, CORNER_REACH), mu=mu, g=g,
                                    s_max=s_max), steer)
    if ax is None:
        ax = Figure(figsize=(8.0, 3.5), layout="constrained").add_subplot()
    ax.fill_between(s, 0.0, np.nan_to_num(allowed, nan=s_max), color="#e3f2fd",
                    zorder=1, label="allowed (cornering, steering rate and s_max)")
    ax.plot(s, corner, color="#ef6c00", lw=1.2, zorder=3, gid="cornering_limit",
            label=r"cornering limit $\sqrt{\mu g / |\kappa|}$")
    if np.isfinite(steer).any():
        ax.plot(s, steer, color="#6a1b9a", lw=1.0, ls=":", zorder=3, gid="steering_limit",
                label="steering-rate limit")
    ax.axhline(s_max, color="#c62828", ls="--", lw=1.2, zorder=3, gid="s_max",
               label=f"$s_{{max}}$ = {s_max:.2f} m/s")
    ax.plot(s, v, color="#1565c0", lw=2.0, zorder=4, gid="speed", label="planned speed")
    ax.set_xlim(float(s[0]), float(s[-1]))
    ax.set_ylim(0.0, top)
    ax.set_xlabel("distance along the trajectory s [m]")
    ax.set_ylabel("speed [m/s]")
    ax.grid(True, lw=0.3, alpha=0.5)
    _legend([ax])
    if title:
        ax.set_title(title)
    if path is not None:
        _save(ax, path)
    return ax


# -- helpers of the planning figures --------------------------------------------------------
def _roadmap_list(roadmap: Roadmap | Sequence[Roadmap]) -> list[Roadmap]:
    from splineplan.roadmap import Roadmap

    maps = [roadmap] if isinstance(roadmap, Roadmap) else list(roadmap)
    if not maps:
        raise ValueError("no roadmap to draw")
    return maps


def _station_shift(rm: Roadmap, corridor: Corridor) -> float:
    """Station [m] on ``corridor`` of the roadmap's station 0: a road segment's roadmap
    counts its stations from the segment's start."""
    if len(rm.graph_xy) == 0:
        return 0.0
    s_on = corridor.to_sl(rm.graph_xy)[:, 0]
    return float(np.median(s_on - rm.graph_s))


def _plan_axes(ax: Any, corridor: Corridor, frame: str) -> tuple[list[Any], _Frame]:
    """The axes of a plan figure and its frame: one x-y axes for a compact plan, stacked
    panels in the road's frame for a long one (see the module's docstring)."""
    if frame not in ("auto", "xy", "road"):
        raise ValueError(f"frame must be 'auto', 'xy' or 'road', not {frame!r}")
    if ax is not None:
        return [ax], _Frame(corridor, frame == "road")
    road = frame == "road" or (frame == "auto" and corridor.length > ROAD_FRAME_FROM)
    if not road:
        poly = corridor.polygon()
        dx, dy = np.ptp(poly, axis=0) + 1e-9
        width = 11.0
        height = float(np.clip(width * dy / dx + 1.8, 3.0, 9.0))
        return [Figure(figsize=(width, height), layout="constrained").add_subplot()], \
            _Frame(corridor, False)
    n = max(1, math.ceil(corridor.length / PANEL_LENGTH - 1e-9))
    step = corridor.length / n
    lat = _lateral_span(corridor)
    panel_h = 9.6 * (lat[1] - lat[0]) / (step + 2.0)
    heading = np.unwrap(corridor.heading_at(corridor.s))
    bends = float(np.ptp(heading)) > BENDS_FROM
    poly = corridor.polygon()
    dx, dy = np.ptp(poly, axis=0) + 1e-9
    map_h = float(np.clip(9.6 * dy / dx, 1.0, 2.2)) if bends else 0.0
    fig = Figure(figsize=(11.0, n * (panel_h + 0.32) + 1.9 + (map_h + 0.4 if bends else 0.0)),
                 layout="constrained")
    if bends:
        grid = fig.subplots(n + 1, 1, squeeze=False,
                            height_ratios=[map_h + 0.2] + [panel_h + 0.32] * n)[:, 0]
        _draw_road_map(grid[0], corridor, [i * step for i in range(n + 1)])
        axes = list(grid[1:])
    else:
        axes = list(fig.subplots(n, 1, squeeze=False)[:, 0])
    for i, a in enumerate(axes):
        a.set_xlim(i * step - 1.0, (i + 1) * step + 1.0)
        a.set_ylim(*lat)
    return axes, _Frame(corridor, True)


def _draw_road_map(ax: Any, corridor: Corridor, stations: list[float]) -> None:
    """The road in x-y above a road-frame figure, with the panels' first stations marked,
    so that the bends straightened in the panels can be found."""
    poly = corridor.polygon()
    ax.fill(poly[:, 0], poly[:, 1], color="#dddddd", ec=PLAN_COLOURS["edge"], lw=0.6)
    ref = corridor.reference
    ax.plot(ref[:, 0], ref[:, 1], color="0.5", lw=0.6, ls="--")
    marks = corridor.to_xy(stations, np.zeros(len(stations)))
    ax.plot(marks[:, 0], marks[:, 1], ls="none", marker="|", ms=12, mew=1.5, color="k")
    for st, (x, y) in zip(stations, marks, strict=True):
        ax.annotate(f"s = {st:.0f} m", (x, y), xytext=(4, 4), textcoords="offset points",
                    fontsize="x-small")
    lo, hi = poly.min(axis=0), poly.max(axis=0)
    pad = 0.06 * float(np.max(hi - lo))
    ax.set_xlim(lo[0] - pad, hi[0] + pad)
    ax.set_ylim(lo[1] - pad, hi[1] + pad)
    ax.set_aspect("equal", adjustable="box")
    ax.set_xlabel("x [m]", fontsize="small")
    ax.set_ylabel("y [m]", fontsize="small")
    ax.tick_params(labelsize="x-small")
    ax.set_title("the road in x-y (panels below start at the marked stations)",
                 fontsize="small")
    ax.set_gid("road_map")


def _lateral_span(corridor: Corridor) -> tuple[float, float]:
    lo, hi = float(np.min(corridor.right)), float(np.max(corridor.left))
    m = max(1.0, 0.1 * (hi - lo))
    return lo - m, hi + m


def _draw_road(ax: Any, fr: _Frame) -> None:
    c = fr.corridor
    right, left = fr.sl(c.s, c.right), fr.sl(c.s, c.left)
    poly = np.concatenate((right, left[::-1]))
    ax.fill(poly[:, 0], poly[:, 1], color=PLAN_COLOURS["road"], zorder=0, gid="road",
            label="road")
    for i, b in enumerate((left, right)):
        ax.plot(b[:, 0], b[:, 1], color=PLAN_COLOURS["edge"], lw=1.2, zorder=1,
                gid="road_edge", label="road edge" if i == 0 else None)


def _draw_obstacles(ax: Any, obstacles: Obstacles, fr: _Frame) -> None:
    if len(obstacles) == 0:
        return
    polys = [fr.xy(p) for p in obstacles.polygons()]
    if fr.road:  # only those beside the road: the projection of far ones means nothing
        lat = _lateral_span(fr.corridor)
        reach = lat[1] - lat[0]
        polys = [p for p in polys if np.any((p[:, 0] > -5.0)
                                            & (p[:, 0] < fr.corridor.length + 5.0)
                                            & (p[:, 1] > lat[0] - reach)
                                            & (p[:, 1] < lat[1] + reach))]
    ax.add_collection(PolyCollection(polys, facecolors=PLAN_COLOURS["obstacle"],
                                     edgecolors=PLAN_COLOURS["obstacle"], linewidths=0.3,
                                     zorder=2, gid="obstacles", label="obstacles"))


def _footprints(trajectory: Any, every: float, size: tuple[float, float]) -> Any:
    """The vehicle's outline ``(k, 4, 2)`` [m] every ``every`` metres along the curve."""
    from splineplan.geometry import box_corners

    s = np.asarray(trajectory.s, dtype=float)
    at = np.arange(s[0], s[-1] + 1e-9, every)
    x = np.interp(at, s, trajectory.x)
    y = np.interp(at, s, trajectory.y)
    h = np.interp(at, s, np.unwrap(trajectory.heading))
    return box_corners(np.column_stack((x, y)), h, np.full(len(at), size[0]),
                       np.full(len(at), size[1]))


def _finish(axes: list[Any], fr: _Frame, title: str | None,
            path: str | PathLike[str] | None) -> None:
    if fr.road:
        for a in axes:
            a.set_aspect("equal", adjustable="box")
            a.set_ylabel("lateral l [m]")
            a.tick_params(labelsize="small")
        axes[-1].set_xlabel("station along the road s [m] (lateral offset l: left of the "
                            "road's centre line is positive; true scale)")
    else:
        for a in axes:
            a.set_aspect("equal", adjustable="datalim")
            a.autoscale_view()
            a.set_xlabel("x [m]")
            a.set_ylabel("y [m]")
    if title:
        if len(axes) > 1:
            axes[0].figure.suptitle(title)
        else:
            axes[0].set_title(title)
    _legend(axes)
    if path is not None:
        _save(axes[0], path)


def _legend(axes: list[Any]) -> None:
    """Legend below the axes: outside the figure's plot area when the axes fill the figure
    (one axes, or stacked panels), else inside. Lines coloured by speed get an entry
    coloured the same way."""
    ax = axes[0]
    fig = ax.figure
    handles, labels = ax.get_legend_handles_labels()
    hmap: dict[Any, Any] = {h: _GradientLine() for h in handles
                            if isinstance(h, LineCollection) and h.get_array() is not None}
    own = len(axes) == len([a for a in fig.axes if not hasattr(a, "_colorbar")
                            and a.get_gid() not in ("overview", "road_map")])
    if own and fig.get_layout_engine() is not None:
        fig.legend(handles, labels, loc="outside lower center", ncol=4, fontsize="small",
                   frameon=False, handler_map=hmap)
    else:
        ax.legend(handles, labels, loc="best", fontsize="small", handler_map=hmap)


def _save(ax: Any, path: str | PathLike[str]) -> None:
    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    ax.figure.savefig(p, dpi=150)


def _param(params: Any, name: str) -> float:
    value = params[name] if isinstance(params, Mapping) else getattr(params, name)
    return float(value)


# ---- figures of run folders ----------------------------------------------------------------
def plot_plan_folder(
    run_dir: str | PathLike[str],
    *,
    out_dir: str | PathLike[str] | None = None,
    fmt: str = "png",
) -> list[str]:
    """Figures of a plan folder (``plan.json``, see :mod:`splineplan.io`).

    Writes ``roadmap.<fmt>`` (Fig. 2), ``trajectory.<fmt>`` (Fig. 4) and ``speed.<fmt>``
    (the speed profile with its limits); a figure whose content the folder lacks (no
    roadmap, no trajectory) is skipped with a warning in the log. Returns the files written.
    """
    from splineplan.io import load_plan
    from splineplan.trajectory import TrajectoryParams

    saved = load_plan(Path(run_dir))
    dest = Path(out_dir) if out_dir is not None else Path(run_dir)
    written: list[str] = []
    if saved.roadmaps:
        p = dest / f"roadmap.{fmt}"
        plot_roadmap(saved.roadmaps, saved.corridor, saved.obstacles, path=p)
        written.append(str(p))
    else:
        log.warning("%s holds no roadmap: roadmap.%s not drawn", run_dir, fmt)
    tr = saved.trajectory
    if tr is not None and len(tr.x) >= 2:
        params = saved.trajectory_params or TrajectoryParams()
        p = dest / f"trajectory.{fmt}"
        plot_trajectory(tr, saved.corridor, saved.obstacles, saved.roadmaps or None, path=p,
                        footprint_every=10.0, s_max=_param(params, "s_max"))
        written.append(str(p))
        p = dest / f"speed.{fmt}"
        plot_speed_profile(tr, params, path=p)
        written.append(str(p))
    else:
        log.warning("%s holds no trajectory: trajectory.%s and speed.%s not drawn", run_dir,
                    fmt, fmt)
    return written


def plot_run_folder(
    run_dir: str | PathLike[str],
    *,
    out_dir: str | PathLike[str] | None = None,
    fmt: str = "png",
) -> list[str]:
    """Figures of a simulation run folder (``metrics.json``, ``trajectory.csv``).

    Writes ``route.<fmt>`` and ``speed_time.<fmt>`` as drawn by :func:`run_figures`; a
    figure with nothing to draw is not written (a warning in the log says so). Returns the
    files written.
    """
    dest = Path(out_dir) if out_dir is not None else Path(run_dir)
    written: list[str] = []
    for name, ax in run_figures(run_dir).items():
        p = dest / f"{name}.{fmt}"
        _save(ax, p)
        written.append(str(p))
    return written


def run_figures(run_dir: str | PathLike[str]) -> dict[str, Any]:
    """The figures of a simulation run folder, by name: ``route`` and ``speed_time`` axes.

    ``route`` (Fig. 3) is the planned route on the network around it (:func:`plot_route`)
    with the driven path coloured by speed on the scale 0 .. ``s_max`` (gid
    ``driven_speed``); without a readable scenario network, only the driven path.
    ``speed_time`` is the speed over time. A run that did not arrive says so in the titles,
    with the reason from ``metrics.json``. A figure with nothing to draw (no driven path
    and no network; no speed samples) is left out, with a warning in the log, rather than
    drawn blank.
    """
    import json

    from splineplan.errors import SplineplanError
    from splineplan.io import read_trajectory_csv

    run = Path(run_dir)
    metrics = json.loads((run / "metrics.json").read_text())
    driven: Any = None
    try:
        driven = read_trajectory_csv(run / "trajectory.csv")
    except SplineplanError as err:
        log.warning("no driven path in %s: %s", run, err)
    moved = driven is not None and len(driven.x) >= 2
    name = metrics.get("scenario", run.name)
    status = str(metrics.get("status") or "unknown")
    reason = str(metrics.get("reason") or "")
    failed = not metrics.get("arrived", status == "arrived")
    why = reason if failed else ""
    s_max = metrics.get("s_max")
    figures: dict[str, Any] = {}
    ax = None
    edges = tuple(metrics.get("route") or ())
    if edges and metrics.get("scenario_file"):
        try:
            from splineplan.network import load_network
            from splineplan.route import Route
            from splineplan.scenario import load_scenario

            sc = load_scenario(metrics["scenario_file"])
            net = load_network(sc.network)
            route = Route(edges, float(metrics.get("route_length") or 0.0), 0.0, "length",
                          sc.ego.vclass)
            s_max = s_max or sc.trajectory.s_max
            head = (f"{name}: route and driven path ({metrics.get('driver')}, {status})"
                    if moved else f"{name}: planned route; not driven ({status})")
            ax = plot_route(net, route, title=_title(head, why), legend=False,
                            also_show=np.column_stack((driven.x, driven.y)) if moved else None)
        except (SplineplanError, OSError, KeyError, AttributeError) as err:
            log.warning("no network picture for %s: %s", run, err)
            ax = None
    fresh = ax is None
    if ax is None and moved:
        ax = Figure(figsize=(8, 6), layout="constrained").add_subplot()
        ax.set_title(_title(f"{name}: driven path ({status})", why))
        ax.set_aspect("equal", adjustable="datalim")
        ax.set_xlabel("x [m]")
        ax.set_ylabel("y [m]")
    if ax is None:
        log.warning("%s: the run has no driven path and its network is not readable: no "
                    "route figure (%s: %s)", run, status, reason)
    else:
        if moved:
            top = _speed_scale(s_max, driven.speed)
            lc = _speed_line(np.column_stack((driven.x, driven.y)), driven.speed, top, lw=2.2,
                             gid="driven_speed", zorder=5, label="driven path, coloured by speed")
            ax.add_collection(lc)
            if failed:
                ax.plot([driven.x[-1]], [driven.y[-1]], marker="X", color="k", ms=9,
                        ls="none", zorder=7, gid="driven_end", label="where the ego stopped")
            ax.figure.colorbar(lc, ax=ax, fraction=0.04, pad=0.02, shrink=0.8) \
                .set_label(f"speed [m/s] (0 .. s_max = {top:.1f})")
            if fresh:
                ax.autoscale_view()
        _legend([ax])
        figures["route"] = ax
    if moved:
        ax2 = Figure(figsize=(8.0, 3.5), layout="constrained").add_subplot()
        ax2.plot(driven.t, driven.speed, color="#1565c0", lw=1.5, gid="speed", label="speed")
        if s_max:
            ax2.axhline(float(s_max), color="#c62828", ls="--", lw=1.0, gid="s_max",
                        label=f"$s_{{max}}$ = {float(s_max):.2f} m/s")
        ax2.set_ylim(bottom=0.0)
        ax2.set_xlabel("time t [s]")
        ax2.set_ylabel("speed [m/s]")
        ax2.set_title(_title(f"{name}: speed over time ({status})", why))
        ax2.grid(True, lw=0.3, alpha=0.5)
        ax2.legend(loc="best", fontsize="small")
        figures["speed_time"] = ax2
    else:
        log.warning("%s: the ego did not move: no speed-over-time figure (%s: %s)", run,
                    status, reason)
    return figures


def _title(head: str, reason: str) -> str:
    """A title with the run's failure reason (if any) wrapped below it."""
    if not reason:
        return head
    return head + "\n" + textwrap.fill(reason, 90)


# ---- scenario bench ------------------------------------------------------------------------

#: Colour and marker of each bench driver.
BENCH_STYLE = {
    "planner": ("#1565c0", "o", "splineplan"),
    "sumo": ("#c62828", "s", "SUMO default"),
    "sublane": ("#2e7d32", "^", "SUMO sublane"),
}


def plot_bench(
    rows: Sequence[Mapping[str, Any]],
    out_dir: str | PathLike[str],
    *,
    fmt: str = "png",
) -> list[str]:
    """Figures of a scenario bench (rows of ``runs.csv``, :mod:`splineplan.bench`).

    Writes ``bench_success.<fmt>`` (success rate [%]: safe arrivals, without a collision
    or time off the road, against obstacle density, per driver),
    ``bench_clearance.<fmt>`` (each run's minimum clearance [m] against density, with the
    median per tier) and ``bench_travel_time.<fmt>`` (travel time [s] of the runs that
    arrived, by tier and driver: a labelled bar at the median, each run a marker, drivers
    told apart by colour, hatch and marker; a driver with no arrival in a tier is named
    there). Density: stopped vehicles per 100 m of road; only the
    generated fields have one. Returns the files written.
    """
    out = Path(out_dir)
    drivers = list(dict.fromkeys(str(r["driver"]) for r in rows))
    tiers = list(dict.fromkeys(str(r["tier"]) for r in rows))
    gen = [r for r in rows if r.get("density") is not None]
    written = []

    def style(d: str) -> tuple[str, str, str]:
        return BENCH_STYLE.get(d, ("0.3", "x", d))

    # success rate against density: one point per (driver, tier), at the tier's mean density
    ax = Figure(figsize=(7.0, 4.5), layout="constrained").add_subplot()
    for d in drivers:
        pts = []
        for t in tiers:
            sel = [r for r in gen if r["driver"] == d and r["tier"] == t]
            if sel:
                pts.append((float(np.mean([float(r["density"]) for r in sel])),
                            100.0 * float(np.mean([bool(r.get("safe", r["arrived"]))
                                                   for r in sel])), t))
        if not pts:
            continue
        pts.sort()
        c, m, name = style(d)
        ax.plot([p[0] for p in pts], [p[1] for p in pts], color=c, marker=m, lw=1.5,
                ls=("-", "--", ":")[drivers.index(d) % 3], ms=9 - 2 * drivers.index(d),
                label=name, gid=f"success_{d}")
        if d == drivers[0]:
            for px, _, t in pts:
                ax.annotate(t, (px, 103.0), ha="center", fontsize="x-small", color="0.35")
    ax.set_ylim(-5.0, 110.0)
    ax.set_xlabel("obstacle density [stopped vehicles per 100 m]")
    ax.set_ylabel("success rate [%]")
    ax.set_title("Runs that arrived safely (no collision, on the road), by obstacle density")
    ax.grid(True, lw=0.3, alpha=0.5)
    if ax.get_legend_handles_labels()[0]:  # none without generated fields
        ax.legend(loc="lower left", fontsize="small")
    p = out / f"bench_success.{fmt}"
    _save(ax, p)
    written.append(str(p))

    # clearance against density: every run, plus the median per (driver, tier)
    ax = Figure(figsize=(7.0, 4.5), layout="constrained").add_subplot()
    for k, d in enumerate(drivers):
        sel = [r for r in gen if r["driver"] == d and r.get("min_clearance") is not None]
        if not sel:
            continue
        c, m, name = style(d)
        x = np.array([float(r["density"]) for r in sel])
        y = np.array([float(r["min_clearance"]) for r in sel])
        jitter = (k - (len(drivers) - 1) / 2.0) * 0.06
        ax.scatter(x + jitter, y, color=c, marker=m, s=18, alpha=0.45, gid=f"clearance_{d}",
                   label=f"{name}: each run")
        med = sorted({(float(np.mean(x[[r['tier'] == t for r in sel]])),
                       float(np.median(y[[r['tier'] == t for r in sel]])))
                      for t in tiers if any(r["tier"] == t for r in sel)})
        ax.plot([q[0] for q in med], [q[1] for q in med], color=c, lw=1.5,
                label=f"{name}: median per tier")
    ax.axhline(0.0, color="k", lw=0.8)
    ax.set_xlabel("obstacle density [stopped vehicles per 100 m]")
    ax.set_ylabel("minimum clearance to other vehicles [m]")
    ax.set_title("Clearance by obstacle density")
    ax.grid(True, lw=0.3, alpha=0.5)
    if ax.get_legend_handles_labels()[0]:
        ax.legend(loc="best", fontsize="small")
    p = out / f"bench_clearance.{fmt}"
    _save(ax, p)
    written.append(str(p))

    ax = _bench_travel_time(rows, drivers, tiers)
    p = out / f"bench_travel_time.{fmt}"
    _save(ax, p)
    written.append(str(p))
    return written


def _bench_travel_time(rows: Sequence[Mapping[str, Any]], drivers: list[str],
                       tiers: list[str]) -> Any:
    """Travel time [s] by tier and driver: the axes of ``bench_travel_time``."""

    def style(d: str) -> tuple[str, str, str]:
        return BENCH_STYLE.get(d, ("0.3", "x", d))

    # travel time by tier and driver: a bar at the median of the runs that arrived, each
    # run a marker on it, the value written above; drivers told apart by colour, hatch
    # and marker; a driver that never arrived in a tier says so where its bar would be
    ax = Figure(figsize=(max(6.5, 0.9 * len(tiers) * max(len(drivers), 1) + 2.5), 4.8),
                layout="constrained").add_subplot()
    width = 0.8 / max(len(drivers), 1)
    hatches = ("", "//", "..", "xx", "\\\\", "++")
    top = max([float(r["travel_time"]) for r in rows if r.get("arrived")
               and r.get("travel_time") is not None] or [1.0])
    proxies: list[tuple[Any, str]] = []
    for k, d in enumerate(drivers):
        c, m, name = style(d)
        hatch = hatches[k % len(hatches)]
        for i, t in enumerate(tiers):
            sel = [r for r in rows if r["driver"] == d and r["tier"] == t]
            if not sel:
                continue
            xb = i + (k - (len(drivers) - 1) / 2.0) * width
            tv = [float(r["travel_time"]) for r in sel
                  if r.get("arrived") and r.get("travel_time") is not None]
            if not tv:
                ax.text(xb, 0.02 * top, f"{name}: none of {len(sel)} arrived", rotation=90,
                        ha="center", va="bottom", fontsize="x-small", color=c,
                        gid=f"travel_none_{d}")
                continue
            med = float(np.median(tv))
            ax.bar([xb], [med], width=width * 0.9, color=c, alpha=0.35, edgecolor=c,
                   hatch=hatch, lw=1.2, gid=f"travel_{d}")
            jit = np.linspace(-0.25, 0.25, len(tv)) * width if len(tv) > 1 else np.zeros(1)
            ax.plot(xb + jit, tv, ls="none", marker=m, ms=6, color=c, mec="k", mew=0.6,
                    zorder=4, gid=f"travel_runs_{d}")
            note = f"{med:.1f} s" + (f"\n(median of {len(tv)})" if len(tv) > 1 else "")
            if len(tv) < len(sel):
                note += f"\n{len(sel) - len(tv)} of {len(sel)} not arrived"
            ax.annotate(note, (xb, max(tv)), xytext=(0, 4), textcoords="offset points",
                        ha="center", va="bottom", fontsize="x-small")
        proxies += [(Patch(facecolor=c, alpha=0.35, edgecolor=c, hatch=hatch, lw=1.2),
                     f"{name}: median"),
                    (Line2D([], [], ls="none", marker=m, ms=6, color=c, mec="k", mew=0.6),
                     f"{name}: each run")]
    ax.set_xticks(range(len(tiers)), tiers)
    ax.set_xlim(-0.5, len(tiers) - 0.5)
    ax.set_ylim(0.0, 1.25 * top)
    ax.set_xlabel("difficulty tier")
    ax.set_ylabel("travel time of runs that arrived [s]")
    ax.set_title("Travel time by tier")
    ax.grid(True, axis="y", lw=0.3, alpha=0.5)
    ax.figure.legend([h for h, _ in proxies], [lab for _, lab in proxies],
                     loc="outside right upper", fontsize="small")
    return ax


#: Distance [m] from the driven path and the goal within which a CommonRoad figure frames
#: static obstacles too, and the least margin [m] round what it frames.
FRAME_REACH = 20.0
FRAME_PAD = 8.0


def plot_commonroad(lanelets: Sequence[Any], obstacles: Obstacles, trajectory: Any, *,
                    route: Sequence[Any] = (), goal: Sequence[Any] = (),
                    moving: Sequence[Any] = (), body: tuple[float, float] = (4.5, 1.8),
                    s_max: float | None = None, title: str | None = None,
                    path: str | PathLike[str] | None = None) -> Any:
    """A CommonRoad scenario with the planned trajectory.

    Parameters
    ----------
    lanelets, route
        Outlines ``(k, 2)`` [m] of every lanelet, and of the route's lanelets (shaded).
    obstacles
        The static obstacles (and the places planned around moving ones).
    trajectory
        The plan (``x, y, heading, speed, s``), drawn coloured by speed with the car's
        ``body`` (length, width [m]) every 0.5 s.
    goal
        Outlines ``(k, 2)`` of the goal region's positions.
    moving
        Each moving obstacle's centre path ``(n, 2)`` [m] (thin grey lines, its start a dot).
    """
    xy = np.column_stack((trajectory.x, trajectory.y))
    # framed on what the car drives, the goal and the static obstacles near them (not the
    # whole route, which may run on for hundreds of metres)
    pts = np.vstack([xy] + [np.asarray(p) for p in goal])
    box_lo, box_hi = pts.min(axis=0) - FRAME_REACH, pts.max(axis=0) + FRAME_REACH
    near = [p for p in (obstacles.polygons() if len(obstacles) else [])
            if np.any(np.all((p >= box_lo) & (p <= box_hi), axis=1))]
    pts = np.vstack([pts, *near])
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    pad = max(FRAME_PAD, 0.1 * float(np.max(hi - lo)))
    lo, hi = lo - pad, hi + pad
    # the figure shaped like the frame (a tall frame in a wide figure left it blank)
    ratio = float((hi[1] - lo[1]) / max(hi[0] - lo[0], 1e-9))
    size = ((10.0, float(np.clip(8.0 * ratio + 1.6, 4.5, 10.0))) if ratio <= 1.0
            else (float(np.clip(8.5 / ratio + 2.6, 5.5, 10.0)), 9.5))
    fig, ax = plt.subplots(figsize=size, layout="constrained")
    ax.add_collection(PolyCollection([np.asarray(p) for p in lanelets], facecolors="0.92",
                                     edgecolors="0.7", linewidths=0.5, zorder=1))
    if len(route):
        ax.add_collection(PolyCollection([np.asarray(p) for p in route], facecolors="#cfe3f5",
                                         edgecolors="none", zorder=1.5,
                                         label="route (level 1)"))
    if len(goal):
        ax.add_collection(PolyCollection([np.asarray(p) for p in goal], facecolors="#b9e4b0",
                                         edgecolors="#3b8a2e", linewidths=1.0, alpha=0.7,
                                         zorder=2, label="goal region"))
    if len(obstacles):
        ax.add_collection(PolyCollection(obstacles.polygons(), facecolors="0.35",
                                         edgecolors="k", zorder=3, label="static obstacles"))
    for k, m in enumerate(moving):
        path_xy = np.asarray(m)
        ax.plot(path_xy[:, 0], path_xy[:, 1], color="0.55", lw=0.8, zorder=2.5,
                label="dynamic obstacles' paths" if k == 0 else None)
        ax.plot(path_xy[:1, 0], path_xy[:1, 1], "o", color="0.55", ms=3, zorder=2.5)
    top = _speed_scale(s_max, trajectory.speed)
    ax.add_collection(_speed_line(xy, trajectory.speed, top, lw=2.0, gid="trajectory",
                                  zorder=5, label="trajectory (colour: speed)"))
    t = np.asarray(trajectory.t, dtype=float)
    finite = np.isfinite(t)
    if finite.sum() >= 2:
        at = np.arange(0.0, t[finite][-1] + 1e-9, 0.5)
        s_at = np.interp(at, t[finite], np.asarray(trajectory.s)[finite])
        from splineplan.geometry import box_corners

        hx = np.interp(s_at, trajectory.s, trajectory.x)
        hy = np.interp(s_at, trajectory.s, trajectory.y)
        hh = np.interp(s_at, trajectory.s, np.unwrap(trajectory.heading))
        cars = box_corners(np.column_stack((hx, hy)), hh, np.full(len(at), body[0]),
                           np.full(len(at), body[1]))
        ax.add_collection(PolyCollection(list(cars), facecolors="none", edgecolors="#1f4e9c",
                                         linewidths=0.5, zorder=4,
                                         label="car every 0.5 s"))
    fig.colorbar(plt.cm.ScalarMappable(norm=Normalize(0.0, top), cmap=SPEED_CMAP), ax=ax,
                 label="speed [m/s]", shrink=0.8)
    ax.set_xlim(lo[0], hi[0])
    ax.set_ylim(lo[1], hi[1])
    ax.set_aspect("equal", adjustable="box")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    if title:
        ax.set_title(title)
    ax.legend(loc="best", fontsize="small")
    if path is not None:
        _save(ax, path)
    return fig


def plot_sweep(rows: Sequence[Mapping[str, Any]], path: str | PathLike[str]) -> Path:
    """Figure of a penetration sweep (rows of ``sweep.csv``, :mod:`splineplan.sweep`): mean
    travel time, time loss, throughput and time exposed to a low time-to-collision against
    the share of planned vehicles, each seed a dot and the mean over seeds a line with its
    standard deviation as a band. Returns the file written."""
    from splineplan.sweep import FIGURES

    fig = Figure(figsize=(10.0, 6.5), layout="constrained")
    axes = fig.subplots(2, 2, sharex=True).ravel()
    shares = sorted({float(r["share"]) for r in rows})
    for ax, (key, label) in zip(axes, FIGURES, strict=True):
        xs, means, sds = [], [], []
        for share in shares:
            vals = [float(r[key]) for r in rows
                    if float(r["share"]) == share and r.get(key) not in (None, "")]
            ax.scatter([100.0 * share] * len(vals), vals, s=14, color="0.55", zorder=3,
                       label="one seed" if share == shares[0] else None)
            if vals:
                xs.append(100.0 * share)
                means.append(float(np.mean(vals)))
                sds.append(float(np.std(vals, ddof=1)) if len(vals) > 1 else 0.0)
        if xs:
            m, sd = np.array(means), np.array(sds)
            ax.fill_between(xs, m - sd, m + sd, color="tab:blue", alpha=0.15, lw=0,
                            label="± 1 sd")
            ax.plot(xs, m, color="tab:blue", marker="o", lw=1.8, label="mean over seeds")
        else:
            ax.text(0.5, 0.5, "no data", ha="center", va="center", transform=ax.transAxes,
                    color="0.4")
        ax.set_ylabel(label)
        top = max([float(np.max(m + sd))] if xs else [1.0])
        ax.set_ylim(0.0, 1.2 * top if top > 0 else 1.0)  # differences in proportion
        ax.set_xticks([100.0 * s for s in shares])
        ax.grid(True, lw=0.3, alpha=0.5)
    for ax in axes[2:]:
        ax.set_xlabel("planned vehicles [% of passenger cars]")
    axes[0].legend(fontsize="small", loc="lower right")
    fig.suptitle("Penetration sweep: traffic as a share of it is planned")
    out = Path(path)
    fig.savefig(out, dpi=120)
    return out
