"""Pacing for wall-clock tests (MAVLink vehicles in their own processes): as fast as the machine allows.

A real-time test that flies at speed 4 on an idle machine cannot keep that pace when every core is
shared with a dozen other processes: vehicles fall behind their own clocks and links time out. So
these tests measure the machine first and choose the speed: the target speed times the share of a
core each runnable process can get now (cores / (1-minute load + 1)), rounded down to a half, at
least 0.5. Every check stated in simulated time holds at any speed; checks on rates scale with it.
"""

from __future__ import annotations

import math
import os


def cpu_share() -> float:
    """Share of the machine a new runnable process gets now (1.0: a free core)."""
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1
    return min(1.0, cores / (os.getloadavg()[0] + 1.0))


def speed(target: float) -> float:
    """The simulation speed factor to run a wall-clock test at (``target`` on a free machine)."""
    return max(0.5, math.floor(target * cpu_share() * 2) / 2)
