"""Pictures of networks, routes and plans (matplotlib, Agg backend).

Imported by no planning code. Each function draws on a given axes or writes a file.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
from matplotlib.collections import LineCollection

if TYPE_CHECKING:
    from splineplan.network import RoadNetwork
    from splineplan.route import Route


def plot_network(network: RoadNetwork, ax: Any = None, *, color: str = "0.75",
                 linewidth: float = 0.8) -> Any:
    """Draw every lane centre line of ``network`` on ``ax`` (a new one if ``None``)."""
    if ax is None:
        _, ax = plt.subplots(figsize=(8, 8))
    segs = [ln.shape for lanes in network.lanes for ln in lanes if len(ln.shape) >= 2]
    segs += [ln.shape for ln in network.internal_lanes.values() if len(ln.shape) >= 2]
    ax.add_collection(LineCollection(segs, colors=color, linewidths=linewidth,
                                     label="lanes", zorder=1))
    xmin, ymin, xmax, ymax = network.bounds
    pad = 0.03 * max(xmax - xmin, ymax - ymin, 1.0)
    ax.set_xlim(xmin - pad, xmax + pad)
    ax.set_ylim(ymin - pad, ymax + pad)
    ax.set_aspect("equal")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    return ax


def plot_route(network: RoadNetwork, route: Route, ax: Any = None, *,
               path: str | Path | None = None, title: str | None = None) -> Any:
    """Draw ``route`` on the whole network; write it to ``path`` if given.

    The route follows the centre of each edge's lanes and the junction lanes between
    them; start and goal are marked. Returns the axes.
    """
    from splineplan.network import route_corridor

    own = ax is None
    if own:
        fig, ax = plt.subplots(figsize=(8, 8))
    else:
        fig = ax.figure
    plot_network(network, ax)
    ref = route_corridor(network, route).reference
    ax.plot(ref[:, 0], ref[:, 1], color="tab:blue", linewidth=2.5, zorder=3,
            label=f"route ({len(route.edges)} edges, {route.length:.0f} m)")
    ax.plot(*ref[0], marker="o", color="tab:green", markersize=9, zorder=4,
            linestyle="none", label=f"start: {route.edges[0]}")
    ax.plot(*ref[-1], marker="*", color="tab:red", markersize=13, zorder=4,
            linestyle="none", label=f"goal: {route.edges[-1]}")
    ax.set_title(title or f"{network.path.name}: {route.edges[0]} -> {route.edges[-1]} "
                 f"({route.vclass}, by {route.weight})")
    ax.legend(loc="best", fontsize="small")
    if path is not None:
        fig.savefig(path, dpi=120, bbox_inches="tight")
        if own:
            plt.close(fig)
    return ax


# ---- the paper's figures 2 and 4, and the speed profile -----------------------------------
from collections.abc import Mapping, Sequence  # noqa: E402
from os import PathLike  # noqa: E402

import numpy as np  # noqa: E402
from matplotlib.collections import PolyCollection  # noqa: E402
from matplotlib.colors import Normalize  # noqa: E402
from matplotlib.figure import Figure  # noqa: E402

if TYPE_CHECKING:
    from splineplan.corridor import Corridor
    from splineplan.obstacles import Obstacles
    from splineplan.roadmap import Roadmap

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


def plot_roadmap(
    roadmap: Roadmap | Sequence[Roadmap],
    corridor: Corridor,
    obstacles: Obstacles,
    ax: Any = None,
    *,
    path: str | PathLike[str] | None = None,
    title: str | None = "Roadmap: sweep lines, free intervals and the widest path",
) -> Any:
    """The paper's Fig. 2: sweep lines, free intervals, the roadmap graph, the chosen path.

    Sweep lines cross the road at each station of the graph; the free intervals are those
    of the grown obstacles (so a vertex anywhere on one keeps the ego clear); arcs join the
    vertices of consecutive lines; the chosen widest-then-shortest path is drawn on top
    with its bottleneck (narrowest vertex) marked. Several roadmaps (one per road segment)
    are drawn together.

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

    Returns
    -------
    The axes; artists carry gids ``sweep_lines``, ``free_intervals``, ``roadmap_arcs``,
    ``roadmap_vertices``, ``widest_path``, ``bottleneck``.
    """
    maps = _roadmap_list(roadmap)
    ax = _plan_axes(ax, corridor)
    _draw_road(ax, corridor)
    _draw_obstacles(ax, obstacles)
    sweep: list[np.ndarray] = []
    intervals: list[np.ndarray] = []
    arcs: list[np.ndarray] = []
    for rm in maps:
        lines, first = np.unique(rm.graph_line, return_index=True)
        s_line = rm.graph_s[first]
        lo, hi = corridor.bounds_at(s_line)
        sweep.extend(np.stack((corridor.to_xy(s_line, lo), corridor.to_xy(s_line, hi)), axis=1))
        intervals.extend(np.stack((corridor.to_xy(rm.graph_s, rm.graph_lo),
                                   corridor.to_xy(rm.graph_s, rm.graph_hi)), axis=1))
        arcs.extend(rm.graph_xy[rm.arcs])
        del lines
    d = maps[0].params.d
    ax.add_collection(LineCollection(sweep, colors=PLAN_COLOURS["sweep"], linewidths=0.5,
                                     linestyles="--", gid="sweep_lines", zorder=2,
                                     label=f"sweep lines (every {d:g} m)"))
    ax.add_collection(LineCollection(intervals, colors=PLAN_COLOURS["interval"], linewidths=2.0,
                                     gid="free_intervals", zorder=3, alpha=0.6,
                                     label="free intervals (grown obstacles)"))
    ax.add_collection(LineCollection(arcs, colors=PLAN_COLOURS["graph"], linewidths=0.6,
                                     gid="roadmap_arcs", zorder=4, alpha=0.7,
                                     label="roadmap arcs"))
    gxy = np.concatenate([rm.graph_xy for rm in maps])
    ax.scatter(gxy[:, 0], gxy[:, 1], s=6, color=PLAN_COLOURS["graph"], zorder=5,
               gid="roadmap_vertices", label="roadmap vertices (interval midpoints)")
    pxy = np.concatenate([rm.xy for rm in maps])
    worst = min(maps, key=lambda rm: rm.bottleneck_width)
    ax.plot(pxy[:, 0], pxy[:, 1], color=PLAN_COLOURS["path"], lw=2.0, zorder=6,
            gid="widest_path", label="chosen widest path")
    bxy = worst.xy[worst.bottleneck_index]
    ax.plot([bxy[0]], [bxy[1]], marker="*", ms=14, color="gold", mec="k", ls="none",
            zorder=7, gid="bottleneck",
            label=f"bottleneck: free width {worst.bottleneck_width:.2f} m")
    st = maps[0].start_xy
    ax.plot([st[0]], [st[1]], marker="o", ms=7, color="k", ls="none", zorder=7, gid="start",
            label="start")
    _finish(ax, title, path)
    return ax


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
    cmap: str = "viridis",
    title: str | None = "Trajectory coloured by speed",
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
    cmap
        Colour map of the speed.

    Returns
    -------
    The axes; the curve is a LineCollection with gid ``trajectory_speed`` (its colour
    scale spans the speed range; a colour bar is added), over a thin Line2D with gid
    ``trajectory`` whose data are the trajectory's x and y.
    """
    maps = _roadmap_list(roadmap) if roadmap is not None else []
    ax = _plan_axes(ax, corridor)
    _draw_road(ax, corridor)
    _draw_obstacles(ax, obstacles)
    x = np.asarray(trajectory.x, dtype=float)
    y = np.asarray(trajectory.y, dtype=float)
    v = np.asarray(trajectory.speed, dtype=float)
    for i, rm in enumerate(maps):
        ax.plot(rm.xy[:, 0], rm.xy[:, 1], ls=":", marker="o", ms=3, lw=0.8,
                color=PLAN_COLOURS["graph"], zorder=4, gid="roadmap_path",
                label="roadmap (level 2)" if i == 0 else None)
    cp = getattr(trajectory, "control_points", None)
    if cp is not None and len(cp):
        cp = np.asarray(cp, dtype=float)
        ax.plot(cp[:, 0], cp[:, 1], ls="none", marker="x", ms=4, color="#7b1fa2", zorder=5,
                gid="control_points", label="spline control points")
    if footprint_every:
        if vehicle_size is None:
            vehicle_size = ((maps[0].params.vehicle_length, maps[0].params.vehicle_width)
                            if maps else (4.5, 1.8))
        _draw_footprints(ax, trajectory, footprint_every, vehicle_size)
    ax.plot(x, y, color="k", lw=0.6, zorder=6, gid="trajectory", label="trajectory (level 3)")
    pts = np.column_stack((x, y))
    segs = np.stack((pts[:-1], pts[1:]), axis=1)
    norm = Normalize(vmin=float(v.min()), vmax=float(v.max()))
    lc = LineCollection(list(segs), cmap=cmap, norm=norm, linewidths=3.0, zorder=7,
                        gid="trajectory_speed")
    lc.set_array((v[:-1] + v[1:]) / 2.0)
    ax.add_collection(lc)
    ax.plot([x[0]], [y[0]], marker="o", color="k", ms=6, ls="none", zorder=8, gid="start",
            label="start")
    ax.plot([x[-1]], [y[-1]], marker="s", color="k", ms=6, ls="none", zorder=8, gid="end",
            label="end")
    cb = ax.figure.colorbar(lc, ax=ax, fraction=0.03, pad=0.02)
    cb.set_label("speed [m/s]")
    _finish(ax, title, path)
    return ax


