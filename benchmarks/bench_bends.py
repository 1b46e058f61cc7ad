"""Edges' own bends: level 1's test against the kinematic oracle.

``python -m benchmarks bends [--nets monaco city grid] [--oracle-cache FILE] [-v]``.
For every edge the passenger class may use, the runs of vertices turning one way that
:func:`splineplan.network.bend_fits` looks at (a turn above ``FIT_STRAIGHT`` that a
single kink of it would not allow, at least ``BEND_LEAD`` from the edge's ends). The
oracle (:mod:`benchmarks.kinematic_oracle`: hybrid A*, the 4.5 x 1.8 m car, 4.2 m turning
radius, raster 5 cm) drives from the middle of the rightmost allowed lane 12 m before the
run to the allowed lanes 10-12 m after it, inside the edge's allowed lanes (each a band of
its width about its centre line, mitred at its bends, as SUMO draws it). Printed per
network: runs, oracle-drivable, and how often the level-1 test agrees.
"""

from __future__ import annotations

import argparse
import json
import math
import time
from pathlib import Path

from benchmarks.kinematic_oracle import Search, drive
from benchmarks.turns import lane_band

ROOT = Path(__file__).resolve().parent.parent
NETS = {"city": ROOT / "sumo_nets" / "city.net.xml", "grid": ROOT / "sumo_nets" / "grid.net.xml",
        "monaco": ROOT.parent / "shared" / "data" / "monaco.net.xml.gz"}
#: How far [m] before and after a run the oracle's car starts and ends.
LEAD = 12.0
SEARCH = Search(step=0.05)


def bench(path: Path, cache: dict[str, bool], verbose: bool) -> dict[str, int]:
    """Oracle and level-1 test on each run of one network; print and return the counts."""
    from shapely.geometry import LineString
    from shapely.ops import substring, unary_union

    import splineplan.network as nw

    net = nw.load_network(path)
    car = nw.CarShape()
    counts = {"runs": 0, "drivable": 0, "agree": 0, "refused": 0, "passed": 0}
    t0 = time.perf_counter()
    for edge in net.edge_ids:
        lanes = [ln for ln in net.lanes_of(edge) if ln.allows("passenger")]
        ref, st, runs = nw.sharp_runs(lanes, car)
        area = None
        for first, last, turn in runs:
            key = f"{path.name}:{edge}:{first}:{last}"
            if key not in cache:
                line = LineString(ref)
                if area is None:
                    area = unary_union([lane_band(ln.shape, ln.width) for ln in lanes])
                s0, s1 = float(st[first]) - LEAD, float(st[last]) + LEAD
                p0, p1 = line.interpolate(s0), line.interpolate(s0 + 0.3)
                heading = math.atan2(p1.y - p0.y, p1.x - p0.x)
                goal = area.intersection(substring(line, s1 - 2.0, s1).buffer(
                    8.0, cap_style="flat"))
                window = area.intersection(substring(line, s0 - 4.0, s1 + 2.0).buffer(
                    8.0, cap_style="flat"))
                cache[key] = bool(drive(window, [], (p0.x, p0.y, heading), goal,
                                        margin=0.0, search=SEARCH).found)
            drives = cache[key]
            lane_run = nw._run_fits(ref, st, lanes, float(st[first]), float(st[last]), turn,
                                    car)
            counts["runs"] += 1
            counts["drivable"] += drives
            counts["agree"] += drives == lane_run
            counts["refused"] += drives and not lane_run
            counts["passed"] += lane_run and not drives
            if verbose and drives != lane_run:
                print(f"  {edge} vertices {first}-{last}, {math.degrees(turn):.0f} degrees: "
                      f"oracle {'drives' if drives else 'cannot'}, level 1 "
                      f"{'fits' if lane_run else 'too tight'}", flush=True)
    n = counts["runs"]
    print(f"{path.name}: {n} sharp runs, oracle-drivable {counts['drivable']}; level 1 "
          f"agrees on {counts['agree']} ({100.0 * counts['agree'] / max(n, 1):.1f} %), "
          f"refuses {counts['refused']} the oracle drives, passes {counts['passed']} it "
          f"cannot ({time.perf_counter() - t0:.0f} s)", flush=True)
    return counts


def main(argv: list[str]) -> int:
    ap = argparse.ArgumentParser(prog="python -m benchmarks bends", description=__doc__)
    ap.add_argument("--nets", nargs="+", default=["city", "grid", "monaco"],
                    choices=sorted(NETS))
    ap.add_argument("--oracle-cache", type=Path,
                    help="JSON file of the oracle's verdicts, read if present and updated")
    ap.add_argument("-v", "--verbose", action="store_true",
                    help="a line per run where the two differ")
    args = ap.parse_args(argv)
    cache: dict[str, bool] = {}
    if args.oracle_cache is not None and args.oracle_cache.exists():
        cache.update(json.loads(args.oracle_cache.read_text()))
    for name in args.nets:
        if not NETS[name].exists():
            print(f"{name}: {NETS[name]} not found, skipped")
            continue
        bench(NETS[name], cache, args.verbose)
    if args.oracle_cache is not None:
        args.oracle_cache.write_text(json.dumps(cache))
    return 0


if __name__ == "__main__":
    import sys

    sys.exit(main(sys.argv[1:]))
