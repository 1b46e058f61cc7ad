"""First-run compile time: the planner's numba loops compiled from an empty cache.

Each run is a fresh process with its own empty ``NUMBA_CACHE_DIR`` (the package's own cache
in ``__pycache__`` is left alone):

- ``cold``: ``splineplan simulate scenarios/city.toml`` (or ``plan ...``) on an empty cache,
  as the first run after an install;
- ``warm``: the same command again on the cache the cold run filled;
- ``compile 1`` / ``compile N``: ``python -m splineplan.precompile --jobs 1`` (the loops one
  after another, as numba compiles them on first call) and with one process per CPU.

Prints the median wall time [s] and CPU time [s] (this process's children: user + system)
of each, cold minus warm, and the load average before and after (the machine may be
shared: the figures mean something only when it is quiet).

``python -m benchmarks compile [--repeat N] [--command simulate|plan]``
"""

from __future__ import annotations

import argparse
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
COMMANDS = {
    "simulate": ["simulate", "scenarios/city.toml", "--no-progress"],
    "plan": ["plan", "sumo_nets/city.net.xml", "SWA0", "G1G2"],
}


def _run(args: list[str], cache: Path) -> tuple[float, float]:
    """Wall and CPU time [s] of ``python ARGS`` with the numba cache in ``cache``."""
    env = dict(os.environ, NUMBA_CACHE_DIR=str(cache),
               PYTHONPATH=os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")]))
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    subprocess.run([sys.executable, *args], cwd=ROOT, env=env, check=True,
                   stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return wall, cpu


def main(argv: list[str]) -> None:
    ap = argparse.ArgumentParser(prog="bench_compile", description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--command", choices=sorted(COMMANDS), default="simulate")
    args = ap.parse_args(argv)
    jobs = os.cpu_count() or 1
    times: dict[str, list[tuple[float, float]]] = {
        "cold": [], "warm": [], "compile 1": [], f"compile {jobs}": []}
    load0 = os.getloadavg()
    with tempfile.TemporaryDirectory() as tmp:
        for i in range(args.repeat):
            out = Path(tmp) / f"out{i}"
            cli = ["-m", "splineplan.cli", *COMMANDS[args.command], "--out", str(out)]
            cache = Path(tmp) / f"cache{i}"
            times["cold"].append(_run(cli, cache))
            times["warm"].append(_run(cli, cache))
            for n in (1, jobs):
                times[f"compile {n}"].append(
                    _run(["-m", "splineplan.precompile", "--jobs", str(n)],
                         Path(tmp) / f"cache{i}-{n}"))
    load1 = os.getloadavg()
    print(f"{args.command}, {args.repeat} runs, {jobs} CPUs; load average "
          f"{load0[0]:.1f} before, {load1[0]:.1f} after")
    med = {k: (statistics.median(w for w, _ in v), statistics.median(c for _, c in v))
           for k, v in times.items()}
    for k, (wall, cpu) in med.items():
        runs = ", ".join(f"{w:.1f}" for w, _ in times[k])
        print(f"  {k:<10} median wall {wall:6.1f} s  cpu {cpu:6.1f} s   (walls: {runs})")
    print(f"  cold - warm: {med['cold'][0] - med['warm'][0]:.1f} s")