def plot_speed_profile(
    trajectory: Any,
    params: Any,
    ax: Any = None,
    *,
    path: str | PathLike[str] | None = None,
    title: str | None = "Speed profile along the trajectory",
) -> Any:
    """Speed along the curve with its limits: cornering (equation 1) and ``s_max``.

    Parameters
    ----------
    trajectory
        Anything with ``s``, ``speed`` and ``curvature`` arrays ``(n,)``.
    params
        :class:`~splineplan.trajectory.TrajectoryParams` or a mapping with ``mu``, ``g``
        and ``s_max``.
    ax
        Axes to draw into; a new figure when ``None``.
    path
        Where to save the figure, if given.

    Returns
    -------
    The axes; lines with gids ``speed``, ``cornering_limit`` (``sqrt(mu g / |kappa|)``,
    NaN where it exceeds 1.5 ``s_max``) and ``s_max``.
    """
    mu, g, s_max = (_param(params, k) for k in ("mu", "g", "s_max"))
    s = np.asarray(trajectory.s, dtype=float)
    v = np.asarray(trajectory.speed, dtype=float)
    kappa = np.abs(np.asarray(trajectory.curvature, dtype=float))
    with np.errstate(divide="ignore"):
        corner = np.sqrt(mu * g / kappa)
    top = 1.5 * s_max
    corner = np.where(corner <= top, corner, np.nan)
    if ax is None:
        ax = Figure(figsize=(8.0, 3.5), layout="constrained").add_subplot()
    ax.fill_between(s, 0.0, np.minimum(np.nan_to_num(corner, nan=top), s_max), color="#e3f2fd",
                    zorder=1, label="allowed (cornering and s_max)")
    ax.plot(s, corner, color="#ef6c00", lw=1.2, zorder=3, gid="cornering_limit",
            label=r"cornering limit $\sqrt{\mu g / |\kappa|}$")
    ax.axhline(s_max, color="#c62828", ls="--", lw=1.2, zorder=3, gid="s_max",
               label=f"$s_{{max}}$ = {s_max:.2f} m/s")
    ax.plot(s, v, color="#1565c0", lw=2.0, zorder=4, gid="speed", label="planned speed")
    ax.set_xlim(float(s[0]), float(s[-1]))
    ax.set_ylim(0.0, top)
    ax.set_xlabel("distance along the trajectory s [m]")
    ax.set_ylabel("speed [m/s]")
    ax.grid(True, lw=0.3, alpha=0.5)
    _legend(ax)
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


