"""Shared helpers of the fault tests: short runs and message-log joins."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pyarrow.parquet as pq

from swarmbox.record.broadcast import expand_broadcasts
from tests.conftest import table

#: A 4-drone hover of ~40 s: long enough for fault windows, short enough for the test budget.
HOVER = ("algo=hover", "mission=hover", "algo.params.hover_s=30")


def node_dirs(run_dir: Path) -> list[str]:
    return sorted(p.name for p in (run_dir / "logs").iterdir() if p.is_dir())


def messages(run_dir: Path) -> pd.DataFrame:
    """Every node's messages rows (a broadcast as one row per destination), with the writing node's
    directory name in ``node``."""
    parts = [expand_broadcasts(pq.read_table(run_dir / "logs" / n / "messages.parquet")).to_pandas()
             .assign(node=n) for n in node_dirs(run_dir)]
    return pd.concat(parts, ignore_index=True)


def flow(run_dir: Path) -> pd.DataFrame:
    """One row per sent message and destination: send time, receive time (NaN: not received),
    latency in ms and the network's drop reason."""
    msgs = messages(run_dir)
    sends = msgs[(msgs["kind"] == "send")][["msg_id", "src", "dst", "type", "t_s", "tick"]]
    recvs = msgs[msgs["kind"] == "recv"][["msg_id", "dst", "t_s"]].rename(columns={"t_s": "t_recv"})
    drops = msgs[msgs["kind"] == "drop"][["msg_id", "dst", "reason"]]
    out = sends.merge(recvs, on=["msg_id", "dst"], how="left").merge(drops, on=["msg_id", "dst"], how="left")
    out["latency_ms"] = (out["t_recv"] - out["t_s"]) * 1e3
    return out


def touching(frame: pd.DataFrame, node: int) -> pd.DataFrame:
    return frame[(frame["src"] == node) | (frame["dst"] == node)]


def fault_events(run_dir: Path) -> pd.DataFrame:
    ev = table(run_dir, "ground", "events")
    ev = ev[ev["kind"] == "fault"].copy()
    ev["info"] = [json.loads(x) for x in ev["data"]]
    return ev


def slope(t: np.ndarray, y: np.ndarray) -> float:
    return float(np.polyfit(t, y, 1)[0])
