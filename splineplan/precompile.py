"""The planner's compiled loops, compiled ahead of their first call and in parallel.

numba compiles a loop on its first call and caches the machine code on disk (in
``__pycache__`` beside the module, or numba's user cache directory where that is not
writable). Called one after another, the loops of a first run after an install took about
38 s of CPU before anything moved. :func:`ensure` compiles the ones missing from the cache
in one process per idle CPU (this one and helpers started with ``python -m
splineplan.precompile``), each writing its share to the cache, so that the planner then
loads them.

:data:`SIGNATURES` lists every loop with the argument types the planner calls it with:
float64 and int64 arrays that are C-contiguous and writeable
(:func:`splineplan.geometry.kernel_floats`), Python floats, ints and bools. A call with
other types still works: numba compiles that specialisation on the spot.
"""

from __future__ import annotations

import argparse
import importlib
import logging
import os
import subprocess
import sys
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from numba import types as nt

log = logging.getLogger(__name__)

F1, F2, F3 = nt.float64[::1], nt.float64[:, ::1], nt.float64[:, :, ::1]
I1, I2, B1 = nt.int64[::1], nt.int64[:, ::1], nt.boolean[::1]
f8, i8, b1 = nt.float64, nt.int64, nt.boolean
#: :meth:`splineplan.footprint._Checker.slack_args`: road frames, windows, obstacles.
_CHECKER = (F1,) * 13 + (f8,) * 5 + (F1,) * 6 + (I1, F2, f8)