def _plan_axes(ax: Any, corridor: Corridor) -> Any:
    if ax is not None:
        return ax
    poly = corridor.polygon()
    dx, dy = np.ptp(poly, axis=0) + 1e-9
    width = 11.0
    height = float(np.clip(width * dy / dx + 1.8, 3.0, 9.0))
    return Figure(figsize=(width, height), layout="constrained").add_subplot()


def _draw_road(ax: Any, corridor: Corridor) -> None:
    poly = corridor.polygon()
    ax.fill(poly[:, 0], poly[:, 1], color=PLAN_COLOURS["road"], zorder=0, gid="road",
            label="road")
    for i, b in enumerate((corridor.left_xy(), corridor.right_xy())):
        ax.plot(b[:, 0], b[:, 1], color=PLAN_COLOURS["edge"], lw=1.2, zorder=1,
                gid="road_edge", label="road edge" if i == 0 else None)


def _draw_obstacles(ax: Any, obstacles: Obstacles) -> None:
    if len(obstacles) == 0:
        return
    ax.add_collection(PolyCollection(obstacles.polygons(), facecolors=PLAN_COLOURS["obstacle"],
                                     edgecolors=PLAN_COLOURS["obstacle"], linewidths=0.3,
                                     zorder=2, gid="obstacles", label="obstacles"))


