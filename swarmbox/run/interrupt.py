"""SIGINT / SIGTERM during runs: finish the current run's files, mark it interrupted, start no other.

The command line installs :func:`install`. While a run executes (:func:`armed`), the first signal
raises :class:`RunInterrupted` in the tick loop, so the runner records status ``interrupted`` with
the simulated time reached and closes every log file properly; further signals are ignored until
those files are written. A signal between runs only marks the request. Later jobs of a sweep see
:func:`requested` and do not start; the sweep summary lists them and the process exits ``128 +
signal`` (130 for Ctrl-C).
"""

from __future__ import annotations

import os
import signal
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any


class RunInterrupted(BaseException):
    """Raised in the main thread by SIGINT / SIGTERM (a BaseException: user code cannot swallow it)."""

    def __init__(self, signum: int) -> None:
        self.signum = signum
        super().__init__(f"interrupted by {signal.Signals(signum).name}")


_state: dict[str, Any] = {"signum": None, "armed": False, "installed": False}
ENV = "SWARMBOX_INTERRUPTED"


def _handler(signum: int, _frame: Any) -> None:
    if _state["signum"] is not None:
        return   # already stopping: let the interrupted run finish writing its files
    _state["signum"] = signum
    os.environ[ENV] = signal.Signals(signum).name   # read by the end-of-sweep analysis: skip it
    if _state["armed"]:
        _state["armed"] = False
        raise RunInterrupted(signum)


def install() -> None:
    """Route SIGINT and SIGTERM through this module (main thread only; elsewhere a no-op)."""
    if threading.current_thread() is not threading.main_thread():
        return
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, _handler)
    _state["installed"] = True


@contextmanager
def armed() -> Iterator[None]:
    """Within this block a first signal raises :class:`RunInterrupted` (when installed)."""
    if _state["signum"] is not None:
        raise RunInterrupted(_state["signum"])
    _state["armed"] = _state["installed"]
    try:
        yield
    finally:
        _state["armed"] = False


def release() -> None:
    """Once the interrupted run's files are written: a further signal stops the process at once."""
    if _state["installed"] and threading.current_thread() is threading.main_thread():
        signal.signal(signal.SIGINT, signal.default_int_handler)
        signal.signal(signal.SIGTERM, signal.SIG_DFL)


def requested() -> int | None:
    """The signal number received, or None."""
    return _state["signum"]


def exit_code() -> int:
    signum = _state["signum"]
    return 128 + int(signum) if signum is not None else 0


def signal_name() -> str:
    signum = _state["signum"]
    return signal.Signals(signum).name if signum is not None else ""
