"""Maps as images: reading, corridor and obstacles, errors, and plan-image checked on pixels."""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np
import pytest
import shapely
from conftest import ROOT
from hypothesis import given, settings
from hypothesis import strategies as st
from PIL import Image

from splineplan.cli import main
from splineplan.errors import GeometryError, ParameterError, ScenarioError
from splineplan.image_map import BOUNDARY_INSET, image_map

MAPS = ROOT / "scenarios" / "maps"
SCALE = 0.25  # the bundled maps' metres per pixel


# -- independent oracles (Pillow + shapely, not the planner's code) ---------------------------
def dark_mask(path: Path) -> np.ndarray:
    """Dark pixels of an image file: luminance below one half, transparent counts as dark."""
    with Image.open(path) as im:
        rgba = np.asarray(im.convert("RGBA"), dtype=float) / 255.0
    lum = (0.2126 * rgba[..., 0] + 0.7152 * rgba[..., 1] + 0.0722 * rgba[..., 2]) * rgba[..., 3]
    return lum < 0.5


def pixel_boxes(mask: np.ndarray, scale: float) -> tuple[np.ndarray, np.ndarray]:
    """Shapely squares of the True pixels of a mask, and their (row, col)."""
    rows, cols = np.nonzero(mask)
    h = mask.shape[0]
    x0, y0 = cols * scale, (h - 1 - rows) * scale
    return shapely.box(x0, y0, x0 + scale, y0 + scale), np.column_stack((rows, cols))


def swept_footprint(x: np.ndarray, y: np.ndarray, heading: np.ndarray, length: float,
                    width: float, step: float = 0.05) -> shapely.Geometry:
    """Union of the vehicle's rectangles (centred on the curve) every ``step`` metres."""
    s = np.concatenate(([0.0], np.cumsum(np.hypot(np.diff(x), np.diff(y)))))
    at = np.append(np.arange(0.0, s[-1], step), s[-1])
    xs, ys = np.interp(at, s, x), np.interp(at, s, y)
    h = np.interp(at, s, np.unwrap(heading))
    c, sn = np.cos(h), np.sin(h)
    corners = [np.column_stack((xs + a * length / 2 * c - b * width / 2 * sn,
                                ys + a * length / 2 * sn + b * width / 2 * c))
               for a, b in ((-1, -1), (1, -1), (1, 1), (-1, 1))]
    return shapely.union_all(shapely.polygons(np.stack(corners, axis=1)))


def dark_pixels_hit(path: Path, scale: float, footprint: shapely.Geometry) -> np.ndarray:
    """(row, col) of the dark pixels the footprint overlaps with positive area."""
    boxes, rc = pixel_boxes(dark_mask(path), scale)
    idx = shapely.STRtree(boxes).query(footprint, predicate="intersects")
    area = shapely.area(shapely.intersection(boxes[idx], footprint))
    return rc[idx[area > 1e-9]]


def write_png(path: Path, lum: np.ndarray) -> Path:
    Image.fromarray((np.asarray(lum) * 255).astype(np.uint8), mode="L").save(path)
    return path


def road_array(h: int = 40, w: int = 80, band: tuple[int, int] = (10, 30)) -> np.ndarray:
    img = np.zeros((h, w))
    img[band[0]:band[1]] = 1.0
    return img


# -- reading --------------------------------------------------------------------------------
def test_straight_road_corridor_and_axes() -> None:
    # road on rows 10..29 of 40: y from (40 - 30) * 0.5 = 5 m to (40 - 10) * 0.5 = 15 m
    m = image_map(road_array(), scale=0.5)
    assert m.corridor.length == pytest.approx(40.0)
    np.testing.assert_allclose(m.corridor.reference[:, 1], 10.0, atol=1e-9)
    np.testing.assert_allclose(m.corridor.left, 5.0 - BOUNDARY_INSET, atol=1e-9)
    np.testing.assert_allclose(m.corridor.right, -5.0 + BOUNDARY_INSET, atol=1e-9)
    assert len(m.obstacles) == 0
    np.testing.assert_allclose(m.default_start(), [0.25, 10.0])
    assert m.extent == (0.0, 40.0, 0.0, 20.0)
    # pixel <-> metres: row 0 is the top, y grows upwards
    np.testing.assert_array_equal(m.to_pixel([[0.1, 19.9], [39.9, 0.1]]), [[0, 0], [39, 79]])
    np.testing.assert_allclose(m.to_xy([39], [0]), [[0.25, 0.25]])