def _draw_footprints(ax: Any, trajectory: Any, every: float,
                     size: tuple[float, float]) -> None:
    from splineplan.geometry import box_corners

    s = np.asarray(trajectory.s, dtype=float)
    at = np.arange(s[0], s[-1] + 1e-9, every)
    x = np.interp(at, s, trajectory.x)
    y = np.interp(at, s, trajectory.y)
    h = np.interp(at, s, np.unwrap(trajectory.heading))
    corners = box_corners(np.column_stack((x, y)), h, np.full(len(at), size[0]),
                          np.full(len(at), size[1]))
    ax.add_collection(PolyCollection(list(corners), facecolors="none", edgecolors="#424242",
                                     linewidths=0.5, zorder=5, gid="footprints",
                                     label=f"vehicle every {every:g} m"))


def _finish(ax: Any, title: str | None, path: str | PathLike[str] | None) -> None:
    ax.set_aspect("equal", adjustable="datalim")
    ax.autoscale_view()
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    if title:
        ax.set_title(title)
    _legend(ax)
    if path is not None:
        _save(ax, path)


def _legend(ax: Any) -> None:
    """Legend below the axes: outside the figure's plot area when the axes fill it alone."""
    fig = ax.figure
    if len(fig.axes) - sum(hasattr(a, "_colorbar") for a in fig.axes) <= 1 and \
            fig.get_layout_engine() is not None:
        fig.legend(*ax.get_legend_handles_labels(), loc="outside lower center", ncol=4,
                   fontsize="small", frameon=False)
    else:
        ax.legend(loc="best", fontsize="small")


def _save(ax: Any, path: str | PathLike[str]) -> None:
    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    ax.figure.savefig(p, dpi=150)


def _param(params: Any, name: str) -> float:
    value = params[name] if isinstance(params, Mapping) else getattr(params, name)
    return float(value)


