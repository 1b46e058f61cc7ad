"""Signal handling shared by the commands that write partial outputs when interrupted."""

from __future__ import annotations

import contextlib
import signal
import threading
from collections.abc import Iterator
from typing import Any


@contextlib.contextmanager
def _sigint_handler(handler: Any) -> Iterator[bool]:
    """SIGINT handled by ``handler`` while the block runs, the old handler back after it;
    yields whether it could be set (only the main thread can change signal handlers)."""
    if threading.current_thread() is not threading.main_thread():
        yield False
        return
    try:
        old = signal.signal(signal.SIGINT, handler)
    except (ValueError, OSError):  # not possible here (an embedded interpreter)
        yield False
        return
    try:
        yield True
    finally:
        signal.signal(signal.SIGINT, old)


@contextlib.contextmanager
def sigint_ignored() -> Iterator[None]:
    """Ignore SIGINT (Ctrl-C) while the block runs: a second Ctrl-C while the outputs of an
    interrupted run are written would leave them half written. Only the main thread can
    change signal handlers; elsewhere this does nothing."""
    with _sigint_handler(signal.SIG_IGN):
        yield


class _Deferred:
    """Whether a Ctrl-C came while :func:`sigint_deferred` held it back."""

    def __init__(self) -> None:
        self.requested = False

    def check(self) -> None:
        """Raise :class:`KeyboardInterrupt` if a Ctrl-C came (a safe point to stop at)."""
        if self.requested:
            raise KeyboardInterrupt


@contextlib.contextmanager
def sigint_deferred() -> Iterator[_Deferred]:
    """Hold a Ctrl-C back until the block calls ``check()`` at a safe point; a second one
    raises at once.

    A simulation stops between two whole steps, so that its record ends on a step the
    loop has seen through. Only the main thread can change signal handlers; elsewhere, or
    where SIGINT is ignored (a process started in a shell's background), the block runs
    with the handling it had and ``check()`` does nothing.
    """
    state = _Deferred()
    if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
        yield state
        return

    def handler(signum: int, frame: object) -> None:
        if state.requested:  # the second Ctrl-C: stop now
            raise KeyboardInterrupt
        state.requested = True

    with _sigint_handler(handler):
        yield state

