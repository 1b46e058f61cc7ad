"""Plan folders: what is written is read back unchanged."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from conftest import ROOT

from splineplan.errors import ScenarioError
from splineplan.image_map import image_map, plan_image
from splineplan.io import load_plan, read_trajectory_csv, save_plan
from splineplan.trajectory import TrajectoryParams


@pytest.fixture(scope="module")
def planned() -> object:
    amap = image_map(ROOT / "scenarios" / "maps" / "one_obstacle.png", scale=0.25)
    return plan_image(amap)


def test_round_trip(planned: object, tmp_path: Path) -> None:
    plan = planned
    tp = TrajectoryParams(s_max=11.0)
    save_plan(tmp_path, corridor=plan.corridor, obstacles=plan.map.obstacles,
              roadmaps=plan.roadmaps, trajectory=plan.trajectory, trajectory_params=tp,
              meta={"seed": 7, "start": plan.start})
    doc = json.loads((tmp_path / "plan.json").read_text())
    assert doc["format"] == "splineplan.plan" and doc["version"] == 1
    saved = load_plan(tmp_path)
    c0, c1 = plan.corridor, saved.corridor
    for name in ("reference", "s", "left", "right"):
        np.testing.assert_array_equal(getattr(c0, name), getattr(c1, name))
    assert len(saved.obstacles) == len(plan.map.obstacles)
    np.testing.assert_array_equal(saved.obstacles.vertices, plan.map.obstacles.vertices)
    assert saved.obstacles.ids == plan.map.obstacles.ids
    assert len(saved.roadmaps) == len(plan.roadmaps)
    for r0, r1 in zip(plan.roadmaps, saved.roadmaps, strict=True):
        for name in ("xy", "width", "graph_xy", "graph_lo", "graph_hi", "arcs", "path",
                     "graph_line"):
            np.testing.assert_array_equal(getattr(r0, name), getattr(r1, name))
        assert r1.arcs.dtype == np.int64
        assert r1.bottleneck_width == r0.bottleneck_width
        assert r1.params == r0.params
    tr, back = plan.trajectory, saved.trajectory
    assert back is not None
    for name in ("t", "x", "y", "heading", "speed", "curvature", "s"):
        np.testing.assert_allclose(getattr(back, name), getattr(tr, name), rtol=0, atol=1e-12)
    np.testing.assert_array_equal(back.control_points, tr.control_points)
    assert back.min_clearance == pytest.approx(tr.min_clearance)
    assert back.feasible == tr.feasible
    assert saved.trajectory_params["s_max"] == 11.0
    assert saved.meta["seed"] == 7 and saved.meta["start"] == pytest.approx(list(plan.start))


def test_read_errors(tmp_path: Path) -> None:
    with pytest.raises(ScenarioError, match=r"no plan\.json"):
        load_plan(tmp_path)
    (tmp_path / "plan.json").write_text("{not json")
    with pytest.raises(ScenarioError, match="not readable JSON"):
        load_plan(tmp_path)
    (tmp_path / "plan.json").write_text(json.dumps({"format": "other"}))
    with pytest.raises(ScenarioError, match="not a splineplan plan"):
        load_plan(tmp_path)
    (tmp_path / "plan.json").write_text(json.dumps({"format": "splineplan.plan", "version": 1}))
    with pytest.raises(ScenarioError, match="malformed"):
        load_plan(tmp_path)
    (tmp_path / "t.csv").write_text("t,x,y\n0,1,2\n")
    with pytest.raises(ScenarioError, match="lacks the columns heading, speed"):
        read_trajectory_csv(tmp_path / "t.csv")


def test_driven_path_without_curvature(tmp_path: Path) -> None:
    """A simulation's CSV (more columns, no curvature) reads; curvature from the heading."""
    r = 20.0
    a = np.linspace(0.0, 1.0, 50)
    rows = ["t,x,y,heading,speed,station,off_road"]
    rows += [f"{i * 0.1},{r * np.sin(v)},{r - r * np.cos(v)},{v},5.0,{r * v},0"
             for i, v in enumerate(a)]
    (tmp_path / "trajectory.csv").write_text("\n".join(rows) + "\n")
    back = read_trajectory_csv(tmp_path / "trajectory.csv")
    np.testing.assert_allclose(back.curvature, 1.0 / r, rtol=2e-3)
    np.testing.assert_allclose(back.s[-1], r * 1.0, rtol=1e-3)


def test_route_corridor_round_trip_keeps_edges_and_junctions() -> None:
    from splineplan.io import corridor_from_dict, corridor_to_dict
    from splineplan.network import load_network, route_corridor
    from splineplan.route import shortest_route

    net = load_network(ROOT / "sumo_nets" / "grid.net.xml")
    cor = route_corridor(net, shortest_route(net, "A1B1", "D1D0"))
    back = corridor_from_dict(json.loads(json.dumps(corridor_to_dict(cor))))
    assert back.edges == cor.edges
    np.testing.assert_array_equal(back.edge_starts, cor.edge_starts)
    np.testing.assert_array_equal(back.edge_ends, cor.edge_ends)
    mid = (cor.edge_ends[0] + cor.edge_starts[1]) / 2.0
    assert back.junction_at(mid) == cor.junction_at(mid) == cor.edges[:2]


def test_a_plan_folder_written_before_the_roadmap_bands_reads(planned: object,
                                                               tmp_path: Path) -> None:
    plan = planned
    save_plan(tmp_path, corridor=plan.corridor, obstacles=plan.map.obstacles,
              roadmaps=plan.roadmaps, trajectory=plan.trajectory,
              trajectory_params=TrajectoryParams())
    doc = json.loads((tmp_path / "plan.json").read_text())
    for r in doc["roadmaps"]:
        del r["band_lo"], r["band_hi"]
    (tmp_path / "plan.json").write_text(json.dumps(doc))
    saved = load_plan(tmp_path)
    assert [len(r.band_lo) for r in saved.roadmaps] == [0] * len(plan.roadmaps)
    np.testing.assert_array_equal(saved.roadmaps[0].xy, plan.roadmaps[0].xy)
