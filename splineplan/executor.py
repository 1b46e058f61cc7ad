"""Runs of a suite, each in a fresh Python process, on this machine or on a Ray cluster.

libsumo holds one simulation per process, so every run (a bench case with one driver, a
point of a penetration sweep) runs in a process of its own:
``python -m splineplan.executor TASK.json``. A task is a JSON-able dict with ``runner`` (the
module whose ``run_task(task)`` makes the run's row and whose ``failed_row(task, message)``
stands in for a run that could not make one) and ``run_dir`` (where the process writes
``row.json``). Two executors hand the runs out, with one behaviour: a local pool of threads
that each start such processes, or a Ray cluster (its nodes must have splineplan installed
and see the run folders, as on one machine or a shared file system).

Ctrl-C stops a suite at once: the runs not started are cancelled, those in hand are sent
SIGINT and write their partial records (killed after :data:`STOP_GRACE` seconds), and the
rows that finished are returned.
"""

from __future__ import annotations

import contextlib
import importlib
import json
import logging
import os
import signal
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Generator, Mapping, Sequence
from concurrent.futures import ThreadPoolExecutor, as_completed, wait
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from splineplan._signals import sigint_ignored
from splineplan.errors import ParameterError

log = logging.getLogger(__name__)

#: Seconds a Ctrl-C gives the runs in hand to write their partial outputs before their
#: processes are killed.
STOP_GRACE = 5.0

#: Rows as the runs finish: (index of the task, row).
Rows = Generator[tuple[int, dict[str, Any]], None, None]


@dataclass(frozen=True)
class Ran:
    """Outcome of :func:`run_tasks`.

    Attributes
    ----------
    rows
        The row of each task, ``None`` where it did not finish (interrupted).
    executor
        ``local (N workers)`` or ``ray (ADDRESS)``.
    wall_time
        Wall time [s] of all runs.
    interrupted
        Whether Ctrl-C stopped them.
    """

    rows: list[dict[str, Any] | None]
    executor: str
    wall_time: float
    interrupted: bool = False


def run_tasks(tasks: list[dict[str, Any]], *, workers: int | None = None,
              address: str | None = None, label: Callable[[int], str] | None = None,
              progress: bool = True) -> Ran:
    """Run every task: on ``workers`` local processes at a time (default: the number of
    cores), or on the Ray cluster at ``address``. ``label(i)`` names task ``i`` in the
    progress bar (on stderr) and the log."""
    if workers is not None and workers < 1:
        raise ParameterError(f"workers must be >= 1, got {workers}")
    for t in tasks:  # a row of an earlier suite in the same folder is not one of this one
        Path(t["run_dir"], "row.json").unlink(missing_ok=True)
    name = label or (lambda i: Path(tasks[i]["run_dir"]).name)
    n_workers = workers or os.cpu_count() or 1
    executor = f"ray ({address})" if address else f"local ({n_workers} workers)"
    bar = _bar(len(tasks)) if progress else None
    running: dict[int, str] = {}
    lock = threading.Lock()

    def started(i: int) -> None:
        with lock:
            running[i] = name(i)
            if bar is not None:
                bar.set_postfix_str(", ".join(list(running.values())[:3]), refresh=True)

    rows: list[dict[str, Any] | None] = [None] * len(tasks)
    t0 = time.perf_counter()
    stream = on_ray(tasks, address) if address else local(tasks, n_workers, started)
    interrupted = False
    try:
        for i, row in stream:
            rows[i] = row
            with lock:
                running.pop(i, None)
                if bar is not None:
                    bar.set_description_str(f"done {name(i)}: {row.get('status')}")
                    bar.set_postfix_str(", ".join(list(running.values())[:3]))
                    bar.update(1)
            log.info("%s: %s %s", name(i), row.get("status"), row.get("error") or "")
    except KeyboardInterrupt:
        interrupted = True
    finally:
        if bar is not None:
            bar.close()
    if interrupted:
        with sigint_ignored():  # stop the runs in hand, take what has finished
            stream.close()
            _finished_since(tasks, rows)
    return Ran(rows, executor, time.perf_counter() - t0, interrupted)


