"""The dashboard thread: draws the latest snapshot a few times a second.

It runs beside the tick loop, reads only the feed (see :mod:`swarmbox.monitor.feed`), and measures
its own CPU time so the run can report what watching cost. A frame costs nothing when neither a new
snapshot nor an event arrived, and otherwise rewrites only the lines that changed
(:mod:`swarmbox.monitor.screen`); there is no other drawing thread (no rich ``Live`` auto-refresh).
"""

from __future__ import annotations

import sys
import threading
import time
from typing import Any

from rich.console import Console

from swarmbox.monitor.feed import GroundFeed, TappedRecorder, snapshot
from swarmbox.monitor.screen import Screen
from swarmbox.monitor.view import DashboardView

_LEVEL = {"error": "ERROR", "failsafe": "ERROR", "collision": "ERROR", "safety": "WARN", "fault": "WARN",
          "proximity": "WARN", "topology": "WARN"}


class Monitor:
    """Live terminal dashboard of one run: ``tap`` the recorder, ``start`` with the swarm, ``stop``."""

    def __init__(self, title: str, *, rate_hz: float = 2.0, window_s: float = 5.0,
                 console: Console | None = None, dashboard: bool = True, rerun: str | None = None) -> None:
        if rate_hz <= 0:
            raise ValueError(f"run.monitor_hz must be > 0, got {rate_hz}")
        self.feed = GroundFeed(rate_hz)
        self.view = DashboardView(title, window_s=window_s)
        self.console = console or Console(file=sys.stderr)
        self.dashboard = dashboard
        self._rerun_target = rerun
        self.stream = None
        self.error = ""
        self._rate_hz = rate_hz
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._screen: Screen | None = None
        self._size = (0, 0)
        self._cpu_s = 0.0
        self._frames = 0     # frames that drew something
        self._wakeups = 0
        self._started = (0.0, 0.0)

    def tap(self, recorder: Any) -> TappedRecorder:
        return TappedRecorder(recorder, self.feed)

    def start(self, swarm: Any) -> None:
        self.attach(swarm)
        self.watch(swarm.ground)

    def attach(self, swarm: Any) -> None:
        """The tick thread's half of :meth:`start`: the feed watches ``swarm``'s ground, and a swarm
        that buffers its rows (the fleet core) hands them over before each snapshot."""
        self.feed.hand_over = getattr(swarm, "hand_over_rows", None)
        swarm.ground.observer = self.feed

    def watch(self, ground: Any) -> None:
        """Start watching a ground node (the whole swarm's, or a ground in its own process)."""
        ground.observer = self.feed
        if self._rerun_target:
            from swarmbox.monitor.rerun_live import RerunStream
            self.stream = RerunStream(self._rerun_target, self.view.title.replace(" ", "_"))
        if self.dashboard:
            self._screen = Screen(self.console)
        self._started = (time.perf_counter(), time.process_time())
        self._thread = threading.Thread(target=self._loop, name="swarmbox-monitor", daemon=True)
        self._thread.start()

    def _loop(self) -> None:
        period = 1.0 / self._rate_hz
        try:
            while not self._stop.wait(period):
                self._frame()
        except Exception as exc:  # a broken screen must not touch the run: stop drawing, say why
            self.error = f"{type(exc).__name__}: {exc}"

    def _frame(self, final: bool = False) -> None:
        t0 = time.thread_time()
        self._wakeups += 1
        news = bool(self.feed.events)
        while self.feed.events:
            node_id, row = self.feed.events.popleft()
            line = self.view.add_event(node_id, row)
            if self.stream is not None:
                self.stream.event(row[0], line, _LEVEL.get(row[2], "INFO"))
        snap = self.feed.latest
        fresh = snap is not None and snap is not self.view.snap
        if snap is not None:
            self.view.update(snap, final)
        if self.stream is not None and fresh:
            self.stream.snapshot(snap, self.view)
        if self._screen is not None and self._screen.live:   # a plain stream gets the last frame only
            size = (self._screen.width(), self._screen.height())
            if fresh or news or size != self._size:
                self._size = size
                self.view.max_rows = max(4, size[1] - 16)
                self._frames += self._screen.draw(self.view.lines())
        self._cpu_s += time.thread_time() - t0

    def stop(self, swarm: Any | None = None, *, ground: Any | None = None) -> dict[str, float]:
        """Stop rendering (the last frame stays on screen); returns what the monitor cost."""
        self._stop.set()
        if self._thread is None:
            return {}   # never started: the run failed while being built
        self._thread.join()
        ground = swarm.ground if swarm is not None else ground
        if ground is not None:
            ground.observer = None
            self.feed.latest = snapshot(ground, time.perf_counter(), ticks_ago=1,   # the final state
                                        arrivals=self.feed.arrivals)
        if not self.error:
            self._frame(final=True)
        if self._screen is not None:
            t0 = time.thread_time()
            if not self._screen.live:
                self.view.max_rows = max(4, self._screen.height() - 16)
                self._screen.draw(self.view.lines())
                self._frames += 1
            self._screen.close()
            self._cpu_s += time.thread_time() - t0
        streamed = self.stream.close() if self.stream is not None else None
        wall = time.perf_counter() - self._started[0]
        cpu = time.process_time() - self._started[1]
        return {"frames": self._frames, "wakeups": self._wakeups, "rerun_frames": streamed,
                "error": self.error,
                "lines_written": self._screen.lines_written if self._screen else 0,
                "render_cpu_s": round(self._cpu_s, 4),
                "snapshot_s": round(self.feed.snapshot_cost_s, 4), "snapshots": self.feed.snapshots,
                "process_cpu_s": round(cpu, 3), "wall_s": round(wall, 3),
                "cpu_share": round((self._cpu_s + self.feed.snapshot_cost_s) / cpu, 5) if cpu > 0 else 0.0}

