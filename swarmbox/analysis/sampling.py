"""How often a run was stepped and logged: the time each logged row stands for.

A run steps at ``run.tick_hz`` (``tick_s`` in run.json) and writes one state row per drone every
``run.state_every_ticks`` ticks. Every time-integrated metric and the diagnosis grid use these, so the
same flight gives the same numbers whether it was logged at every tick or every 4th.

The logged ticks themselves are the first source (the log says what was written, whatever the
config asked for); the configuration is the fallback for a run with too few state rows to tell.
"""

from __future__ import annotations

import numpy as np

from swarmbox.analysis.load import RunData

#: The distributed runtime refuses frames older than ``run.net.max_age_s`` (2 s by default).
MAX_AGE_S = 2.0


def tick_s(run: RunData) -> float:
    """Length of one tick in s: run.json's ``tick_s``, else ``1 / run.tick_hz`` of the config, else the
    median unified time step between consecutive logged ticks (NaN when none of these exists)."""
    value = run.manifest.get("tick_s")
    if isinstance(value, int | float) and value > 0:
        return float(value)
    hz = (run.config.get("run") or {}).get("tick_hz") if isinstance(run.config, dict) else None
    if isinstance(hz, int | float) and hz > 0:
        return 1.0 / float(hz)
    state = run.tables["state"]
    if "t_u" not in state or len(state) < 2:
        return np.nan
    ticks = state.drop_duplicates("tick").sort_values("tick")
    steps = np.diff(ticks["t_u"].to_numpy(dtype="float64")) / np.maximum(np.diff(ticks["tick"]), 1)
    return float(np.median(steps)) if len(steps) else np.nan


def state_every_ticks(run: RunData) -> int:
    """Ticks between two state rows of a drone: the median step of the logged ticks, else the config's
    ``run.state_every_ticks``, else 1."""
    state = run.tables["state"]
    if len(state) >= 2:
        node, tick = state["node"].to_numpy(), state["tick"].to_numpy(dtype="float64")
        order = np.lexsort((tick, node))
        node, tick = node[order], tick[order]
        step = np.diff(tick)[node[1:] == node[:-1]]
        step = step[step > 0]
        if len(step):
            return max(1, int(round(float(np.median(step)))))
    every = (run.config.get("run") or {}).get("state_every_ticks") if isinstance(run.config, dict) else None
    return max(1, int(every)) if isinstance(every, int | float) else 1


def state_period_s(run: RunData) -> float:
    """Time one state row of a drone stands for, in s (tick length x ticks between rows)."""
    return tick_s(run) * state_every_ticks(run)


def _delays_s(node: object) -> list[float]:
    """Every configured one-way delay bound (latency + jitter, in s) in a config subtree."""
    if isinstance(node, dict):
        own = [(float(node.get("latency_ms") or 0) + float(node.get("jitter_ms") or 0)) / 1e3]
        return own + [d for v in node.values() for d in _delays_s(v)]
    if isinstance(node, list):
        return [d for v in node for d in _delays_s(v)]
    return []


def max_latency_s(run: RunData) -> float:
    """The longest plausible latency of a message in this run: the age at which the distributed
    runtime refuses a frame (``run.net.max_age_s``), or twice the worst one-way delay the network and
    fault configs allow, whichever is longer. A receive later than that after a send is not its receive."""
    cfg = run.config if isinstance(run.config, dict) else {}
    age = ((cfg.get("run") or {}).get("net") or {}).get("max_age_s", MAX_AGE_S)
    delays = _delays_s(cfg.get("network")) + _delays_s(cfg.get("fault"))
    age = float(age) if isinstance(age, int | float) and age > 0 else MAX_AGE_S
    return max(age, 2 * max(delays, default=0.0))
