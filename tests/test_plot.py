"""Figures: their content (artists' data), not only that a file is written."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from conftest import NETS, ROOT
from matplotlib.collections import LineCollection, PolyCollection

from splineplan.cli import main
from splineplan.image_map import image_map, plan_image
from splineplan.plot import plot_roadmap, plot_route, plot_speed_profile, plot_trajectory
from splineplan.trajectory import TrajectoryParams

MAP = ROOT / "scenarios" / "maps" / "field_c.png"


@pytest.fixture(scope="module")
def planned() -> object:
    return plan_image(image_map(MAP, scale=0.25))


def _by_gid(ax: object, gid: str) -> list[object]:
    return [a for a in ax.get_children() if a.get_gid() == gid]  # type: ignore[attr-defined]


def _labels_have_units(ax: object) -> None:
    for label in (ax.get_xlabel(), ax.get_ylabel()):  # type: ignore[attr-defined]
        assert label.endswith("]") and "[" in label, label


def test_roadmap_figure(planned: object, tmp_path: Path) -> None:
    plan = planned
    out = tmp_path / "fig2.png"
    ax = plot_roadmap(plan.roadmaps, plan.corridor, plan.map.obstacles, path=out)
    assert out.stat().st_size > 10_000
    rm = plan.roadmaps[0]
    (sweep,) = _by_gid(ax, "sweep_lines")
    n_lines = len(np.unique(np.concatenate([r.graph_line for r in plan.roadmaps])))
    assert len(sweep.get_segments()) == n_lines
    # each sweep line spans the road at its station: ends on the two boundaries
    seg = np.asarray(sweep.get_segments()[0])
    sl = plan.corridor.to_sl(seg)
    r_b, l_b = plan.corridor.bounds_at(sl[:, 0])
    np.testing.assert_allclose(sl[:, 1], [r_b[0], l_b[1]], atol=1e-6)
    (intervals,) = _by_gid(ax, "free_intervals")
    assert len(intervals.get_segments()) == len(rm.graph_xy)
    lengths = [np.hypot(*np.diff(np.asarray(s), axis=0)[0]) for s in intervals.get_segments()]
    np.testing.assert_allclose(lengths, rm.graph_hi - rm.graph_lo, atol=1e-6)
    (arcs,) = _by_gid(ax, "roadmap_arcs")
    assert len(arcs.get_segments()) == len(rm.arcs)
    (path,) = _by_gid(ax, "widest_path")
    np.testing.assert_array_equal(path.get_xydata(), rm.xy)
    (bottleneck,) = _by_gid(ax, "bottleneck")
    np.testing.assert_array_equal(bottleneck.get_xydata()[0], rm.xy[rm.bottleneck_index])
    assert f"{rm.bottleneck_width:.2f} m" in bottleneck.get_label()
    (obst,) = [c for c in ax.collections if isinstance(c, PolyCollection)
               and c.get_gid() == "obstacles"]
    assert len(obst.get_paths()) == len(plan.map.obstacles)
    _labels_have_units(ax)
    assert ax.get_aspect() == 1.0
    labels = [t.get_text() for t in ax.figure.legends[0].get_texts()]
    assert "chosen widest path" in labels and any("sweep lines" in t for t in labels)


def test_trajectory_figure(planned: object, tmp_path: Path) -> None:
    plan = planned
    tr = plan.trajectory
    out = tmp_path / "fig4.pdf"
    ax = plot_trajectory(tr, plan.corridor, plan.map.obstacles, plan.roadmaps, path=out,
                         footprint_every=10.0, s_max=TrajectoryParams().s_max)
    assert out.read_bytes()[:4] == b"%PDF"
    (line,) = _by_gid(ax, "trajectory")
    np.testing.assert_array_equal(line.get_xdata(), tr.x)
    np.testing.assert_array_equal(line.get_ydata(), tr.y)
    (coloured,) = _by_gid(ax, "trajectory_speed")
    assert isinstance(coloured, LineCollection)
    # the colour scale is the same in every picture: 0 .. s_max, not the speeds' range
    assert coloured.norm.vmin == 0.0
    assert coloured.norm.vmax == pytest.approx(TrajectoryParams().s_max)
    assert tr.speed.min() > 0.5 or tr.speed.max() < TrajectoryParams().s_max - 0.5
    segs = coloured.get_segments()
    assert len(segs) == len(tr.x) - 1
    np.testing.assert_allclose(np.asarray(segs[5])[0], [tr.x[5], tr.y[5]])
    # the colour bar is that of the speed
    cbar = coloured.colorbar
    assert cbar is not None and cbar.ax.get_ylabel() == "speed [m/s]"
    (rmap,) = _by_gid(ax, "roadmap_path")
    np.testing.assert_array_equal(rmap.get_xydata(), plan.roadmaps[0].xy)
    (feet,) = _by_gid(ax, "footprints")
    assert len(feet.get_paths()) == int(tr.s[-1] // 10.0) + 1
    _labels_have_units(ax)
    assert ax.get_aspect() == 1.0


def test_speed_profile_figure(planned: object, tmp_path: Path) -> None:
    tr = planned.trajectory
    tp = TrajectoryParams()
    ax = plot_speed_profile(tr, tp, path=tmp_path / "speed.svg")
    assert (tmp_path / "speed.svg").read_text().lstrip().startswith("<?xml")
    (speed,) = _by_gid(ax, "speed")
    np.testing.assert_array_equal(speed.get_xdata(), tr.s)
    np.testing.assert_array_equal(speed.get_ydata(), tr.speed)
    (smax,) = _by_gid(ax, "s_max")
    assert smax.get_ydata()[0] == pytest.approx(tp.s_max)
    (corner,) = _by_gid(ax, "cornering_limit")
    with np.errstate(divide="ignore"):
        want = np.sqrt(tp.mu * tp.g / np.abs(tr.curvature))
    shown = np.asarray(corner.get_ydata(), dtype=float)
    ok = np.isfinite(shown)
    assert ok.any()
    np.testing.assert_allclose(shown[ok], want[ok])
    assert np.all(~ok == (want > 1.5 * tp.s_max))
    # the planned speed never exceeds its limits
    assert np.all(tr.speed <= np.minimum(want, tp.s_max) + 1e-6)
    _labels_have_units(ax)
    # a mapping of parameters (as read back from plan.json) works the same
    ax2 = plot_speed_profile(tr, {"mu": tp.mu, "g": tp.g, "s_max": tp.s_max})
    np.testing.assert_array_equal(_by_gid(ax2, "speed")[0].get_ydata(), tr.speed)


def test_plot_command_redraws_from_files(tmp_path: Path,
                                         capsys: pytest.CaptureFixture[str]) -> None:
    run = tmp_path / "run"
    assert main(["plan-image", str(MAP), "--scale", "0.25", "--out", str(run),
                 "--no-plot"]) == 0
    assert not (run / "trajectory.png").exists()
    capsys.readouterr()
    assert main(["plot", str(run), "--out", str(tmp_path / "pics")]) == 0
    written = capsys.readouterr().out.split()
    assert sorted(Path(w).name for w in written) == ["roadmap.png", "speed.png",
                                                     "trajectory.png"]
    for w in written:
        assert Path(w).stat().st_size > 10_000
    (tmp_path / "nothing").mkdir()
    assert main(["plot", str(tmp_path / "nothing")]) == 2
    assert "neither plan.json nor metrics.json" in capsys.readouterr().err


def test_plot_command_on_a_simulation_folder(tmp_path: Path) -> None:
    """A run folder without a readable scenario still gives the driven path and speed."""
    run = tmp_path / "sim"
    run.mkdir()
    (run / "metrics.json").write_text(json.dumps({"scenario": "demo", "route": ["a"],
                                                  "scenario_file": None}))
    t = np.linspace(0, 10, 21)
    lines = ["t,x,y,heading,speed"] + [f"{v},{2 * v},0,0,2" for v in t]
    (run / "trajectory.csv").write_text("\n".join(lines) + "\n")
    assert main(["plot", str(run)]) == 0
    assert (run / "route.png").stat().st_size > 5_000
    assert (run / "speed_time.png").stat().st_size > 5_000


# ---- route pictures: zoomed to the route, band and driven path told apart -----------------
def _route_ref(net: object, route: object) -> np.ndarray:
    from splineplan.network import route_corridor

    return route_corridor(net, route).reference  # type: ignore[arg-type]


def _view_area(ax: object) -> float:
    x0, x1 = ax.get_xlim()  # type: ignore[attr-defined]
    y0, y1 = ax.get_ylim()  # type: ignore[attr-defined]
    return float((x1 - x0) * (y1 - y0))


def _net_area(net: object) -> float:
    x0, y0, x1, y1 = net.bounds  # type: ignore[attr-defined]
    return float((x1 - x0) * (y1 - y0))


def test_route_figure_zooms_to_the_route_with_context(tmp_path: Path) -> None:
    from splineplan.network import load_network
    from splineplan.plot import ROUTE_PAD_MIN
    from splineplan.route import shortest_route

    net = load_network(NETS / "city.net.xml")
    route = shortest_route(net, "A0B0", "B1C1")
    ax = plot_route(net, route, path=tmp_path / "route.png")
    ref = _route_ref(net, route)
    (x0, x1), (y0, y1) = ax.get_xlim(), ax.get_ylim()
    # the route and some road around it (at least ROUTE_PAD_MIN, or up to the network's
    # edge) are in view ...
    nx0, ny0, nx1, ny1 = net.bounds
    lo, hi = ref.min(axis=0), ref.max(axis=0)
    assert x0 <= max(lo[0] - ROUTE_PAD_MIN, nx0) and x1 >= min(hi[0] + ROUTE_PAD_MIN, nx1)
    assert y0 <= max(lo[1] - ROUTE_PAD_MIN, ny0) and y1 >= min(hi[1] + ROUTE_PAD_MIN, ny1)
    # ... but the view is the route's neighbourhood, not the whole network
    assert _view_area(ax) < 0.5 * _net_area(net)
    # the network is drawn in light grey around it
    (lanes,) = _by_gid(ax, "lanes")
    assert np.all(np.asarray(lanes.get_colors())[:, :3] > 0.7)
    assert (tmp_path / "route.png").stat().st_size > 20_000


def test_route_on_a_large_network_has_an_overview(monaco_net: Path, tmp_path: Path) -> None:
    from splineplan.network import load_network
    from splineplan.route import shortest_route

    net = load_network(monaco_net)
    route = shortest_route(net, "-1718#11", "1756#0")
    ax = plot_route(net, route, path=tmp_path / "monaco.png")
    ref = _route_ref(net, route)
    (x0, x1), (y0, y1) = ax.get_xlim(), ax.get_ylim()
    assert x0 < ref[:, 0].min() and x1 > ref[:, 0].max()
    assert y0 < ref[:, 1].min() and y1 > ref[:, 1].max()
    # a 1.5 km route on a 10 x 6 km map: the view is a few percent of the map
    assert _view_area(ax) < 0.05 * _net_area(net)
    (overview,) = [a for a in ax.child_axes if a.get_gid() == "overview"]
    ox0, _, ox1, _ = net.bounds
    assert overview.get_xlim()[0] <= ox0 + 1.0 and overview.get_xlim()[1] >= ox1 - 1.0


def _city_run(tmp_path: Path, *, driven: bool, arrived: bool = True,
              scenario: bool = True) -> tuple[Path, list[str]]:
    """A run folder on the city scenario: metrics.json, and a driven path (samples along
    the route's reference at 2..6 m/s) or a trajectory.csv with its header only."""
    from splineplan.network import load_network
    from splineplan.route import shortest_route

    edges = ["SWA0", "A0B0", "B0B1"]
    run = tmp_path / "run"
    run.mkdir()
    metrics = {"scenario": "city", "driver": "planner",
               "scenario_file": str(ROOT / "scenarios" / "city.toml") if scenario else None,
               "route": edges, "route_length": 400.0,
               "status": "arrived" if arrived else "timeout", "arrived": arrived,
               "reason": "the goal was reached" if arrived else
               "duration 10 s reached before the ego arrived (the ego was never inserted)"}
    (run / "metrics.json").write_text(json.dumps(metrics))
    lines = ["t,x,y,heading,speed"]
    if driven:
        net = load_network(NETS / "city.net.xml")
        ref = _route_ref(net, shortest_route(net, edges[0], edges[-1]))[::5]
        v = np.linspace(2.0, 6.0, len(ref))
        lines += [f"{0.5 * i},{x},{y},0,{s}"
                  for i, ((x, y), s) in enumerate(zip(ref, v, strict=True))]
    (run / "trajectory.csv").write_text("\n".join(lines) + "\n")
    return run, edges


def test_run_route_figure_shows_route_and_driven_path_apart(tmp_path: Path) -> None:
    from splineplan.plot import ROUTE_BAND, run_figures
    from splineplan.scenario import load_scenario

    run, _ = _city_run(tmp_path, driven=True)
    figs = run_figures(run)
    assert set(figs) == {"route", "speed_time"}
    ax = figs["route"]
    (band,) = _by_gid(ax, "route")
    (path,) = _by_gid(ax, "driven_speed")
    # the planned route is a wide translucent band under a thin line coloured by speed
    assert band.get_linewidth() >= 3 * float(np.max(path.get_linewidths()))
    assert band.get_alpha() is not None and band.get_alpha() < 0.6
    assert band.get_zorder() < path.get_zorder()
    # colour scale: 0 .. the scenario's s_max, though the speeds span 2 .. 6 m/s
    s_max = load_scenario(ROOT / "scenarios" / "city.toml").trajectory.s_max
    assert path.norm.vmin == 0.0 and path.norm.vmax == pytest.approx(s_max)
    # the legend's entries look like the artists: a band of the band's width and alpha,
    # and a line with several colours of the speed map
    ax.figure.savefig(tmp_path / "route.png")  # colours are mapped when drawn
    legend = ax.figure.legends[0]
    entries = dict(zip([t.get_text() for t in legend.get_texts()], legend.legend_handles,
                       strict=True))
    (band_label,) = [t for t in entries if t.startswith("planned route")]
    assert entries[band_label].get_linewidth() == ROUTE_BAND[1]
    assert entries[band_label].get_alpha() == ROUTE_BAND[2]
    (path_label,) = [t for t in entries if t.startswith("driven path")]
    colours = np.unique(np.round(entries[path_label].get_colors(), 3), axis=0)
    assert isinstance(entries[path_label], LineCollection) and len(colours) > 3
    assert entries[path_label].cmap.name == path.cmap.name


def test_failed_run_draws_what_exists_and_no_blank_figure(
        tmp_path: Path, capsys: pytest.CaptureFixture[str],
        caplog: pytest.LogCaptureFixture) -> None:
    from splineplan.plot import run_figures

    run, _ = _city_run(tmp_path, driven=False, arrived=False)
    figs = run_figures(run)
    # the route on the network, titled with the failure; no speed figure without speeds
    assert set(figs) == {"route"}
    ax = figs["route"]
    assert "never inserted" in ax.get_title() and "timeout" in ax.get_title()
    assert _by_gid(ax, "route") and not _by_gid(ax, "driven_speed")
    assert "did not move" in caplog.text
    assert main(["plot", str(run)]) == 0
    assert [Path(w).name for w in capsys.readouterr().out.split()] == ["route.png"]
    assert not (run / "speed_time.png").exists()
    # without its scenario there is nothing to draw: no file, and the command says so
    bare = tmp_path / "bare"
    run.rename(bare)
    metrics = json.loads((bare / "metrics.json").read_text())
    (bare / "metrics.json").write_text(json.dumps({**metrics, "scenario_file": None}))
    (bare / "route.png").unlink()
    assert main(["plot", str(bare)]) == 0
    assert "nothing to draw" in capsys.readouterr().out
    assert not list(bare.glob("*.png"))


def test_plan_folder_without_trajectory_writes_no_trajectory_figure(
        planned: object, tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    from splineplan.io import save_plan
    from splineplan.plot import plot_plan_folder

    plan = planned
    save_plan(tmp_path / "p", corridor=plan.corridor, obstacles=plan.map.obstacles,
              roadmaps=plan.roadmaps)
    written = plot_plan_folder(tmp_path / "p")
    assert [Path(w).name for w in written] == ["roadmap.png"]
    assert "no trajectory" in caplog.text


# ---- long plans: every segment's sweep lines, in the road's frame -------------------------
@pytest.fixture(scope="module")
def long_plan() -> tuple[object, object]:
    """A 600 m plan on straight.net.xml past one obstacle: three road segments."""
    from splineplan.network import load_network, read_obstacles
    from splineplan.pipeline import plan

    net = load_network(NETS / "straight.net.xml")
    obstacles = read_obstacles(net, ROOT / "scenarios" / "one_obstacle.rou.xml")
    return plan(net, "e0", "e2", obstacles), obstacles


def test_roadmap_figure_sweeps_the_whole_route(long_plan: tuple[object, object]) -> None:
    result, obstacles = long_plan
    corridor, maps = result.corridor, result.roadmaps
    assert len(maps) >= 2 and corridor.length > 500.0
    ax = plot_roadmap(maps, corridor, obstacles, frame="xy")
    (sweep,) = _by_gid(ax, "sweep_lines")
    segs = [np.asarray(s) for s in sweep.get_segments()]
    k = 0
    for rm in maps:  # each roadmap's vertices lie on its own sweep lines
        lines = np.unique(rm.graph_line)
        for line, seg in zip(lines, segs[k:k + len(lines)], strict=True):
            pts = rm.graph_xy[rm.graph_line == line]
            a, b = seg
            t = np.clip((pts - a) @ (b - a) / ((b - a) @ (b - a)), 0.0, 1.0)
            gap = np.hypot(*(a + t[:, None] * (b - a) - pts).T)
            assert gap.max() < 1e-6
        k += len(lines)
    assert k == len(segs)
    stations = corridor.to_sl(np.array([s.mean(axis=0) for s in segs]))[:, 0]
    d = maps[0].params.d
    assert stations.max() > corridor.length - 20.0 * d > 300.0


def test_long_plans_are_drawn_in_the_road_frame_in_panels(
        long_plan: tuple[object, object], tmp_path: Path) -> None:
    from splineplan.plot import PANEL_LENGTH

    result, obstacles = long_plan
    corridor, tr = result.corridor, result.trajectory
    ax = plot_trajectory(tr, corridor, obstacles, result.roadmaps, footprint_every=10.0,
                         s_max=13.89, path=tmp_path / "long.png")
    panels = [a for a in ax.figure.axes if not hasattr(a, "_colorbar")]
    assert len(panels) == int(np.ceil(corridor.length / PANEL_LENGTH))  # a straight road:
    assert not [a for a in panels if a.get_gid() == "road_map"]  # no map of its bends
    spans = np.array([a.get_xlim() for a in panels])
    assert np.all(np.diff(spans, axis=1) <= PANEL_LENGTH + 2.0 + 1e-9)
    assert spans[0, 0] <= 0.0 and spans[-1, 1] >= corridor.length
    assert np.all(spans[1:, 0] <= spans[:-1, 1])  # no gap between panels
    for a in panels:  # true scale, the road's width in view
        assert a.get_aspect() == 1.0
        lo, hi = a.get_ylim()
        assert lo < corridor.right.min() and hi > corridor.left.max()
        assert hi - lo < 3.0 * (corridor.left.max() - corridor.right.min())
    # the curve is drawn by station and lateral offset
    (line,) = _by_gid(panels[0], "trajectory")
    np.testing.assert_allclose(line.get_xydata(), corridor.to_sl(np.column_stack((tr.x, tr.y))))
    (coloured,) = _by_gid(panels[-1], "trajectory_speed")
    assert (coloured.norm.vmin, coloured.norm.vmax) == (0.0, 13.89)
    assert panels[-1].get_xlabel().startswith("station") and "[m]" in panels[-1].get_xlabel()


# ---- bench: drivers told apart with one seed ----------------------------------------------
def test_bench_travel_time_tells_drivers_apart_with_one_seed() -> None:
    from splineplan.plot import _bench_travel_time

    rows = [{"driver": d, "tier": t, "arrived": not (d == "sumo" and t == "blocked"),
             "travel_time": tt}
            for (d, t, tt) in [("planner", "bundled", 45.9), ("sumo", "bundled", 46.5),
                               ("sublane", "bundled", 46.5), ("planner", "blocked", 46.0),
                               ("sumo", "blocked", None), ("sublane", "blocked", 72.1)]]
    ax = _bench_travel_time(rows, ["planner", "sumo", "sublane"], ["bundled", "blocked"])
    bars = {d: [p for p in ax.patches if p.get_gid() == f"travel_{d}"]
            for d in ("planner", "sumo", "sublane")}
    assert [len(b) for b in bars.values()] == [2, 1, 2]
    # equal times, yet each driver's bar has its own colour and hatch, at its own place
    looks = {(tuple(np.round(b[0].get_facecolor(), 3)), b[0].get_hatch()) for b in
             bars.values()}
    assert len(looks) == 3
    xs = [b[0].get_x() for b in bars.values()]
    assert len(set(np.round(xs, 6))) == 3
    # values written on the bars; the driver that never arrived is named where it ran
    texts = [t.get_text() for t in ax.texts]
    assert "46.5 s" in texts and "72.1 s" in texts
    assert any("SUMO default" in t and "none of 1 arrived" in t for t in texts)
    legend = ax.figure.legends[0]
    labels = [t.get_text() for t in legend.get_texts()]
    assert {"splineplan: median", "SUMO default: median", "SUMO sublane: each run"} <= set(labels)


def test_a_long_bending_plan_gets_a_map_of_the_road_above_its_panels() -> None:
    from splineplan.network import load_network
    from splineplan.obstacles import Obstacles
    from splineplan.pipeline import plan
    from splineplan.plot import PANEL_LENGTH

    net = load_network(NETS / "curved.net.xml")
    result = plan(net, "s0", "s1", Obstacles.empty())
    corridor = result.corridor
    ax = plot_roadmap(result.roadmaps, corridor, Obstacles.empty())
    axes = [a for a in ax.figure.axes if not hasattr(a, "_colorbar")]
    (road_map,) = [a for a in axes if a.get_gid() == "road_map"]
    assert len(axes) - 1 == int(np.ceil(corridor.length / PANEL_LENGTH))
    # the map shows the whole road in x-y (the 90-degree bend), above the panels
    poly = corridor.polygon()
    (x0, x1), (y0, y1) = road_map.get_xlim(), road_map.get_ylim()
    assert x0 <= poly[:, 0].min() and x1 >= poly[:, 0].max()
    assert y0 <= poly[:, 1].min() and y1 >= poly[:, 1].max()
    assert axes.index(road_map) == 0


@pytest.mark.parametrize("net_name, start, end", [("grid.net.xml", "B0C0", "C0C1"),
                                                   ("city.net.xml", "SWA0", "A0B0")])
def test_turn_figure_shows_the_junction_the_curve_and_what_it_breaks(
        tmp_path: Path, net_name: str, start: str, end: str) -> None:
    """A junction turn's figure: the view holds the junction's outline; the drivable area
    is the plan's corridor; the curvature panel draws the curve's curvature against the
    turning limit; the broken limits are marked exactly when the plan is infeasible."""
    from splineplan.network import load_network
    from splineplan.pipeline import plan
    from splineplan.plot import plot_turn

    net = load_network(NETS / net_name)
    result = plan(net, start, end)
    fig = plot_turn(net, result, path=tmp_path / "turn.png")
    assert (tmp_path / "turn.png").stat().st_size > 20_000
    ax = fig.axes[0]  # the map; then the curvature panel and the colour bar
    axk = next(a for a in fig.axes if a.get_ylabel().startswith("|curvature|"))
    node = net.to_nodes[net.edge_index(start)]
    shape = net.junction_shapes[node]
    x0, x1 = ax.get_xlim()
    y0, y1 = ax.get_ylim()
    assert x0 <= shape[:, 0].min() and shape[:, 0].max() <= x1
    assert y0 <= shape[:, 1].min() and shape[:, 1].max() <= y1
    area = next(p for p in ax.patches if p.get_gid() == "drivable_area")
    assert np.allclose(area.get_xy()[:-1], result.corridor.polygon())
    paved = [p for p in ax.patches if p.get_gid() == "paved_area"]
    wide = result.corridor.paved()
    assert bool(paved) == (wide is not None)
    if wide is not None:
        assert np.allclose(paved[0].get_xy()[:-1], wide.polygon())
    curve = next(line for line in axk.lines if line.get_gid() == "curvature")
    assert np.allclose(curve.get_ydata(), np.abs(result.trajectory.curvature))
    limit = next(line for line in axk.lines if line.get_gid() == "kappa_max")
    assert limit.get_ydata()[0] == pytest.approx(TrajectoryParams().kappa_max)
    marked = [line for line in ax.lines if line.get_gid() == "violations"]
    assert bool(marked) == (not result.trajectory.feasible)
    gids = {c.get_gid() for c in ax.collections}
    assert {"lanes", "swept", "trajectory_speed"} <= gids
