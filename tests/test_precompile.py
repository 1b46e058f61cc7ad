"""The list of compiled loops and their signatures, and compiling them in helper processes."""

from __future__ import annotations

import importlib
import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

from numba.core.registry import CPUDispatcher

import splineplan
from splineplan import precompile

ROOT = Path(__file__).resolve().parent.parent
PACKAGE = Path(splineplan.__file__).parent


def _dispatchers() -> dict[tuple[str, str], CPUDispatcher]:
    """Every numba loop defined in the package's modules."""
    found = {}
    for path in sorted(PACKAGE.glob("*.py")):
        if "njit" not in path.read_text():
            continue
        module = importlib.import_module(f"splineplan.{path.stem}")
        for name, obj in vars(module).items():
            if isinstance(obj, CPUDispatcher) and obj.py_func.__module__ == module.__name__:
                found[(module.__name__, name)] = obj
    return found


def test_every_compiled_loop_is_listed() -> None:
    listed = {(m, name) for m, (_, loops) in precompile.SIGNATURES.items() for name in loops}
    # those inlined into their callers are never compiled on their own
    compiled = {key for key, d in _dispatchers().items()
                if d.targetoptions.get("inline") != "always"}
    assert compiled == listed


def test_listed_signatures_compile() -> None:
    # a signature that no longer fits its loop (arguments added, types changed) fails here
    precompile.compile_here(list(precompile.SIGNATURES))
    for module, (_, loops) in precompile.SIGNATURES.items():
        for name, sigs in loops.items():
            disp = getattr(importlib.import_module(module), name)
            assert set(sigs) <= set(disp.signatures), (module, name)


PLANNING = """
import numpy as np
from splineplan.corridor import Corridor
from splineplan.network import load_network
from splineplan.obstacles import Obstacles
from splineplan.pipeline import plan
from splineplan.planner import plan_corridor

result = plan(load_network("sumo_nets/city.net.xml"), "SWA0", "G1G2")
assert len(result.trajectory.x) > 100
road = Corridor.from_boundaries([[0.0, 3.5], [80.0, 3.5]], [[0.0, -3.5], [80.0, -3.5]])
free = plan_corridor(road, Obstacles.empty(), [1.0, -1.5], 0.0)
parked = Obstacles.from_boxes([[30.0, 1.5], [55.0, -1.5]], [0.0, 0.1], 4.5, 1.8)
dodge = plan_corridor(road, parked, [1.0, -1.5], 0.0)
assert free.trajectory.length > 70 and dodge.trajectory.length > 70
road.to_sl(np.array([[10.0, 0.5]]))  # one point: a contiguous column
"""


def _env(**extra: str) -> dict[str, str]:
    path = os.pathsep.join([str(PACKAGE.parent), os.environ.get("PYTHONPATH", "")])
    return dict(os.environ, PYTHONPATH=path, **extra)


def test_planning_calls_the_loops_with_the_listed_signatures_only() -> None:
    # a read-only, strided or differently typed argument would compile another
    # specialisation on first use, outside the parallel compile; in a process of its own,
    # so that other tests' direct calls of the loops do not count
    code = PLANNING + textwrap.dedent("""
        import sys
        from numba.core.registry import CPUDispatcher
        from splineplan import precompile
        listed = {(m, n): set(s) for m, (_, loops) in precompile.SIGNATURES.items()
                  for n, s in loops.items()}
        for m in [m for m in sys.modules if m.startswith("splineplan.")]:
            for n, d in vars(sys.modules[m]).items():
                if isinstance(d, CPUDispatcher) and d.py_func.__module__ == m:
                    for sig in set(d.signatures) - listed.get((m, n), set()):
                        print("unlisted", m, n, sig)
        """)
    out = subprocess.run([sys.executable, "-c", code], cwd=ROOT, env=_env(),
                         capture_output=True, text=True, check=True)
    assert "unlisted" not in out.stdout, out.stdout


def test_helper_process_fills_the_cache_for_this_one(tmp_path: Path) -> None:
    # a fresh cache: this process compiles one module, a helper the other; then neither
    # is missing, the others are
    env = _env(NUMBA_CACHE_DIR=str(tmp_path))
    code = ("import json; from splineplan import precompile as p; "
            "print(json.dumps([p.missing(), "
            "p.ensure(jobs=2, modules=['splineplan.obstacles', 'splineplan.network']) > 0, "
            "p.missing()]))")
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True,
                         check=True)
    before, compiled, after = json.loads(out.stdout.splitlines()[-1])
    assert set(before) == set(precompile.SIGNATURES)
    assert compiled
    assert set(after) == set(precompile.SIGNATURES) - {"splineplan.obstacles",
                                                       "splineplan.network"}
    assert list(tmp_path.rglob("*_swept_hulls*.nbi")) and list(tmp_path.rglob("*_paved*.nbi"))


def test_modules_are_shared_out_evenly_between_processes() -> None:
    weight = {m: w for m, (w, _) in precompile.SIGNATURES.items()}
    groups = precompile.share(list(weight), 2)
    assert sorted(m for g in groups for m in g) == sorted(weight)
    loads = [sum(weight[m] for m in g) for g in groups]
    assert loads[0] >= loads[1]  # the heaviest stays in the calling process
    assert loads[0] - loads[1] <= max(weight.values())  # largest first: within one module
    assert precompile.share(list(weight), 1) == [sorted(weight, key=lambda m: -weight[m])]
    assert 1 <= precompile.free_cpus(0.05) <= (os.cpu_count() or 1)
