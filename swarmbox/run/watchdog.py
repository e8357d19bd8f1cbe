"""A wall-clock limit on every call of a user hook: a hook that never returns fails the run, named.

The watchdog wraps the dispatch methods the core calls on an algorithm instance (``run_stage``,
``enter_stage``, ``on_task``, ``on_report``, ``successors``), so the core is unchanged. Each call
stamps its start; a daemon thread checks the stamp and, past ``limit_s``, sends SIGALRM to the main
thread, whose handler raises :class:`HookTimeout` inside the hook. A signal interrupts ``sleep``
and pure-Python loops alike. The exception is a BaseException, so a hook's own ``except Exception``
cannot swallow it. Signals reach only the main thread: elsewhere the watchdog stays off.

Cost per hook call: one closure call, two attribute stores and a ``time.monotonic()`` (no syscall).
"""

from __future__ import annotations

import signal
import threading
import time
from collections.abc import Callable
from typing import Any

from swarmbox.core.stages import Stage

HOOKS = ("run_stage", "enter_stage", "on_task", "on_report", "successors")
_LOOP = {Stage.PREPARATION: "prep_loop/prep_complete", Stage.EXECUTION: "exec_loop/exec_complete"}


class HookTimeout(BaseException):
    """A user hook ran longer than ``run.hook_timeout_s``."""


def hook_label(method: str, args: tuple) -> str:
    """The user-facing hook name of a dispatch call (as the core names it in errors)."""
    if method == "run_stage" and args and args[0] in _LOOP:
        return _LOOP[args[0]]
    if method == "enter_stage" and args and isinstance(args[0], Stage):
        return f"{args[0].name.lower()} entry"
    return method


class HookWatchdog:
    """Guards algorithm instances; :meth:`start` before the run, :meth:`stop` after it."""

    def __init__(self, limit_s: float) -> None:
        self.limit_s = float(limit_s)
        self._call: tuple[str, str, tuple] | None = None   # (who, method, args) of the running hook
        self._since = 0.0
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._old_handler: Any = None
        self._main_id = threading.main_thread().ident

    @property
    def active(self) -> bool:
        return self._thread is not None

    def guard(self, algorithm: Any, who: str) -> None:
        """Wrap ``algorithm``'s dispatch methods (instance attributes shadow the class's)."""
        for name in HOOKS:
            method = getattr(algorithm, name, None)
            if method is not None:
                setattr(algorithm, name, self._wrap(method, who, name))

    def _wrap(self, fn: Callable, who: str, name: str) -> Callable:
        def guarded(*args: Any) -> Any:
            outer = self._call
            self._call, self._since = (who, name, args), time.monotonic()
            try:
                return fn(*args)
            finally:
                self._call = outer
        return guarded

    def start(self) -> bool:
        """Arm the watchdog; returns False (and stays off) outside the main thread."""
        if threading.current_thread() is not threading.main_thread():
            return False
        self._old_handler = signal.signal(signal.SIGALRM, self._on_alarm)
        self._thread = threading.Thread(target=self._watch, name="hook-watchdog", daemon=True)
        self._thread.start()
        return True

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join()
            self._thread = None
            signal.signal(signal.SIGALRM, self._old_handler or signal.SIG_DFL)

    def _overdue(self) -> tuple[str, str, tuple] | None:
        call = self._call
        if call is not None and time.monotonic() - self._since >= self.limit_s:
            return call
        return None

    def _watch(self) -> None:
        poll = min(0.25, self.limit_s / 4)
        while not self._stop.wait(poll):
            if self._overdue() is not None:
                signal.pthread_kill(self._main_id, signal.SIGALRM)
                self._stop.wait(self.limit_s)   # one alarm per limit: the raise unwinds the hook

    def _on_alarm(self, _signum: int, _frame: Any) -> None:
        call = self._overdue()
        if call is None:
            return   # the hook returned in the meantime
        who, method, args = call
        self._call = None
        raise HookTimeout(f"{who}: {hook_label(method, args)} did not return within "
                          f"{self.limit_s:g} s (run.hook_timeout_s)")
