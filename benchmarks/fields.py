"""Seeded obstacle fields shared by the roadmap and trajectory benchmarks."""

from __future__ import annotations

import numpy as np

from splineplan.corridor import Corridor
from splineplan.geometry import FloatArray
from splineplan.obstacles import Obstacles

LANE_WIDTH = 3.2
CAR_LENGTH = 4.5
CAR_WIDTH = 1.8


def obstacle_field(
    length: float = 300.0, n_obstacles: int = 40, width: float = 9.6, seed: int = 0
) -> tuple[Corridor, Obstacles, FloatArray]:
    """A straight road along +x with parked cars in rows, every row leaving a lane free.

    The road is ``width`` [m] wide (lanes of 3.2 m, centred on y = 0) and ``length`` [m]
    long. Cars (4.5 x 1.8 m) stand in rows about evenly spaced from 25 m to 10 m before the
    end; a row blocks one or two lanes, never all, and always leaves free a lane that the
    previous row left free too; cars stand within 0.3 m of their lane's centre, so a passage
    always exists for a vehicle of the same size. Returns the
    corridor, the obstacles and the start point (1 m in, centre of the rightmost lane).
    """
    rng = np.random.default_rng(seed)
    n_lanes = max(round(width / LANE_WIDTH), 1)
    centres = (np.arange(n_lanes) - (n_lanes - 1) / 2.0) * (width / n_lanes)
    per_row_max = max(n_lanes - 1, 1)
    span = length - 35.0
    n_rows = max(int(np.ceil(n_obstacles / (1.0 + 0.5 * (per_row_max - 1)))), 1)
    if n_obstacles > 0 and (span / n_rows < CAR_LENGTH + 3.0 or n_rows * per_row_max
                            < n_obstacles):
        raise ValueError(f"{n_obstacles} obstacles do not fit on {length} m with passages")
    counts = np.ones(n_rows, dtype=int)
    extra = n_obstacles - n_rows
    if extra > 0:
        counts[rng.choice(n_rows, size=extra, replace=False)] += 1
    counts = counts[:n_obstacles] if n_obstacles < n_rows else counts
    pos, head = [], []
    step = span / max(len(counts), 1)
    free = set(range(n_lanes))
    for r, c in enumerate(counts):
        s = 25.0 + (r + 0.5) * step + rng.uniform(-0.2, 0.2) * (step - CAR_LENGTH - 3.0)
        # keep one lane free that the previous row also left free: a passage without
        # squeezing between rows
        keep_free = int(rng.choice(sorted(free)))
        others = [i for i in range(n_lanes) if i != keep_free]
        blocked = rng.choice(others, size=min(int(c), len(others)), replace=False)
        free = set(range(n_lanes)) - {int(b) for b in blocked}
        for lane in blocked:
            pos.append((s, centres[lane] + rng.uniform(-0.3, 0.3)))
            head.append(rng.uniform(-0.05, 0.05))
    ref = np.column_stack((np.linspace(0.0, length, 3), np.zeros(3)))
    corridor = Corridor.from_reference(ref, np.full(3, width / 2.0), np.full(3, -width / 2.0))
    obstacles = (Obstacles.from_boxes(np.asarray(pos), np.asarray(head), CAR_LENGTH, CAR_WIDTH)
                 if pos else Obstacles.empty())
    return corridor, obstacles, np.array([1.0, centres[0]])
