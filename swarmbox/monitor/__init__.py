"""Live monitor: a terminal dashboard of a running swarm, fed by what the ground node receives.

``run.monitor``: ``auto`` (default) shows it for real-time backends (PX4, MAVLink vehicles) when
stderr is a terminal and the run is not part of a sweep; ``on`` always; ``off`` never.
``run.monitor_hz`` sets the refresh rate. ``run.rerun`` (a Rerun viewer's URL or an ``.rrd`` path;
a relative path is inside the run directory) also streams the run live to Rerun. See docs/monitor.md.

This module decides without importing rich; the dashboard itself lives in :mod:`.live`.
"""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Any

from swarmbox.monitor.targets import rerun_target

MODES = ("auto", "on", "off")
#: ``run.rerun`` values that name a viewer to connect to rather than a file to write.


def wanted(mode: str, *, realtime: bool, multirun: bool, tty: bool | None = None) -> bool:
    """Whether a run shows the dashboard."""
    if mode not in MODES:
        raise ValueError(f"run.monitor must be one of {', '.join(MODES)}, got {mode!r}")
    if mode != "auto":
        return mode == "on"
    tty = sys.stderr.isatty() if tty is None else tty
    return realtime and tty and not multirun



def create(title: str, rate_hz: float, *, dashboard: bool = True, rerun: str | None = None,
           run_dir: Path | None = None) -> Any:
    """The run's monitor: the dashboard, a live Rerun stream (``run.rerun``), or both.
    ``run_dir``: where a relative ``run.rerun`` path goes (the current directory without one)."""
    from swarmbox.monitor.live import Monitor

    if rerun and run_dir is not None:
        rerun = rerun_target(rerun, run_dir)
    return Monitor(title, rate_hz=rate_hz, dashboard=dashboard, rerun=rerun)
