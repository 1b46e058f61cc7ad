"""Figures: their content (artists' data), not only that a file is written."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from conftest import ROOT
from matplotlib.collections import LineCollection, PolyCollection

from splineplan.cli import main
from splineplan.image_map import image_map, plan_image
from splineplan.plot import plot_roadmap, plot_speed_profile, plot_trajectory
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