#: Per module: its loops' compile time [s of CPU, measured] (to share the modules out
#: between processes) and each loop's signatures. A module compiles in one process: the
#: loops that call one another live in one module (see :mod:`splineplan.kernels`).
SIGNATURES: dict[str, tuple[float, dict[str, tuple[tuple[Any, ...], ...]]]] = {
    "splineplan.kernels": (11.8, {
        "upper": ((F1, f8),),
        "lower": ((F1, f8),),
        "road_one": ((f8, f8, f8, f8, *(F1,) * 13, f8, f8, f8, f8, i8),),
        "road_clearance": (((F1,) * 17 + (f8,) * 5),),
        "obstacle_clearance": ((F1, F1, F1, F1, F1, I1, F2, f8, f8, f8, f8, b1),),
        "rect_polygon_distance": ((F1, F1, f8, f8),),
        "footprint_slack": ((F1, F1, F1, F1, *_CHECKER),),
        "curvature": ((f8, f8, f8, f8),),
        "optimise": ((F2, F2, F2, F2, F1, F1, F1, I1, F3, I1, I1, I2, B1, B1, i8, f8, f8, i8,
                      i8, F1, nt.Tuple(_CHECKER)),),
        "steering_angle": ((f8, f8),),
        "allowed_speeds": ((F2, F2, F2, i8, i8, f8, f8, f8, f8),),
        "_smooth_targets": ((F2, i8),),
        "_smooth_move": ((i8, F2, F2, F2, F2, F1, F1, F1, I1, F3, I1, I1, f8, f8, f8, f8, f8,
                          F1, nt.Tuple(_CHECKER)),),
        "smooth_steering": ((F2, F2, F2, F2, F1, F1, F1, I1, F3, I1, I1, I2, B1, i8, f8, f8,
                             f8, f8, f8, f8, f8, f8, i8, F1, nt.Tuple(_CHECKER)),),
        "box_gap_one": ((f8,) * 10,),
        "body_meetings": ((I1, i8, F1, F2, F1, F1, F1, F1, F1, F2, F1, f8, f8),),
        "crosses": ((F2, F1, B1, F2, F1, f8, f8, f8, f8, f8, f8),),
        "box_gaps": ((F2, F1, F1, F1, F2, F1, F1, F1),),
        "first_touch": ((F2, F1, F1, F1, F2, F2, F1, F1, F1, F2, F1),),
        "towed_slip": ((F1, F1, f8, f8),),
        "first_in_circles": ((F2, i8, F1, F1, F1, F1),),
        "blocked_samples": ((F2, F1, f8, f8, F2, F1, I1, f8, f8, f8, f8),),
    }),
    "splineplan.spacetime": (1.5, {
        "_drive": ((F1, F1, F1, F1, f8, f8, f8, f8),),
        "_safe_speed": ((f8, F1, F1, i8, i8, f8, f8),),
    }),
    "splineplan.roadmap": (10.2, {
        "_cull_kernel": ((F2, F2, F2, f8),),
        "_slab": ((f8, f8, f8, f8),),
        "_capsule_on_line": ((f8, f8, f8, f8, f8),),
        "_free_kernel": ((I1, I1, *(F1,) * 10, I1, f8, f8),),
        "_arc_pairs": ((I1, i8),),
        "_retries": ((B1, I1, I1, I1, F1, F1, i8, i8),),
        "_gather": ((I1, I1, B1, F2, F2, I1, B1, F2, F2),),
        "_point_segment": ((f8,) * 6,),
        "_segment_distance": ((f8,) * 8,),
        "_links_kernel": ((I1, I1, I1, I1, I1, F1, F1, F1, F1, F1, F1, F2, I1, F1, F1, F1, F1,
                           f8),),
        "_bent_kernel": ((F1,) * 5,),
        "_search_kernel": ((i8, I1, I1, F1, I1, F1, I1, i8, f8),),
        "_windows": ((F1, f8),),
        "_place_kernel": (((F1,) * 9 + (B1,) + (f8,) * 9),),
    }),
    "splineplan.control_polygon": (4.2, {
        "_bending_system": ((F2, F2, F1, f8, F1, F1),),
        "_hess": ((F1, F1, F1, F1),),
        "_pinned_solve": ((F1, F1, F1, F1, F1, F1, B1, B1, i8, F2, F1),),
        "_min_bending_loops": ((F1, F1, F1, F1, F1, F1, i8),),
        "_leg_splits": ((f8,) * 5,),
        "_leg_pieces": ((F1, i8, f8, f8, b1),),
        "_leg_fractions": ((F1, B1, f8, f8, b1),),
        "_farthest_from": ((f8, f8, i8, i8, F3, F2, F2, f8),),
        "_band_simplify_loop": ((F3, F2, F2, f8),),
        "_fill_bins": ((I2, I1, I1, I1),),
        "_detour_sweep": ((F1, F2, I2, nt.boolean[:, :, ::1], nt.boolean[:, ::1], F2, i8),),
        "_detour_bins": ((I2, i8, i8),),
    }),
    "splineplan.optimiser": (2.0, {
        "_basis_kernel": ((F1, F1, i8, i8),),
        "_evaluate_kernel": ((F2, I1, F3, i8),),
        "_repair_marks": ((I1, I1, I1, I1, F2, F2, i8),),
    }),
    "splineplan.corridor": (3.0, {
        "_grid_build": ((F1, F1, f8),),
        "_grid_nearest": ((F1, F1, F1, F1, f8, f8, f8, i8, i8, I1, I1, i8),),
        "_project_kernel": ((F1, F1, I1, F1, F1, F1, F1, F1),),
    }),
    "splineplan.network": (2.5, {
        "_paved_spans": ((F1, F1, F1, F1, F1, F1, F1, I1, f8),),
    }),
    "splineplan.lattice": (1.0, {
        "_search": ((F2, F3, I2, I2, F2, i8, f8, I1),),
    }),
    "splineplan.turnpath": (3.0, {
        "_fill": ((F1, F1, I1, f8, f8, i8, i8, f8),),
        "_search": ((F2, f8, f8, F2, F2, F1, F1, f8, f8, i8),),
    }),
    "splineplan.obstacles": (1.0, {
        "_swept_hulls": ((F1, F1, I1, F1, F1),),
    }),
}


def _dispatcher(module: str, name: str) -> Any:
    return getattr(importlib.import_module(module), name)


def _in_cache(disp: Any, sig: tuple[Any, ...]) -> bool:
    """Whether numba's disk cache holds ``disp`` compiled for ``sig`` (numba's own lookup,
    without loading the code)."""
    cache = disp._cache
    key = cache._index_key(sig, disp.targetctx.codegen())
    return key in cache._cache_file._load_index()


def missing() -> list[str]:
    """The modules of :data:`SIGNATURES` with a loop or a signature not in the disk cache
    (none where the cache cannot be read)."""
    todo = []
    for module, (_, loops) in SIGNATURES.items():
        try:
            if not all(_in_cache(_dispatcher(module, name), sig)
                       for name, sigs in loops.items() for sig in sigs):
                todo.append(module)
        except (AttributeError, OSError) as err:  # another numba, or no cache: compile lazily
            log.debug("cannot tell whether %s is cached: %s", module, err)
    return todo


