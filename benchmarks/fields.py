"""Seeded obstacle fields shared by the roadmap and trajectory benchmarks.

A field is a straight multi-lane road along +x with rows of parked cars. The generator
guarantees a passage for a car of the same size (4.5 x 1.8 m) that respects a 5 m turning
radius: it walks a *path lane* through the rows and never blocks it.

- Each row blocks one lane or several, never all, and never the path lane.
- The path lane changes only to a neighbouring lane, at a row that leaves both the old and
  the new path lane free (so the car may straddle them there), only where the previous and
  the next row stand far enough apart (:data:`LANE_CHANGE_ROOM` of clear road for the car's
  centre: a 3.2 m S-move within a 5 m turning radius needs about 9 m), and never at two
  consecutive rows.
- Cars stand within 0.3 m of their lane's centre and within 0.05 rad of the road's heading.

The same arguments give the same field.
"""

from __future__ import annotations

import numpy as np

from splineplan.corridor import Corridor
from splineplan.geometry import FloatArray
from splineplan.obstacles import Obstacles

LANE_WIDTH = 3.2
CAR_LENGTH = 4.5
CAR_WIDTH = 1.8
#: Shortest row spacing [m] (centre to centre): a car length and 3 m between rows.
MIN_ROW_STEP = CAR_LENGTH + 3.0
#: Road [m] that a lane change needs for the car's centre, clear of the rows before and after.
LANE_CHANGE_ROOM = 2.0 * CAR_LENGTH + 1.0
#: Road [m] kept clear at the start and at the end.
START_CLEAR, END_CLEAR = 25.0, 10.0


def obstacle_field(
    length: float = 300.0, n_obstacles: int = 40, width: float = 9.6, seed: int = 0
) -> tuple[Corridor, Obstacles, FloatArray]:
    """A straight road along +x with parked cars in rows and a guaranteed passage.

    The road is ``width`` [m] wide (lanes of about 3.2 m, centred on y = 0) and ``length``
    [m] long. The rows stand about evenly from 25 m to 10 m before the end, at least
    :data:`MIN_ROW_STEP` apart; rows hold one car, or up to ``lanes - 1`` to fit the count.
    See the module docstring for the passage. Raises ``ValueError`` if the cars do not fit
    (on 3 lanes: at most ``2 * floor((length - 35) / 7.5)`` cars, 70 on 300 m; 80 fit from
    335 m on). Returns the corridor, the obstacles and the start point (1 m in, centre of
    the rightmost lane).
    """
    rng = np.random.default_rng(seed)
    n_lanes = max(round(width / LANE_WIDTH), 1)
    centres = (np.arange(n_lanes) - (n_lanes - 1) / 2.0) * (width / n_lanes)
    per_row_max = max(n_lanes - 1, 1)
    span = length - START_CLEAR - END_CLEAR
    fit = int(span // MIN_ROW_STEP)
    # about 1.5 cars per row, more per row where the road is too short for that many rows
    n_rows = max(int(np.ceil(n_obstacles / per_row_max)),
                 min(int(np.ceil(n_obstacles / (1.0 + 0.5 * (per_row_max - 1)))), fit))
    n_rows = min(n_rows, n_obstacles)
    if n_obstacles > 0 and (n_lanes < 2 or n_rows > fit or n_rows * per_row_max < n_obstacles):
        raise ValueError(f"{n_obstacles} obstacles do not fit on {length} m x {width} m "
                         f"with a passage")
    counts = np.ones(n_rows, dtype=int)
    extra = n_obstacles - n_rows
    while extra > 0:  # spread the extra cars over rows with room
        room = np.flatnonzero(counts < per_row_max)
        add = rng.choice(room, size=min(extra, len(room)), replace=False)
        counts[add] += 1
        extra -= len(add)
    step = span / max(n_rows, 1)
    jitter = 0.2 * max(step - MIN_ROW_STEP, 0.0)
    rows_s = START_CLEAR + (np.arange(n_rows) + 0.5) * step + rng.uniform(-jitter, jitter,
                                                                          n_rows)
    pos, head = [], []
    path = 0  # the start's lane
    changed = False
    for r in range(n_rows):
        before = rows_s[r - 1] if r > 0 else 0.0
        after = rows_s[r + 1] if r + 1 < n_rows else length
        room_ok = after - before - 2.0 * CAR_LENGTH >= LANE_CHANGE_ROOM
        options = [q for q in (path - 1, path + 1) if 0 <= q < n_lanes]
        new = path
        if (not changed and room_ok and counts[r] <= n_lanes - 2 and options
                and rng.random() < 0.5):
            new = int(rng.choice(options))
        changed = new != path
        others = [i for i in range(n_lanes) if i not in (path, new)]
        blocked = rng.choice(others, size=min(int(counts[r]), len(others)), replace=False)
        for lane in blocked:
            pos.append((rows_s[r], centres[lane] + rng.uniform(-0.3, 0.3)))
            head.append(rng.uniform(-0.05, 0.05))
        path = new
    ref = np.column_stack((np.linspace(0.0, length, 3), np.zeros(3)))
    corridor = Corridor.from_reference(ref, np.full(3, width / 2.0), np.full(3, -width / 2.0))
    obstacles = (Obstacles.from_boxes(np.asarray(pos), np.asarray(head), CAR_LENGTH, CAR_WIDTH)
                 if pos else Obstacles.empty())
    return corridor, obstacles, np.array([1.0, centres[0]])
