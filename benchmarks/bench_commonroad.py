"""CommonRoad benchmark: splineplan's solutions of public CommonRoad scenarios, certified by
commonroad-drivability-checker, against CommonRoad's reactive planner in the same process.

The scenarios (``benchmarks/data/commonroad_scenarios.tar.xz``, see the README beside it):
every scenario with static obstacles in the public CommonRoad route-planner repository's
history, and a seeded sample of the others there. Each is solved by

- splineplan (:func:`splineplan.commonroad.plan`, BMW 320i): one plan from the initial
  state to the goal; its time is the plan's (levels 1-3, the speed plan among the dynamic
  obstacles, the goal timing);
- the reactive planner (``commonroad-reactive-planner``, its default configuration but in
  one process, see :func:`_reactive`; the route planner's shortest reference path),
  replanning every third step as its own example script does, until the goal is reached,
  it finds no trajectory, the goal's last time step passes, or its planning time runs
  over ``--peer-budget``; its time per cycle is that of ``ReactivePlanner.plan``. A run
  that takes over :data:`PEER_SECONDS` of wall time counts as failed.

Both solutions are judged by the same checks (:func:`splineplan.commonroad.certify_solution`:
collisions with every obstacle at its time, the road boundary, ``trajectory_feasibility``
with the KS model, the goal reached, the start state).

``python -m benchmarks commonroad [--scenarios DIR] [--limit N] [--no-peer] [--json FILE]
[--speed-limits]``
"""

from __future__ import annotations

import argparse
import contextlib
import json
import logging
import os
import random
import signal
import statistics
import tarfile
import tempfile
import time
import warnings
from collections.abc import Iterator
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parent
ARCHIVE = ROOT / "data" / "commonroad_scenarios.tar.xz"
CHECKS = ("collision_free", "road_compliant", "feasible", "goal_reached", "starts_right")
#: Time [s] a check may take: the drivability checker's road boundary never finishes on
#: one scenario (ZAM_Tutorial-1_1_T-1); a check stopped there counts as failed.
CHECK_SECONDS = 60
#: Wall time [s] the peer's run may take: on ZAM_Tutorial-1_1_T-1 (no goal state) it did
#: not finish in 15 minutes; a run stopped there counts as failed.
PEER_SECONDS = 300


@contextlib.contextmanager
def _time_limit(seconds: int) -> Iterator[None]:
    """Raise TimeoutError inside the block after ``seconds`` (main thread, Unix)."""
    def stop(signum: int, frame: Any) -> None:
        raise TimeoutError(f"stopped after {seconds} s")

    old = signal.signal(signal.SIGALRM, stop)
    signal.alarm(seconds)
    try:
        yield
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, old)


def _splineplan(path: Path, speed_limits: bool = False) -> dict[str, Any]:
    from splineplan import commonroad as cr
    from splineplan.errors import SplineplanError

    problem = cr.read(path)
    row: dict[str, Any] = {"scenario": path.stem, "static": len(problem.scenario.static_obstacles),
                           "dynamic": len(problem.scenario.dynamic_obstacles),
                           "has_goal": bool(problem.planning_problem.goal.state_list)}
    t0 = time.perf_counter()
    c0 = time.process_time()
    try:
        res = cr.plan(problem, speed_limits=speed_limits)
        cpu = time.process_time() - c0
    except SplineplanError as err:
        row.update(error=str(err), plan_ms=1e3 * (time.perf_counter() - t0), passed=False)
        return row
    with _time_limit(CHECK_SECONDS):
        cert = cr.certify(res)
    row.update({k: getattr(cert, k) for k in CHECKS}, passed=cert.passed,
               plan_ms=1e3 * res.plan_seconds, cpu_ms=1e3 * cpu, error="")
    return row


