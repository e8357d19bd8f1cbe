"""A run (or a time window of it) on the unified timeline, in the shape replay viewers want.

:func:`build_replay` loads a run directory, puts every node on the ground clock
(:mod:`swarmbox.analysis.unify`) and keeps, for the chosen window ``[t_from, t_to]`` of unified
seconds:

- ``state``: every drone state sample (estimate, GNSS, ground truth, velocity, stage, battery);
- ``setpoints``: every setpoint handed to a vehicle;
- ``stages`` and ``events``: every node's stage changes, markers, faults, safety, proximity, ...;
- ``links``: per link (src -> dst) and per ``window_s`` bin, the mean latency (ms) and the loss
  ratio of its messages (by send time; see :mod:`swarmbox.analysis.network`);
- ``metrics``: per drone and bin, the analyzer's monitored series (latency, loss, GNSS - estimate;
  see :mod:`swarmbox.analysis.timeline`).

Bins are stamped with their end, clipped to the window, so that every exported record lies in the
run's time range ``span``. Absolute times (``epoch_ns``) start at the run's ``started_at``.
"""

from __future__ import annotations

from dataclasses import dataclass
from datetime import datetime
from pathlib import Path

import numpy as np
import pandas as pd

from swarmbox.analysis import network
from swarmbox.analysis.load import RunData, load_run
from swarmbox.analysis.metrics import discrepancy
from swarmbox.analysis.timeline import drone_timeline
from swarmbox.analysis.unify import T, unify


class ReplayError(ValueError):
    """The run cannot be replayed as asked (nothing in the window, bad window)."""


@dataclass(frozen=True)
class Replay:
    run_dir: Path
    name: str
    start_epoch_ns: int            # absolute time of unified t = 0
    span: tuple[float, float]      # first and last record, unified s
    drones: list[int]
    state: pd.DataFrame
    setpoints: pd.DataFrame
    stages: pd.DataFrame
    events: pd.DataFrame
    links: pd.DataFrame            # T, src, dst, latency_ms, loss_ratio, messages
    metrics: pd.DataFrame          # T, drone, metric, value

    def epoch_ns(self, t_u: float | np.ndarray) -> np.ndarray:
        """Absolute nanoseconds of unified times."""
        return self.start_epoch_ns + np.round(np.asarray(t_u, dtype="float64") * 1e9).astype("int64")


def _start_epoch_ns(manifest: dict) -> int:
    started = manifest.get("started_at")
    try:
        return int(datetime.fromisoformat(started).timestamp()) * 1_000_000_000
    except (TypeError, ValueError):
        return 0


def link_series(flow: pd.DataFrame, window_s: float) -> pd.DataFrame:
    """Per link and bin (by send time): mean latency of delivered messages, loss ratio, count."""
    cols = [T, "src", "dst", "latency_ms", "loss_ratio", "messages"]
    if flow.empty:
        return pd.DataFrame(columns=cols)
    f = flow.assign(**{T: (np.floor(flow["t_send"].to_numpy() / window_s) + 1) * window_s})
    g = f.groupby([T, "src", "dst"])
    out = pd.DataFrame({
        "latency_ms": g["latency_ms"].mean(),
        "loss_ratio": f[f["counted"]].groupby([T, "src", "dst"])["lost"].mean(),
        "messages": g.size(),
    }).reset_index()
    return out[cols]


def _clip(frame: pd.DataFrame, t0: float, t1: float, stamp_end: bool = False) -> pd.DataFrame:
    if stamp_end:   # a bin ending after t1 still holds data from before it: stamp it at t1
        frame = frame.assign(**{T: frame[T].clip(upper=t1)})
    return frame[(frame[T] >= t0) & (frame[T] <= t1)].sort_values(T, kind="stable").reset_index(drop=True)


def build_replay(source: str | Path | RunData, *, t_from: float | None = None, t_to: float | None = None,
                 window_s: float = 0.5) -> Replay:
    """Everything a replay shows, for the unified window ``[t_from, t_to]`` (default: the whole run)."""
    if window_s <= 0:
        raise ReplayError(f"window_s must be > 0, got {window_s}")
    run = source if isinstance(source, RunData) else load_run(source)
    unify(run)
    tables = run.tables
    drones = run.drones
    stamped = [tables[t][T] for t in ("state", "stages", "events", "setpoints") if len(tables[t])]
    if not stamped:
        raise ReplayError(f"{run.path}: no state, stage or event records to replay")
    first = float(min(s.min() for s in stamped))
    last = float(max(s.max() for s in stamped))
    t0 = first if t_from is None else max(first, float(t_from))
    t1 = last if t_to is None else min(last, float(t_to))
    if t1 < t0:
        raise ReplayError(f"empty window: --from {t_from} / --to {t_to} outside the run's "
                          f"[{first:.3f}, {last:.3f}] s")
    tick_s = float(run.manifest.get("tick_s") or 0.025)
    flow = network.message_flow(tables["messages"], tick_s)
    flow = flow[(flow["t_send"] >= t0) & (flow["t_send"] <= t1)]
    state = _clip(tables["state"], t0, t1)
    metrics = drone_timeline(flow, discrepancy(state), drones, window_s, tick_s)
    return Replay(
        run_dir=run.path, name=run.path.name, start_epoch_ns=_start_epoch_ns(run.manifest),
        span=(t0, t1), drones=drones, state=state,
        setpoints=_clip(tables["setpoints"], t0, t1),
        stages=_clip(tables["stages"], t0, t1), events=_clip(tables["events"], t0, t1),
        links=_clip(link_series(flow, window_s), t0, t1, stamp_end=True),
        metrics=_clip(metrics, t0, t1, stamp_end=True))


def node_label(node: int) -> str:
    return "ground" if node == -1 else "net" if node == -2 else f"drone_{node}"


def enu(n: np.ndarray, e: np.ndarray, d: np.ndarray) -> np.ndarray:
    """Mission NED -> ENU (x east, y north, z up): what 3-D viewers assume."""
    return np.column_stack([e, n, -d]).astype("float64")


def latency_rgb(latency_ms: np.ndarray, worst_ms: float = 100.0) -> np.ndarray:
    """Green (0 ms) -> yellow -> red (``worst_ms`` or more); grey when unknown (all lost)."""
    x = np.clip(np.nan_to_num(np.asarray(latency_ms, dtype="float64"), nan=-1.0) / worst_ms, -1.0, 1.0)
    r = np.where(x < 0, 0.5, np.clip(2 * x, 0, 1))
    g = np.where(x < 0, 0.5, np.clip(2 - 2 * x, 0, 1))
    b = np.where(x < 0, 0.5, 0.0)
    return np.column_stack([r, g, b])
