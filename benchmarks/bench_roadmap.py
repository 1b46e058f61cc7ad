"""Level-2 roadmap: build and search time on a multi-lane road with parked cars.

Base case (the target: at most 5 ms median): a 300 m straight segment of a 3-lane road
(9.6 m wide), 40 car-sized obstacles (4.5 x 1.8 m) at random positions and headings that
leave a passage, d = 1 m. Then the time against segment length, d and obstacle count.
"""

from __future__ import annotations

import statistics
import time

import numpy as np

from splineplan.corridor import Corridor
from splineplan.errors import RoadBlockedError
from splineplan.obstacles import Obstacles
from splineplan.roadmap import RoadmapParams, plan_roadmap

ROAD_WIDTH = 9.6
SEED = 20240601


def straight_road(length: float, width: float = ROAD_WIDTH) -> Corridor:
    """A straight corridor along +x from the origin, ``width`` [m] wide."""
    x = np.array([0.0, length])
    return Corridor.from_boundaries(np.column_stack((x, [width / 2] * 2)),
                                    np.column_stack((x, [-width / 2] * 2)))


def parked_cars(
    corridor: Corridor, count: int, rng: np.random.Generator, params: RoadmapParams
) -> Obstacles:
    """``count`` cars in the road's three lanes at random stations, lateral positions and
    headings (up to 30 deg off the road's), never two in different lanes less than 7 m
    apart, so that a passage stays open; the first 10 m are kept clear for the start."""
    lane = ROAD_WIDTH / 3
    for _ in range(100):
        s: list[float] = []
        lanes: list[int] = []
        while len(s) < count:
            si, li = float(rng.uniform(10.0, corridor.length - 3.0)), int(rng.integers(3))
            if all(abs(si - sj) >= 7.0 or li == lj for sj, lj in zip(s, lanes, strict=True)):
                s.append(si)
                lanes.append(li)
        sa = np.asarray(s)
        lat = (np.asarray(lanes) - 1) * lane + rng.uniform(-0.5, 0.5, count)
        head = corridor.heading_at(sa) + rng.uniform(-np.pi / 6, np.pi / 6, count)
        obs = Obstacles.from_boxes(corridor.to_xy(sa, lat), head, 4.5, 1.8)
        try:
            plan_roadmap(corridor, obs, corridor.to_xy(0.0, 0.0), params)
        except RoadBlockedError:
            continue
        return obs
    raise RuntimeError("could not draw a passable field")


def time_case(length: float, d: float, count: int, *, repeat: int = 30,
              seed: int = SEED) -> float:
    """Median time [ms] of plan_roadmap on one field."""
    params = RoadmapParams(d=d, segment_length=max(length, 2 * d))
    corridor = straight_road(length)
    obs = parked_cars(corridor, count, np.random.default_rng(seed), params)
    start = corridor.to_xy(0.0, 0.0)
    plan_roadmap(corridor, obs, start, params)
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        plan_roadmap(corridor, obs, start, params)
        times.append(time.perf_counter() - t0)
    return 1e3 * statistics.median(times)


def main(argv: list[str]) -> None:
    base = time_case(300.0, 1.0, 40, repeat=100)
    print(f"base: 300 m, d = 1 m, 40 cars: {base:.2f} ms median (target 5 ms)")
    for length in (100.0, 300.0, 1000.0, 3000.0):
        print(f"length {length:6.0f} m (d = 1, 40 cars per 300 m): "
              f"{time_case(length, 1.0, round(40 * length / 300)):.2f} ms")
    for d in (0.25, 0.5, 1.0, 2.0):
        print(f"d {d:4.2f} m (300 m, 40 cars): {time_case(300.0, d, 40):.2f} ms")
    for count in (0, 10, 40, 80):
        print(f"{count:3d} cars (300 m, d = 1): {time_case(300.0, 1.0, count):.2f} ms")


if __name__ == "__main__":
    main([])
