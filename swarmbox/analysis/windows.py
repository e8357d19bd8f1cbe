"""How much of a run the analyzer works on at once: its window.

The stages that walk the run in pieces (the diagnosis scan in chunks of grid points, the message
flow matched per send-time window, the clock statistics read in Parquet batches) take their size from
here. A piece is a span of simulated time, so what they hold at once does not grow with the flight.
Their results do not depend on it: the same tables come out of one window or of many
(``tests/analysis/test_memory_windows.py``). ``SWARMBOX_ANALYSIS_WINDOW_S`` overrides the default, for
tests that force many windows on a short run, or to trade memory for fewer passes.
"""

from __future__ import annotations

import math
import os

#: Environment variable overriding :data:`DEFAULT_WINDOW_S` (seconds of simulated time, > 0).
ENV = "SWARMBOX_ANALYSIS_WINDOW_S"
#: 10 s: at 1,000 drones about 1.6 M message rows (~60 MB as the windows are kept), matched with what
#: the latency bound (2 s) reaches of the windows either side.
DEFAULT_WINDOW_S = 10.0
#: Rows of the doubled message flow (each message once for its sender, once for its destination) a
#: per-agent metric groups at once: a few agents at a time beyond that.
TOUCH_ROWS = 1 << 21
#: Rows per Parquet batch when a table is read in pieces.
BATCH_ROWS = 1 << 16


def window_s() -> float:
    """The analysis window in seconds: ``$SWARMBOX_ANALYSIS_WINDOW_S`` when set, else the default."""
    raw = os.environ.get(ENV)
    if raw is None or not raw.strip():
        return DEFAULT_WINDOW_S
    try:
        value = float(raw)
    except ValueError as exc:
        raise ValueError(f"{ENV}={raw!r} is not a number of seconds") from exc
    if not value > 0 or math.isnan(value):
        raise ValueError(f"{ENV}={raw!r}: the window must be > 0 s (inf: one window)")
    return value


def points(step_s: float, window: float | None = None) -> int:
    """Grid points of ``step_s`` in a window (at least one; a huge count for an infinite window)."""
    window = window_s() if window is None else window
    if math.isinf(window):
        return 1 << 62
    return max(1, int(window / step_s))
