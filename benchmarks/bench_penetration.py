"""Several planned vehicles in one SUMO run, at rising shares of the traffic.

``python -m benchmarks penetration [--seeds N] [--shares S ...] [--workers N] [--monaco]``

1. The city network with its bundled random traffic (``scenarios/city_traffic.sumocfg``,
   about 400 vehicles): a penetration sweep (:mod:`splineplan.sweep`) at each share over
   seeds. Prints, per share, the planned vehicles that arrived, collisions, time off the
   road, mean travel time and time loss of every vehicle, and for each run the wall time
   against the simulated time and per planned vehicle and simulated second.
2. ``--monaco`` (when ``../shared/data`` holds the Monaco network): demand made by SUMO's
   ``randomTrips.py`` (1,000 trips in the hour, routed by duarouter), 10 % of the passenger
   cars planned, one seed: whether it completes, its collisions, and its wall time.
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

from splineplan.sweep import build_sweep, run_sweep, summarise

ROOT = Path(__file__).resolve().parent.parent
CITY = ROOT / "scenarios" / "city_traffic.sumocfg"
MONACO = ROOT.parent / "shared" / "data" / "monaco.net.xml.gz"


def _report(res, label: str) -> None:  # type: ignore[no-untyped-def]
    print(f"{label}: {len(res.rows)} runs in {res.wall_time:.0f} s on {res.executor}")
    for s in summarise(res.rows):
        print(f"  share {100 * s['share']:5.1f} %: {s['runs']} runs ({s['failed']} failed), "
              f"planned arrived {s['planned_arrived']}/{s['planned']}, collisions "
              f"{s['collisions']}, mean travel time {s['mean_travel_time'] or 0:.1f} s, "
              f"time loss {s['mean_time_loss'] or 0:.1f} s, throughput "
              f"{s['throughput'] or 0:.0f} veh/h")
    for r in res.rows:
        summary = Path(r["run_dir"]) / "summary.json"
        m = json.loads(summary.read_text()) if summary.is_file() else {}
        rt = m.get("real_time_factor")
        per = m.get("wall_time_per_vehicle_second")
        print(f"  {r['name']}: {r['status']}, off road {r['time_off_road'] or 0:.1f} s, "
              f"wall {r['wall_time'] or 0:.0f} s for {r['sim_time'] or 0:.0f} s simulated"
              f" ({'-' if rt is None else f'{rt:.2f}x real time'}), "
              f"{'-' if per is None else f'{1e3 * per:.1f} ms'} per planned vehicle-second")
    times = [r["wall_time"] for r in res.rows if r["wall_time"]]
    if times:
        print(f"  median wall time per run {statistics.median(times):.0f} s")


def _monaco_demand(out: Path) -> Path:
    """A SUMO configuration: Monaco with 1,000 random trips in an hour (randomTrips.py)."""
    import sumo

    tools = Path(sumo.SUMO_HOME) / "tools"
    trips = out / "monaco.trips.xml"
    routes = out / "monaco.rou.xml"
    subprocess.run([sys.executable, str(tools / "randomTrips.py"), "-n", str(MONACO),
                    "-e", "3600", "-p", "3.6", "--seed", "1", "--fringe-factor", "5",
                    "--min-distance", "300", "-o", str(trips), "-r", str(routes),
                    "--validate", "--trip-attributes", 'departLane="best" departSpeed="max"',
                    "--vehicle-class", "passenger"],
                   check=True, capture_output=True, text=True)
    cfg = out / "monaco.sumocfg"
    cfg.write_text(f'<configuration>\n  <input>\n    <net-file value="{MONACO}"/>\n'
                   f'    <route-files value="{routes.name}"/>\n  </input>\n  <time>\n'
                   '    <begin value="0"/>\n    <end value="3600"/>\n'
                   '    <step-length value="0.1"/>\n  </time>\n</configuration>\n')
    return cfg


def main(argv: list[str]) -> None:
    ap = argparse.ArgumentParser(prog="python -m benchmarks penetration")
    ap.add_argument("--seeds", type=int, default=5)
    ap.add_argument("--shares", type=float, nargs="+", default=[0.0, 0.1, 0.25, 0.5, 1.0])
    ap.add_argument("--workers", type=int, default=None)
    ap.add_argument("--out", default=None, help="output folder (default: a temporary one)")
    ap.add_argument("--monaco", action="store_true", help="also the Monaco run")
    ap.add_argument("--no-city", action="store_true", help="skip the city sweep")
    args = ap.parse_args(argv)
    out = Path(args.out or tempfile.mkdtemp(prefix="splineplan_penetration_"))
    if not args.no_city:
        points = build_sweep(CITY, shares=args.shares, seeds=args.seeds)
        res = run_sweep(points, out_dir=out / "city", workers=args.workers, progress=False)
        _report(res, "city_traffic")
    if args.monaco:
        if not MONACO.is_file():
            print(f"Monaco skipped: {MONACO} not found")
            return
        (out / "monaco").mkdir(parents=True, exist_ok=True)
        cfg = _monaco_demand(out / "monaco")
        points = build_sweep(cfg, shares=(0.1,), seeds=1)
        res = run_sweep(points, out_dir=out / "monaco" / "sweep", workers=1, progress=False)
        _report(res, "monaco (randomTrips, 10 % planned)")
    print(f"outputs in {out}")
