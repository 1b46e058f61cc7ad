"""Regenerate the example map images of this folder: ``python scenarios/maps/make_maps.py``.

Every map is drawn at 0.25 m per pixel (``splineplan plan-image MAP.png --scale 0.25``):
light (white) is road, dark (black) is an obstacle or off-road. The road runs from the
left edge to the right edge. The maps mirror the paper's Fig. 4 (Kala & Warwick):

- ``empty.png``: a straight road 12 m wide, 100 m long, no obstacle (Fig. 4a).
- ``one_obstacle.png``: the same road with one boulder (Fig. 4b).
- ``field_c.png``: a field of mixed obstacles, one of them L-shaped (Fig. 4c).
- ``field_d.png``: a denser field with a cup-shaped obstacle open towards the vehicle
  (Fig. 4d).
- ``curved.png``: a road that bends (a sine wave, 10 m wide) with two obstacles.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from PIL import Image

HERE = Path(__file__).resolve().parent
SCALE = 0.25  # metres per pixel
WIDTH, HEIGHT = 400, 80  # pixels: 100 m x 20 m


def _canvas() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Dark image and the metric centre coordinates (x, y) of every pixel."""
    img = np.zeros((HEIGHT, WIDTH), dtype=np.uint8)
    cols, rows = np.meshgrid(np.arange(WIDTH), np.arange(HEIGHT))
    x = (cols + 0.5) * SCALE
    y = (HEIGHT - rows - 0.5) * SCALE
    return img, x, y


def _straight_road() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    img, x, y = _canvas()
    img[(y >= 4.0) & (y <= 16.0)] = 255
    return img, x, y


def _disc(img: np.ndarray, x: np.ndarray, y: np.ndarray, cx: float, cy: float,
          r: float) -> None:
    img[np.hypot(x - cx, y - cy) <= r] = 0


def _box(img: np.ndarray, x: np.ndarray, y: np.ndarray, x0: float, x1: float, y0: float,
         y1: float) -> None:
    img[(x >= x0) & (x <= x1) & (y >= y0) & (y <= y1)] = 0


def empty() -> np.ndarray:
    return _straight_road()[0]


def one_obstacle() -> np.ndarray:
    img, x, y = _straight_road()
    _disc(img, x, y, 50.0, 9.0, 2.5)
    return img


def field_c() -> np.ndarray:
    img, x, y = _straight_road()
    _disc(img, x, y, 25.0, 12.0, 2.0)
    _box(img, x, y, 38.0, 42.0, 4.0, 8.5)  # touches the right road edge
    _box(img, x, y, 55.0, 57.0, 9.0, 14.0)  # L-shape: upright ...
    _box(img, x, y, 55.0, 62.0, 9.0, 10.5)  # ... and foot
    _disc(img, x, y, 75.0, 7.0, 1.5)
    _disc(img, x, y, 82.0, 13.0, 1.5)
    return img


def field_d() -> np.ndarray:
    img, x, y = _straight_road()
    _box(img, x, y, 20.0, 28.0, 11.5, 12.5)  # cup open to the left
    _box(img, x, y, 20.0, 28.0, 7.5, 8.5)
    _box(img, x, y, 27.0, 28.0, 7.5, 12.5)
    _disc(img, x, y, 40.0, 5.5, 1.5)
    _disc(img, x, y, 45.0, 14.0, 1.5)
    _disc(img, x, y, 52.0, 9.0, 1.8)
    _box(img, x, y, 62.0, 66.0, 11.0, 16.0)
    _box(img, x, y, 70.0, 73.0, 4.0, 8.0)
    _disc(img, x, y, 85.0, 10.5, 2.0)
    return img


def curved() -> np.ndarray:
    img, x, y = _canvas()
    centre = 10.0 + 4.0 * np.sin(2 * np.pi * x / 100.0)
    img[np.abs(y - centre) <= 5.0] = 255
    _disc(img, x, y, 30.0, 10.0 + 4.0 * np.sin(0.6 * np.pi) + 1.5, 1.5)
    _disc(img, x, y, 70.0, 10.0 + 4.0 * np.sin(1.4 * np.pi) - 1.5, 1.5)
    return img


MAPS = {
    "empty": empty,
    "one_obstacle": one_obstacle,
    "field_c": field_c,
    "field_d": field_d,
    "curved": curved,
}


def main() -> None:
    for name, draw in MAPS.items():
        Image.fromarray(draw(), mode="L").save(HERE / f"{name}.png", optimize=True)


if __name__ == "__main__":
    main()