def plot_plan_folder(
    run_dir: str | PathLike[str],
    *,
    out_dir: str | PathLike[str] | None = None,
    fmt: str = "png",
) -> list[str]:
    """Figures of a plan folder (``plan.json``, see :mod:`splineplan.io`).

    Writes ``roadmap.<fmt>`` (Fig. 2), ``trajectory.<fmt>`` (Fig. 4) and ``speed.<fmt>``
    (the speed profile with its limits). Returns the files written.
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
    if saved.trajectory is not None:
        p = dest / f"trajectory.{fmt}"
        plot_trajectory(saved.trajectory, saved.corridor, saved.obstacles,
                        saved.roadmaps or None, path=p, footprint_every=10.0)
        written.append(str(p))
        p = dest / f"speed.{fmt}"
        plot_speed_profile(saved.trajectory, saved.trajectory_params or TrajectoryParams(),
                           path=p)
        written.append(str(p))
    return written


def plot_run_folder(
    run_dir: str | PathLike[str],
    *,
    out_dir: str | PathLike[str] | None = None,
    fmt: str = "png",
) -> list[str]:
    """Figures of a simulation run folder (``metrics.json``, ``trajectory.csv``).

    Writes ``route.<fmt>`` (Fig. 3: the route on the whole network, with the driven path
    coloured by speed; needs the scenario's network, else only the driven path) and
    ``speed_time.<fmt>`` (speed over time). Returns the files written.
    """
    import json
    import logging

    from splineplan.errors import SplineplanError
    from splineplan.io import read_trajectory_csv

    log = logging.getLogger(__name__)
    run = Path(run_dir)
    dest = Path(out_dir) if out_dir is not None else run
    metrics = json.loads((run / "metrics.json").read_text())
    driven = read_trajectory_csv(run / "trajectory.csv")
    written: list[str] = []
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
            ax = plot_route(net, route, Figure(figsize=(8, 8), layout="constrained")
                            .add_subplot(), title=f"{metrics.get('scenario')}: route and "
                            f"driven path ({metrics.get('driver')}, {metrics.get('status')})")
        except (SplineplanError, OSError, KeyError, AttributeError) as err:
            log.warning("no network picture for %s: %s", run, err)
            ax = None
    if ax is None:
        ax = Figure(figsize=(8, 6), layout="constrained").add_subplot()
        ax.set_title(f"{metrics.get('scenario', run.name)}: driven path")
    if len(driven.x) > 1:
        pts = np.column_stack((driven.x, driven.y))
        v = driven.speed
        lc = LineCollection(list(np.stack((pts[:-1], pts[1:]), axis=1)), cmap="viridis",
                            norm=Normalize(float(v.min()), float(v.max())), linewidths=3.0,
                            zorder=5, gid="driven_speed")
        lc.set_array((v[:-1] + v[1:]) / 2.0)
        ax.add_collection(lc)
        ax.plot(driven.x, driven.y, color="k", lw=0.5, zorder=4, gid="driven",
                label="driven path")
        ax.figure.colorbar(lc, ax=ax, fraction=0.03, pad=0.02).set_label("speed [m/s]")
        ax.autoscale_view()
    ax.set_aspect("equal", adjustable="box")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.legend(loc="best", fontsize="small")
    p = dest / f"route.{fmt}"
    _save(ax, p)
    written.append(str(p))
    ax2 = Figure(figsize=(8.0, 3.5), layout="constrained").add_subplot()
    ax2.plot(driven.t, driven.speed, color="#1565c0", lw=1.5, gid="speed", label="speed")
    ax2.set_xlabel("time t [s]")
    ax2.set_ylabel("speed [m/s]")
    ax2.set_title(f"{metrics.get('scenario', run.name)}: speed over time")
    ax2.grid(True, lw=0.3, alpha=0.5)
    ax2.legend(loc="best", fontsize="small")
    p = dest / f"speed_time.{fmt}"
    _save(ax2, p)
    written.append(str(p))
    return written


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
    arrived, by tier and driver). Density: stopped vehicles per 100 m of road; only the
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

    # travel time by tier and driver: box plots of the runs that arrived
    ax = Figure(figsize=(max(6.0, 1.3 * len(tiers) * max(len(drivers), 1)), 4.5),
                layout="constrained").add_subplot()
    width = 0.8 / max(len(drivers), 1)
    for k, d in enumerate(drivers):
        c, _, name = style(d)
        data, pos = [], []
        for i, t in enumerate(tiers):
            v = [float(r["travel_time"]) for r in rows if r["driver"] == d and r["tier"] == t
                 and r.get("arrived") and r.get("travel_time") is not None]
            if v:
                data.append(v)
                pos.append(i + (k - (len(drivers) - 1) / 2.0) * width)
        if data:
            bp = ax.boxplot(data, positions=pos, widths=width * 0.85, patch_artist=True,
                            manage_ticks=False)
            for patch in bp["boxes"]:
                patch.set(facecolor=c, alpha=0.55, edgecolor=c)
            for med_line in bp["medians"]:
                med_line.set(color="k")
        ax.plot([], [], color=c, lw=6, alpha=0.55, label=name)
    ax.set_xticks(range(len(tiers)), tiers)
    ax.set_xlabel("difficulty tier")
    ax.set_ylabel("travel time of runs that arrived [s]")
    ax.set_title("Travel time by tier")
    ax.grid(True, axis="y", lw=0.3, alpha=0.5)
    ax.legend(loc="best", fontsize="small")
    p = out / f"bench_travel_time.{fmt}"
    _save(ax, p)
    written.append(str(p))
    return written
