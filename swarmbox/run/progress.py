"""Progress for long work: a sweep's runs (done / failed / ETA) and one long run's simulated time.

Both show a rich progress bar on a terminal and print plain lines otherwise (logs, CI, pipes), so a
180-run study or a 900 s mission is never silent. The sweep monitor reads the run directories'
``run.json`` files from a background thread, so it works the same with every launcher (in-process,
joblib, Ray, Submitit) and costs the runs nothing.
"""

from __future__ import annotations

import json
import math
import sys
import threading
import time
from pathlib import Path
from typing import Any

from hydra.experimental.callback import Callback
from omegaconf import DictConfig, OmegaConf

PLAIN_EVERY_S = 30.0   # without a terminal: a line on every change, and at least this often


def _clock(seconds: float) -> str:
    if not math.isfinite(seconds):
        return "?"
    s = int(round(seconds))
    return f"{s // 3600}:{s // 60 % 60:02d}:{s % 60:02d}"


def count_jobs(config: DictConfig) -> int | None:
    """Number of jobs of a basic-sweeper multirun (preset ``hydra.sweeper.params`` + command line)."""
    from hydra.core.override_parser.overrides_parser import OverridesParser

    try:
        params = OmegaConf.select(config, "hydra.sweeper.params") or {}
        args = [f"{k}={v}" for k, v in params.items()] + list(config.hydra.overrides.task)
        sizes: dict[str, int] = {}
        for o in OverridesParser.create().parse_overrides(args):
            key = o.get_key_element()
            sizes[key] = len(list(o.sweep_string_iterator())) if o.is_sweep_override() else 1
        return math.prod(sizes.values())
    except Exception:  # noqa: BLE001 - another sweeper's syntax: progress without a total
        return None


class SweepMonitor:
    """Counts the finished runs under a sweep directory and reports them with an ETA."""

    def __init__(self, sweep_dir: Path, total: int | None, interval_s: float = 1.0, stream=None) -> None:
        self.sweep_dir, self.total, self.interval_s = sweep_dir, total, interval_s
        self.stream = stream or sys.stderr
        self.before = self._finished()           # already there: a resumed sweep skips these
        self.seen: dict[Path, str] = {}
        self.started = time.perf_counter()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._loop, name="sweep-progress", daemon=True)
        self._bar = None
        self._last_line, self._last_time = "", 0.0

    def _finished(self) -> dict[Path, float]:
        out = {}
        for path in self.sweep_dir.glob("*/run.json"):
            try:
                out[path] = path.stat().st_mtime
            except OSError:
                pass
        return out

    def poll(self) -> dict[str, Any]:
        """Read new ``run.json`` files; the counts so far."""
        for path, mtime in self._finished().items():
            if path in self.seen or self.before.get(path) == mtime:
                continue
            try:
                self.seen[path] = json.loads(path.read_text()).get("status", "?")
            except (OSError, ValueError):
                continue   # written atomically, so unreadable means not there yet
        done = len(self.seen)
        failed = sum(s == "failed" for s in self.seen.values())
        skipped = sum(1 for p in self.before if p not in self.seen)
        elapsed = time.perf_counter() - self.started
        todo = None if self.total is None else max(self.total - skipped, 0)
        eta = (elapsed / done * (todo - done)) if (todo is not None and done) else math.nan
        return {"done": done, "failed": failed, "skipped": skipped, "todo": todo, "elapsed": elapsed,
                "eta": eta}

    def line(self, c: dict[str, Any]) -> str:
        of = f"/{c['todo']}" if c["todo"] is not None else ""
        skipped = f", {c['skipped']} skipped (finished before)" if c["skipped"] else ""
        return (f"sweep {self.sweep_dir}: {c['done']}{of} runs done, {c['failed']} failed{skipped}; "
                f"elapsed {_clock(c['elapsed'])}, ETA {_clock(c['eta'])}")

    def _show(self, final: bool = False) -> None:
        c = self.poll()
        if self._bar is not None:
            progress, task = self._bar
            progress.update(task, completed=c["done"], total=c["todo"],
                            description=f"sweep: {c['failed']} failed, ETA {_clock(c['eta'])}")
            return
        text = self.line(c)
        now = time.perf_counter()
        changed = text.split(";")[0] != self._last_line.split(";")[0]
        if final or changed or now - self._last_time > PLAIN_EVERY_S:
            print(text, file=self.stream, flush=True)
            self._last_line, self._last_time = text, now

    def _loop(self) -> None:
        while not self._stop.wait(self.interval_s):
            self._show()

    def start(self) -> None:
        if getattr(self.stream, "isatty", lambda: False)():
            from rich.console import Console
            from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

            progress = Progress(TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(),
                                TimeElapsedColumn(), console=Console(file=self.stream), transient=False)
            progress.start()
            self._bar = (progress, progress.add_task("sweep", total=None))
        else:   # the state at the start is not news: the first line comes with the first change
            self._last_line, self._last_time = self.line(self.poll()), time.perf_counter()
        self._thread.start()

    def stop(self) -> None:
        self._stop.set()
        self._thread.join(timeout=5)
        self._show(final=True)
        if self._bar is not None:
            self._bar[0].stop()
            self._bar = None
            print(self.line(self.poll()), file=self.stream, flush=True)