def _reactive(path: Path, budget: float) -> dict[str, Any]:
    """The reactive planner's run (see the module docstring), stopped after ``budget``
    seconds of its planning (then judged as far as it got), or as failed after
    :data:`PEER_SECONDS` of wall time."""
    from commonroad.common.file_reader import CommonRoadFileReader

    from splineplan.commonroad import certify_solution

    scenario, pps = CommonRoadFileReader(str(path)).open()
    pp = pps.planning_problem_dict[sorted(pps.planning_problem_dict)[0]]
    row: dict[str, Any] = {"scenario": path.stem, "has_goal": bool(pp.goal.state_list)}
    cycles: list[float] = []
    t_start = time.perf_counter()
    try:
        with _time_limit(PEER_SECONDS):
            sol = _reactive_solution(scenario, pps, pp, budget, cycles)
        with _time_limit(CHECK_SECONDS):
            cert = certify_solution(scenario, pp, sol)
    except Exception as err:  # the peer's own failures are part of the result
        row.update(error=f"{type(err).__name__}: {err}"[:200], passed=False,
                   cycle_ms=1e3 * statistics.median(cycles) if cycles else float("nan"),
                   total_ms=1e3 * (time.perf_counter() - t_start))
        return row
    row.update({k: getattr(cert, k) for k in CHECKS}, passed=cert.passed, error="",
               cycle_ms=1e3 * statistics.median(cycles) if cycles else float("nan"),
               cycles=len(cycles), plan_ms=1e3 * sum(cycles),
               total_ms=1e3 * (time.perf_counter() - t_start))
    return row


def _reactive_solution(scenario: Any, pps: Any, pp: Any, budget: float,
                       cycles: list[float]) -> Any:
    """The reactive planner's solution of planning problem ``pp``, each cycle's planning
    time [s] appended to ``cycles`` (see :func:`_reactive`)."""
    from commonroad_rp.reactive_planner import ReactivePlanner
    from commonroad_rp.utility.config import ReactivePlannerConfiguration
    from commonroad_rp.utility.evaluation import (
        create_full_solution_trajectory,
        create_planning_problem_solution,
    )
    from commonroad_rp.utility.utils_coordinate_system import (
        create_coordinate_system,
        create_initial_ref_path,
    )

    config = ReactivePlannerConfiguration()
    # one process: with its default worker processes, a worker that raises (a sample
    # outside its curvilinear frame) leaves the planner waiting for it forever, and two
    # cores shared with six workers measure nothing
    config.debug.multiproc = False
    config.update(scenario=scenario, planning_problem=pp)
    config.planning_problem_set = pps
    planner = ReactivePlanner(config)
    # its coordinate system made with the clcs package's default settings (the
    # planner's own call passes none, which commonroad-clcs 2025.2 refuses)
    planner.set_reference_path(coordinate_system=create_coordinate_system(
        create_initial_ref_path(scenario.lanelet_network, pp)))
    planner.record_state_and_input(planner.x_0)
    last = max(int(getattr(s.time_step, "end", 200)) for s in pp.goal.state_list)
    optimal = None
    while (not planner.goal_reached() and len(planner.record_state_list) <= last + 1
           and sum(cycles) < budget):
        count = len(planner.record_state_list) - 1
        k = count % config.planning.replanning_frequency
        if k == 0:
            planner.set_desired_velocity(current_speed=planner.x_0.velocity)
            t0 = time.perf_counter()
            optimal = planner.plan()
            cycles.append(time.perf_counter() - t0)
            if not optimal:
                break
        assert optimal is not None
        planner.record_state_and_input(optimal[0].state_list[1 + k])
        planner.reset(initial_state_cart=planner.record_state_list[-1],
                      initial_state_curv=(optimal[1][1 + k], optimal[2][1 + k]),
                      collision_checker=planner.collision_checker,
                      coordinate_system=planner.coordinate_system)
    traj = create_full_solution_trajectory(config, planner.record_state_list)
    return create_planning_problem_solution(config, traj, scenario, pp)


def _scenarios(folder: Path | None, tmp: Path) -> list[Path]:
    if folder is not None:
        return sorted(folder.glob("*.xml"))
    with tarfile.open(ARCHIVE, "r:xz") as tar:
        # tarfile's extraction filters came with Python 3.11.4
        safe = {"filter": "data"} if hasattr(tarfile, "data_filter") else {}
        tar.extractall(tmp, **safe)  # type: ignore[arg-type]
    return sorted(tmp.glob("*.xml"))