def test_obstacle_rectangles_cover_exactly_the_dark_pixels() -> None:
    img = road_array()
    yy, xx = np.mgrid[0:40, 0:80]
    img[np.hypot(yy - 20, xx - 40) <= 5] = 0.0  # a disc
    img[14:26, 60:63] = 0.0  # an L: upright ...
    img[23:26, 60:70] = 0.0  # ... and foot (not convex)
    m = image_map(img, scale=0.5)
    assert m.n_blobs == 2
    union = shapely.union_all([shapely.Polygon(p) for p in m.obstacles.polygons()])
    dark = img < 0.5
    dark[:10] = dark[30:] = False  # off-road rows are not obstacles
    boxes, _ = pixel_boxes(dark, 0.5)
    assert union.area == pytest.approx(dark.sum() * 0.25)
    assert shapely.covers(union, boxes).all()


def test_merge_tolerance_covers_more_with_fewer_polygons() -> None:
    img = road_array()
    yy, xx = np.mgrid[0:40, 0:80]
    img[np.hypot(yy - 20, xx - 40) <= 6] = 0.0
    exact = image_map(img, scale=0.5)
    merged = image_map(img, scale=0.5, merge_tolerance=2)
    assert len(merged.obstacles) < len(exact.obstacles)
    u_exact = shapely.union_all([shapely.Polygon(p) for p in exact.obstacles.polygons()])
    u_merged = shapely.union_all([shapely.Polygon(p) for p in merged.obstacles.polygons()])
    assert u_merged.covers(u_exact)
    # the extra area is at most 2 pixels per row on either side
    assert u_merged.area - u_exact.area <= 13 * 2 * 2 * 0.25 + 1e-9


def test_alpha_transparent_counts_as_off_road(tmp_path: Path) -> None:
    rgba = np.full((20, 40, 4), 255, dtype=np.uint8)  # white everywhere ...
    rgba[:5, :, 3] = 0  # ... but the top 5 rows transparent
    rgba[15:, :, 3] = 0
    path = tmp_path / "alpha.png"
    Image.fromarray(rgba, mode="RGBA").save(path)
    m = image_map(path, scale=1.0)
    assert m.road.sum() == 10 * 40
    np.testing.assert_allclose(m.corridor.reference[:, 1], 10.0, atol=1e-9)


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), n=st.integers(0, 8))
def test_road_minus_obstacles_holds_no_dark_pixel(seed: int, n: int) -> None:
    """Whatever the blobs, the corridor without the obstacles covers only light pixels."""
    rng = np.random.default_rng(seed)
    h, w = 50, 120
    img = np.zeros((h, w))
    cols = np.arange(w)
    centre = 25 + 8 * np.sin(2 * np.pi * cols / w + rng.uniform(0, 2 * np.pi))
    rows = np.arange(h)[:, None]
    img[np.abs(rows - centre[None, :]) <= 9] = 1.0
    for _ in range(n):
        r, c = rng.integers(0, h), rng.integers(5, w - 5)
        a, b = rng.integers(1, 6, size=2)
        img[max(r - a, 0):r + a, c - b:c + b] = 0.0
    try:
        m = image_map(img, scale=0.5)
    except GeometryError:
        return  # blobs closed the road: nothing to check
    # the outline of a corridor whose offsets jump at a bend can touch itself: made valid
    road = shapely.make_valid(shapely.Polygon(m.corridor.polygon()))
    free = road.difference(shapely.union_all(
        [shapely.make_valid(shapely.Polygon(p)) for p in m.obstacles.polygons()]))
    boxes, _ = pixel_boxes(img < 0.5, 0.5)
    overlap = shapely.area(shapely.intersection(boxes, free))
    assert overlap.max(initial=0.0) < 1e-6 * 0.25