def compile_here(modules: Sequence[str]) -> None:
    """Compile (or load from the disk cache) every loop of ``modules`` in this process."""
    for module in modules:
        for name, sigs in SIGNATURES[module][1].items():
            disp = _dispatcher(module, name)
            for sig in sigs:
                disp.compile(sig)


def share(modules: Sequence[str], jobs: int) -> list[list[str]]:
    """``modules`` in at most ``jobs`` groups of about equal compile time (largest first
    into the lightest group); the heaviest group first."""
    groups: list[list[str]] = [[] for _ in range(max(1, min(jobs, len(modules))))]
    load = [0.0] * len(groups)
    for m in sorted(modules, key=lambda m: -SIGNATURES[m][0]):
        g = load.index(min(load))
        groups[g].append(m)
        load[g] += SIGNATURES[m][0]
    order = sorted(range(len(groups)), key=lambda g: -load[g])
    return [groups[g] for g in order if groups[g]]


def _cpu_times() -> tuple[float, float]:
    """Idle and total CPU time of the machine so far [clock ticks] (Linux's /proc/stat)."""
    with open("/proc/stat") as f:
        ticks = [float(v) for v in f.readline().split()[1:9]]
    return ticks[3] + ticks[4], sum(ticks)


def free_cpus(window: float = 0.2) -> int:
    """CPUs idle over the next ``window`` [s] (at least one; all of them where that cannot
    be told). On a busy machine a second process would only share a CPU, for 4-5 s more CPU
    time; the load average would also count the install that has just run."""
    n = os.cpu_count() or 1
    try:
        idle0, total0 = _cpu_times()
        time.sleep(window)
        idle1, total1 = _cpu_times()
    except (OSError, ValueError, IndexError):
        return n
    if total1 <= total0:
        return n
    return max(1, min(n, round(n * (idle1 - idle0) / (total1 - total0))))


def ensure(jobs: int | None = None, modules: Sequence[str] | None = None) -> float:
    """Compile the loops missing from the disk cache (``modules``: those of :func:`missing`)
    in up to ``jobs`` processes (``None``: :func:`free_cpus`), this one included; returns
    the time it took [s]. A helper process that fails only costs time: whatever it left
    out compiles on first call."""
    t0 = time.perf_counter()
    todo = missing() if modules is None else list(modules)
    if not todo:
        return 0.0
    groups = share(todo, jobs or free_cpus())
    root = str(Path(__file__).resolve().parent.parent)  # the same splineplan in the helpers
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(
        p for p in (root, os.environ.get("PYTHONPATH")) if p))
    helpers: list[tuple[list[str], subprocess.Popen[str]]] = []
    for group in groups[1:]:
        try:
            helpers.append((group, subprocess.Popen(
                [sys.executable, "-m", "splineplan.precompile", "--here", *group], env=env,
                stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)))
        except OSError as exc:
            log.warning("could not start a process to compile %s: %s", group, exc)
    compile_here(groups[0])
    for group, proc in helpers:
        _, err = proc.communicate()
        if proc.returncode:
            last = err.strip().splitlines()[-1] if err.strip() else ""
            log.warning("compiling %s failed (they compile on first call): %s", group, last)
    took = time.perf_counter() - t0
    log.info("compiled %s in %d processes in %.1f s", todo, len(groups), took)
    return took


def main(argv: Sequence[str] | None = None) -> int:
    """``python -m splineplan.precompile [--jobs N] [--here MODULE ...]``."""
    parser = argparse.ArgumentParser(prog="python -m splineplan.precompile",
                                     description=__doc__.splitlines()[0])
    parser.add_argument("--jobs", type=int, default=None,
                        help="processes to compile in (one per idle CPU)")
    parser.add_argument("--here", nargs="+", metavar="MODULE", choices=sorted(SIGNATURES),
                        help="compile these modules' loops in this process only")
    args = parser.parse_args(argv)
    if args.here:
        compile_here(args.here)
    else:
        took = ensure(args.jobs)
        print(f"compiled in {took:.1f} s" if took else "already compiled")
    return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