class SweepProgress(Callback):
    """Hydra callback: runs done / failed / ETA while a multirun flies (see :class:`SweepMonitor`)."""

    def __init__(self, interval_s: float = 1.0) -> None:
        self.interval_s = interval_s
        self.monitor: SweepMonitor | None = None

    def __getstate__(self) -> dict[str, Any]:
        # Remote launchers (Ray) pickle Hydra's callbacks along with each job; the monitor (a
        # thread and a stream) stays with the process that started the sweep.
        return {"interval_s": self.interval_s, "monitor": None}

    def on_multirun_start(self, config: DictConfig, **kwargs: Any) -> None:
        sweep_dir = Path(str(config.hydra.sweep.dir))
        sweep_dir.mkdir(parents=True, exist_ok=True)
        self.monitor = SweepMonitor(sweep_dir, count_jobs(config), self.interval_s)
        self.monitor.start()

    def on_multirun_end(self, config: DictConfig, **kwargs: Any) -> None:
        if self.monitor is not None:
            self.monitor.stop()
            self.monitor = None


class RunProgress:
    """Simulated time of one long run, reported at most every ``every_s`` of wall time.

    Called from the tick hook, so the common case is one ``perf_counter`` call; the bar (on a
    terminal) or the line (otherwise) shows simulated time against the mission's time limit.
    """

    def __init__(self, label: str, limit_s: float, every_s: float = 2.0, stream=None) -> None:
        self.label, self.limit_s, self.every_s = label, limit_s, every_s
        self.stream = stream or sys.stderr
        self.started = self.last = time.perf_counter()
        self._bar = None

    def __call__(self, swarm: Any) -> None:
        now = time.perf_counter()
        if now - self.last < self.every_s:
            return
        self.last = now
        g = swarm.ground
        _, alive = g.head_count()
        t = swarm.time.t_s
        text = (f"[{self.label}] {g.stage.name:<11} {alive}/{g.mission.swarm_size} drones alive, "
                f"{t / max(now - self.started, 1e-9):.0f}x real time")
        if self._bar is None and getattr(self.stream, "isatty", lambda: False)():
            from rich.console import Console
            from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn

            progress = Progress(TextColumn("{task.description}"), BarColumn(),
                                TextColumn("t={task.completed:.0f}/{task.total:.0f} s (limit)"),
                                TimeElapsedColumn(), console=Console(file=self.stream), transient=True)
            progress.start()
            self._bar = (progress, progress.add_task(text, total=self.limit_s))
        if self._bar is not None:
            self._bar[0].update(self._bar[1], completed=t, description=text)
        else:
            print(f"{text}  t={t:7.1f} s of at most {self.limit_s:.0f} s", file=self.stream, flush=True)

    def close(self) -> None:
        if self._bar is not None:
            self._bar[0].stop()
            self._bar = None