def _summary(name: str, rows: list[dict[str, Any]], time_key: str) -> str:
    n = len(rows)
    passed = sum(bool(r.get("passed")) for r in rows)
    parts = [f"{name}: all checks {passed}/{n} ({100.0 * passed / max(n, 1):.0f} %)"]
    goals = [r for r in rows if r.get("has_goal", True)]
    if len(goals) < n:  # a planning problem without a goal state: no solution reaches it
        ok = sum(bool(r.get("passed")) for r in goals)
        parts.append(f"{ok}/{len(goals)} ({100.0 * ok / max(len(goals), 1):.0f} %) of those "
                     f"with a goal state ({n - len(goals)} without)")
    for k in CHECKS:
        parts.append(f"{k} {sum(bool(r.get(k)) for r in rows)}")
    times = [r[time_key] for r in rows if r.get(time_key) == r.get(time_key)
             and time_key in r]
    if times:
        parts.append(f"median {time_key} {statistics.median(times):.1f}")
    errors = sum(bool(r.get("error")) for r in rows)
    parts.append(f"errors {errors}")
    return ", ".join(parts)


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(prog="python -m benchmarks commonroad")
    ap.add_argument("--scenarios", type=Path, help="folder of scenario files (default: the "
                    "bundled archive)")
    ap.add_argument("--limit", type=int, default=None, help="only the first N scenarios")
    ap.add_argument("--sample", type=int, default=None, metavar="N",
                    help="only N scenarios drawn with random.Random(SEED)")
    ap.add_argument("--seed", type=int, default=0, help="seed of --sample (0)")
    ap.add_argument("--no-peer", action="store_true", help="skip the reactive planner")
    ap.add_argument("--only-peer", action="store_true", help="skip splineplan")
    ap.add_argument("--peer-budget", type=float, default=60.0, metavar="S",
                    help="planning time [s] after which a reactive planner run stops (60)")
    ap.add_argument("--json", type=Path, help="write every row to this file")
    ap.add_argument("--speed-limits", action="store_true",
                    help="splineplan keeps to the speed limits the traffic signs post")
    args = ap.parse_args(argv)
    os.environ.setdefault("PROTOCOL_BUFFERS_PYTHON_IMPLEMENTATION", "python")
    warnings.filterwarnings("ignore")
    logging.disable(logging.WARNING)
    from splineplan.planner import warm_up

    warm_up()
    peer = not args.no_peer
    if peer:
        try:
            import commonroad_rp  # noqa: F401
        except ImportError:
            print("the reactive planner is not installed (pip install "
                  "commonroad-reactive-planner): splineplan only")
            peer = False
    ours: list[dict[str, Any]] = []
    theirs: list[dict[str, Any]] = []
    with tempfile.TemporaryDirectory() as tmp:
        paths = _scenarios(args.scenarios, Path(tmp))[:args.limit]
        if args.sample is not None:
            paths = sorted(random.Random(args.seed).sample(paths, min(args.sample,
                                                                      len(paths))))
        for path in paths:
            line = f"{path.stem:<28}"
            if not args.only_peer:
                row = _splineplan(path, args.speed_limits)
                ours.append(row)
                line += (f" splineplan {'PASS' if row['passed'] else 'fail'} "
                         f"{row['plan_ms']:7.1f} ms "
                         + (" ".join(k for k in CHECKS if not row.get(k, True)) or "")
                         + (f" {row['error'][:80]}" if row.get("error") else ""))
            if peer:
                rp = _reactive(path, args.peer_budget)
                theirs.append(rp)
                line += (f" | reactive {'PASS' if rp['passed'] else 'fail'} "
                         f"{rp.get('cycle_ms', float('nan')):7.1f} ms/cycle "
                         + (" ".join(k for k in CHECKS if not rp.get(k, True)) or "")
                         + (f" {rp['error'][:60]}" if rp.get("error") else ""))
            print(line, flush=True)
    if ours:
        print(_summary("splineplan", ours, "plan_ms"))
        cpu = [r["cpu_ms"] for r in ours if "cpu_ms" in r]
        if cpu:
            print(f"splineplan: median CPU time of a plan {statistics.median(cpu):.1f} ms "
                  "(with reading the vehicle's parameters, without the state conversion)")
    if peer:
        print(_summary("reactive planner", theirs, "cycle_ms"))
        totals = [r["plan_ms"] for r in theirs if "plan_ms" in r]
        if totals:
            print(f"reactive planner: median planning time per scenario (its cycles summed) "
                  f"{statistics.median(totals):.0f} ms")
    if args.json:
        args.json.write_text(json.dumps({"splineplan": ours, "reactive": theirs}, indent=1,
                                        default=str))


if __name__ == "__main__":
    main()
