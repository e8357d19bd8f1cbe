"""A wall-clock limit on every call of a user hook: a hook that never returns fails the run, named.

Nothing is added to a hook call. A daemon thread looks at the main thread's stack a few times per
limit (``sys._current_frames``) for the innermost frame of a dispatch method (``run_stage``,
``enter_stage``, ``on_task``, ``on_report``, ``successors``) running on a guarded algorithm. When
the same frame is still there ``limit_s`` after it was first seen, the thread sends SIGALRM to the
main thread, whose handler raises :class:`HookTimeout` inside the hook — if that frame is still on
its stack. A signal interrupts ``sleep`` and pure-Python loops alike. The exception is a
BaseException, so a hook's own ``except Exception`` cannot swallow it. Signals reach only the main
thread: elsewhere the watchdog stays off. A hook is stopped between ``limit_s`` and ``limit_s`` plus
two polls (a quarter of the limit, at most 0.25 s each) after it started.
"""

from __future__ import annotations

import signal
import sys
import threading
import time
from types import FrameType
from typing import Any

from swarmbox.core.stages import Stage

HOOKS = frozenset({"run_stage", "enter_stage", "on_task", "on_report", "successors"})
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
        self._who: dict[int, str] = {}   # id(algorithm) -> "drone 3" / "ground"
        self._guarded: list[Any] = []    # keeps every id above taken by its algorithm
        self._overdue: FrameType | None = None   # the hook frame the alarm is about
        self._message = ""
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._old_handler: Any = None
        self._main_id = threading.main_thread().ident

    @property
    def active(self) -> bool:
        return self._thread is not None

    def guard(self, algorithm: Any, who: str) -> None:
        """Watch the hooks of ``algorithm``, naming it ``who`` in the error."""
        self._who[id(algorithm)] = who
        self._guarded.append(algorithm)

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
        self._overdue = None

    def running_hook(self, frame: FrameType | None) -> tuple[FrameType, str] | None:
        """The innermost guarded hook call on the stack ending in ``frame``, with its error text."""
        while frame is not None:
            code = frame.f_code
            if code.co_name in HOOKS and code.co_argcount:
                local = frame.f_locals
                who = self._who.get(id(local.get(code.co_varnames[0])))
                if who is not None:
                    args = tuple(local.get(name) for name in code.co_varnames[1:code.co_argcount])
                    return frame, (f"{who}: {hook_label(code.co_name, args)} did not return within "
                                   f"{self.limit_s:g} s (run.hook_timeout_s)")
            frame = frame.f_back
        return None

    def _watch(self) -> None:
        poll = min(0.25, self.limit_s / 4)
        seen: FrameType | None = None
        since = 0.0
        while not self._stop.wait(poll):
            hook = self.running_hook(sys._current_frames().get(self._main_id))
            if hook is None or hook[0] is not seen:   # holding `seen` keeps its identity unique
                seen, since = (None, 0.0) if hook is None else (hook[0], time.monotonic())
                continue
            if time.monotonic() - since >= self.limit_s:
                self._overdue, self._message = hook
                signal.pthread_kill(self._main_id, signal.SIGALRM)
                self._stop.wait(self.limit_s)   # one alarm per limit: the raise unwinds the hook
                seen = None

    def _on_alarm(self, _signum: int, frame: FrameType | None) -> None:
        overdue, self._overdue = self._overdue, None
        while frame is not None and frame is not overdue:
            frame = frame.f_back
        if frame is None:
            return   # the hook returned in the meantime
        raise HookTimeout(self._message)