# -- errors ---------------------------------------------------------------------------------
def test_errors(tmp_path: Path) -> None:
    bad = tmp_path / "corrupt.png"
    bad.write_bytes(b"\x89PNG\r\n\x1a\n this is not a png")
    with pytest.raises(ScenarioError, match="not a readable image"):
        image_map(bad, scale=0.25)
    with pytest.raises(ScenarioError, match="not found"):
        image_map(tmp_path / "missing.png", scale=0.25)
    with pytest.raises(GeometryError, match="no road joining"):
        image_map(write_png(tmp_path / "dark.png", np.zeros((20, 40))), scale=0.25)
    wall = road_array()
    wall[:, 50:52] = 0.0
    with pytest.raises(GeometryError, match="ends at column 49"):
        image_map(wall, scale=0.25)
    for scale in (0.0, -1.0, float("nan"), float("inf")):
        with pytest.raises(ParameterError, match="scale"):
            image_map(road_array(), scale=scale)
    with pytest.raises(ParameterError, match="threshold"):
        image_map(road_array(), scale=1.0, threshold=1.5)
    img = road_array()
    img[18:22, 30:34] = 0.0
    m = image_map(img, scale=1.0)
    with pytest.raises(GeometryError, match="on an obstacle"):
        m.check_point([31.5, 20.5])
    with pytest.raises(GeometryError, match="off the road"):
        m.check_point([31.5, 2.0], what="goal")
    with pytest.raises(GeometryError, match="outside the map"):
        m.check_point([-3.0, 20.0])


def test_cli_errors_are_one_line(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    bad = tmp_path / "corrupt.png"
    bad.write_bytes(b"garbage")
    cases = [
        [str(bad), "--scale", "0.25"],
        [str(MAPS / "one_obstacle.png"), "--scale", "0"],
        [str(MAPS / "one_obstacle.png"), "--scale", "0.25", "--start", "50,9"],
        [str(write_png(tmp_path / "dark.png", np.zeros((10, 10)))), "--scale", "1"],
        [str(MAPS / "one_obstacle.png"), "--scale", "0.25", "--start", "oops"],
    ]
    for argv in cases:
        argparse_error = "oops" in argv or argv[2] == "0"  # refused as the options are read
        with pytest.raises(SystemExit) if argparse_error else _no_raise():
            code = main(["plan-image", *argv, "--out", str(tmp_path / "o")])
            assert code == 2
        err = capsys.readouterr().err.strip()
        assert err.startswith("splineplan plan-image: error:") and "\n" not in err, err


class _no_raise:
    def __enter__(self) -> None:
        return None

    def __exit__(self, *exc: object) -> bool:
        return False


# -- plan-image, checked on the image's pixels ------------------------------------------------
@pytest.mark.parametrize("name", [
    "empty",
    "one_obstacle",
    "field_c",
    "curved",
    "field_d",
])
def test_plan_image_is_collision_free_on_pixels(name: str, tmp_path: Path) -> None:
    path = MAPS / f"{name}.png"
    out = tmp_path / name
    assert main(["plan-image", str(path), "--scale", str(SCALE), "--out", str(out),
                 "--no-plot"]) == 0
    with (out / "trajectory.csv").open() as fh:
        rows = list(csv.reader(fh))
    assert rows[0][:6] == ["t", "x", "y", "heading", "speed", "curvature"]
    data = np.array(rows[1:], dtype=float)
    t, x, y, heading, speed = data[:, :5].T
    assert np.all(np.diff(t) > 0) and np.all(speed >= 0)
    # it crosses the map from the left edge to the right edge
    assert x[0] < 1.0 and x[-1] > 100.0 - 1.0
    hits = dark_pixels_hit(path, SCALE, swept_footprint(x, y, heading, 4.5, 1.8))
    assert len(hits) == 0, f"footprint covers dark pixels (row, col) {hits[:5].tolist()}"
    # and the image says the start is road
    assert not dark_mask(path)[int(80 - y[0] / SCALE), int(x[0] / SCALE)]


def test_plan_image_oracle_sees_a_collision() -> None:
    """The pixel oracle is not blind: a straight line through one_obstacle hits it."""
    x = np.linspace(0.0, 100.0, 201)
    y = np.full_like(x, 9.0)
    hits = dark_pixels_hit(MAPS / "one_obstacle.png", SCALE,
                           swept_footprint(x, y, np.zeros_like(x), 4.5, 1.8))
    assert len(hits) > 50


def test_plan_image_start_and_goal(tmp_path: Path) -> None:
    out = tmp_path / "sg"
    assert main(["plan-image", str(MAPS / "one_obstacle.png"), "--scale", str(SCALE),
                 "--start", "10,11", "--goal", "80,10", "--out", str(out), "--no-plot"]) == 0
    data = np.loadtxt(out / "trajectory.csv", delimiter=",", skiprows=1)
    assert data[0, 1] == pytest.approx(10.0, abs=1e-6)
    assert data[0, 2] == pytest.approx(11.0, abs=1e-6)
    assert data[-1, 1] == pytest.approx(80.0, abs=0.6)