class _Processes:
    """The worker processes a local pool has running, so that Ctrl-C can stop them."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._live: set[subprocess.Popen[str]] = set()
        self.stopping = False

    def start(self, cmd: list[str], **kwargs: Any) -> subprocess.Popen[str] | None:
        """Start a process, unless the pool is stopping (then ``None``)."""
        with self._lock:
            if self.stopping:
                return None
            proc = subprocess.Popen(cmd, **kwargs)
            self._live.add(proc)
            return proc

    def done(self, proc: subprocess.Popen[str]) -> None:
        with self._lock:
            self._live.discard(proc)

    def interrupt(self) -> None:
        """Start no more processes; Ctrl-C (SIGINT) to those running, so that each closes
        SUMO and writes the partial record of its run."""
        with self._lock:
            self.stopping = True
            live = list(self._live)
        for proc in live:
            with contextlib.suppress(OSError):  # already gone
                proc.send_signal(signal.SIGINT if os.name == "posix" else signal.SIGTERM)

    def kill(self) -> None:
        with self._lock:
            live = list(self._live)
        for proc in live:
            with contextlib.suppress(OSError):
                proc.kill()


def _runner(task: Mapping[str, Any]) -> Any:
    return importlib.import_module(str(task["runner"]))


def execute_task(task: Mapping[str, Any], *, timeout: float = 1800.0,
                 processes: _Processes | None = None) -> dict[str, Any]:
    """Run one task in a fresh Python process (``python -m splineplan.executor TASK.json``).

    The row comes back through ``row.json`` in the run folder; a process that dies without
    writing it gives a failed row with the end of its error output. This function is what
    every executor calls (a thread of the local pool, a Ray task). The process runs in
    a session of its own, so that a Ctrl-C in the terminal reaches only the suite, which
    stops its runs itself (``processes``, the local pool's).
    """
    run_dir = Path(task["run_dir"])
    run_dir.mkdir(parents=True, exist_ok=True)
    task_file = run_dir / "task.json"
    row_file = run_dir / "row.json"
    task_file.write_text(json.dumps(task, indent=1))
    row_file.unlink(missing_ok=True)
    env = dict(os.environ)
    pkg_root = str(Path(__file__).resolve().parent.parent)
    env["PYTHONPATH"] = os.pathsep.join(p for p in (pkg_root, env.get("PYTHONPATH")) if p)
    t0 = time.perf_counter()
    cmd = [sys.executable, "-m", "splineplan.executor", str(task_file)]
    kwargs: dict[str, Any] = {"stdout": subprocess.PIPE, "stderr": subprocess.PIPE,
                              "text": True, "env": env,
                              "start_new_session": os.name == "posix"}
    proc = (processes.start(cmd, **kwargs) if processes is not None
            else subprocess.Popen(cmd, **kwargs))
    if proc is None:  # the suite is stopping
        row: dict[str, Any] = _runner(task).failed_row(
            task, "not run: the suite was interrupted")
        return row
    try:
        stdout, stderr = proc.communicate(timeout=timeout)
        detail = (stderr or stdout or "").strip().splitlines()
        code: int | str = proc.returncode
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.communicate()
        detail, code = [f"the run took longer than {timeout:g} s"], "timeout"
    finally:
        if processes is not None:
            processes.done(proc)
    wall = time.perf_counter() - t0
    if row_file.is_file():
        row = json.loads(row_file.read_text())
    else:
        msg = detail[-1] if detail else ""
        row = _runner(task).failed_row(
            task, f"worker process ended ({code}) without a result: {msg}"[:500])
        row["wall_time"] = wall
    row["process_wall_time"] = wall
    return row


def main(argv: Sequence[str]) -> int:
    """The worker process: run one task file, write its ``row.json``."""
    # the suite stops its runs with SIGINT, also where it was itself started ignoring
    # Ctrl-C (in the background of a shell, under nohup): the run takes it whatever the
    # inherited disposition
    signal.signal(signal.SIGINT, signal.default_int_handler)
    task = json.loads(Path(argv[0]).read_text())
    try:
        row = _runner(task).run_task(task)
    except KeyboardInterrupt:  # the suite stops: the run wrote its partial record
        return 130
    Path(task["run_dir"], "row.json").write_text(json.dumps(row, indent=1, allow_nan=False))
    return 0


def local(tasks: list[dict[str, Any]], workers: int, started: Callable[[int], None]) -> Rows:
    """Rows as the runs finish, from a pool of threads that each run one process at a
    time. When the consumer stops (Ctrl-C), the runs not started are cancelled and those
    running get :data:`STOP_GRACE` seconds to write their partial records."""
    processes = _Processes()

    def job(i: int) -> dict[str, Any]:
        if not processes.stopping:
            started(i)
        return execute_task(tasks[i], processes=processes)

    pool = ThreadPoolExecutor(max_workers=workers)
    futures = {pool.submit(job, i): i for i in range(len(tasks))}
    try:
        for fut in as_completed(futures):
            yield futures[fut], fut.result()
    finally:
        with sigint_ignored():  # a second Ctrl-C must not leave the processes running
            processes.interrupt()
            pool.shutdown(wait=False, cancel_futures=True)
            # a cancelled future never counts as done for wait(): wait for the others
            _, late = wait([f for f in futures if not f.cancelled()], timeout=STOP_GRACE)
            if late:
                processes.kill()
                wait(late, timeout=STOP_GRACE)


def on_ray(tasks: list[dict[str, Any]], address: str) -> Rows:
    """Rows as the runs finish on a Ray cluster: each run is one task of one CPU that
    starts the run's process on its node. When the consumer stops (Ctrl-C), the tasks not
    finished are cancelled."""
    try:
        import ray
    except ImportError as err:
        raise ParameterError("--address needs Ray: pip install 'splineplan[ray]'") from err
    own = not ray.is_initialized()
    if own:
        check_reachable(address)
        try:
            ray.init(address=address, log_to_driver=False, logging_level=logging.WARNING,
                     configure_logging=False)
        except (ConnectionError, RuntimeError, ValueError) as err:
            raise ParameterError(f"cannot reach the Ray cluster at {address}: "
                                 f"{str(err).splitlines()[0] if str(err) else err}") from err
    remote = ray.remote(num_cpus=1, max_retries=0)(execute_task)
    pending: list[Any] = []
    try:
        refs = [remote.remote(t) for t in tasks]
        index = {ref: i for i, ref in enumerate(refs)}
        pending = list(refs)
        while pending:
            ready, pending = ray.wait(pending, num_returns=1)
            i = index[ready[0]]
            try:
                row = ray.get(ready[0])
            except ray.exceptions.RayError as err:  # the worker itself died: a failed row
                row = _runner(tasks[i]).failed_row(
                    tasks[i], f"Ray task failed: {type(err).__name__}: "
                              f"{str(err).splitlines()[0]}")
            yield i, row
    finally:
        with sigint_ignored():
            # stopped early (Ctrl-C): no more runs on the cluster. Only the tasks not yet
            # taken in: cancelling one whose result has arrived races with Ray's own
            # bookkeeping of it, and Ray then aborts this process
            for ref in pending:
                with contextlib.suppress(Exception):
                    ray.cancel(ref)
            if own:
                ray.shutdown()


def check_reachable(address: str) -> None:
    """A clear error at once where nothing listens at a ``HOST:PORT`` address (Ray itself
    retries for minutes)."""
    host, sep, port = address.removeprefix("ray://").rpartition(":")
    if not sep or not port.isdigit():
        return  # "auto", or an address Ray resolves itself
    try:
        socket.create_connection((host, int(port)), timeout=10.0).close()
    except OSError as err:
        raise ParameterError(f"cannot reach the Ray cluster at {address}: "
                             f"{err.strerror or err}") from err


def _finished_since(tasks: Sequence[Mapping[str, Any]], rows: list[dict[str, Any] | None]
                    ) -> None:
    """Fill in the rows of the runs that finished after the last row was taken in (a run
    writes ``row.json`` only when it has finished; an interrupted one writes none)."""
    for i, task in enumerate(tasks):
        row_file = Path(task["run_dir"]) / "row.json"
        if rows[i] is None and row_file.is_file():
            try:
                rows[i] = json.loads(row_file.read_text())
            except (OSError, ValueError):
                continue


def _bar(total: int) -> Any:
    from tqdm import tqdm

    return tqdm(total=total, unit="run", file=sys.stderr, dynamic_ncols=True)


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
