"""Per-drone metrics per time window: the series the anomaly detector and the timeline figures read.

Windows tile the unified clock: window k is [k*w, (k+1)*w) and is stamped with its end, (k+1)*w, the
first moment its value is known. Samples are stamped on ticks and the estimated clock offsets are off by
microseconds, so a sample up to half a tick (``tick_s / 2``, 12.5 ms at 40 Hz) before a window's start
counts in that window: without that tolerance a tick sample landing a microsecond early would fall into
the previous window.
Monitored metrics, per drone and window:

- ``latency_ms``: mean latency of the delivered messages the drone sent or that were sent to it,
  binned by send time;
- ``loss_ratio``: lost / counted among those messages (see :mod:`swarmbox.analysis.network`);
- ``disc_n_m``, ``disc_e_m``, ``disc_d_m``: mean GNSS - estimate over the drone's state samples.

The result is tidy: columns ``t_u`` (window end), ``drone``, ``metric``, ``value``.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from swarmbox.analysis.network import agent_chunks, sorted_keys, touching
from swarmbox.analysis.unify import T

MONITORED = ("latency_ms", "loss_ratio", "disc_n_m", "disc_e_m", "disc_d_m")
COLUMNS = [T, "drone", "metric", "value"]


#: Tick length assumed when none is given (40 Hz, the default ``run.tick_hz``).
TICK_S = 0.025


def _stamp(t: pd.Series, window_s: float, tick_s: float = TICK_S) -> np.ndarray:
    tol = min(tick_s / 2, window_s / 2)
    return (np.floor((t.to_numpy(dtype="float64") + tol) / window_s) + 1) * window_s


def network_timeline(flow: pd.DataFrame, drones: list[int], window_s: float,
                     tick_s: float = TICK_S) -> pd.DataFrame:
    """Latency and loss per drone and window; a few drones at a time (:func:`agent_chunks`: each
    (window, drone) group is whole in its chunk, its rows in the doubled flow's order)."""
    chunks = agent_chunks(flow, drones)
    parts = []
    for chunk in chunks:
        part = _network_part(flow, chunk, window_s, tick_s, len(chunks) > 1)
        if part is None:   # grouped otherwise than the whole would be: the drones at once
            parts = [_network_part(flow, drones, window_s, tick_s)]
            break
        parts.append(part)
    parts = [p for p in parts if len(p)]
    return pd.concat(parts, ignore_index=True) if parts else pd.DataFrame(columns=COLUMNS)


def _network_part(flow: pd.DataFrame, drones: list[int], window_s: float, tick_s: float,
                  chunked: bool = False) -> pd.DataFrame | None:
    # the drones' rows only, stamped in place: at 1,000 drones each copy of the doubled flow is ~0.5 GB
    both = touching(flow, ["t_send", "latency_ms", "delivered", "counted", "lost"], agents=drones)
    if both.empty:
        return pd.DataFrame(columns=COLUMNS)
    both[T] = _stamp(both["t_send"], window_s, tick_s)
    got = both[both["delivered"]]
    if chunked and sorted_keys(got[T].to_numpy(), got["agent"].to_numpy()):
        return None
    lat = got.groupby([T, "agent"])["latency_ms"].mean().rename("latency_ms")
    counted = both[both["counted"]]
    loss = counted.groupby([T, "agent"])["lost"].mean().rename("loss_ratio")
    wide = pd.concat([lat, loss], axis=1).reset_index().rename(columns={"agent": "drone"})
    return wide.melt(id_vars=[T, "drone"], var_name="metric", value_name="value").dropna(subset=["value"])


def discrepancy_timeline(disc: pd.DataFrame, drones: list[int], window_s: float,
                         tick_s: float = TICK_S) -> pd.DataFrame:
    disc = disc[disc["node"].isin(drones)]
    if disc.empty:
        return pd.DataFrame(columns=COLUMNS)
    disc = disc.assign(**{T: _stamp(disc[T], window_s, tick_s)})
    cols = ["disc_n_m", "disc_e_m", "disc_d_m"]
    wide = disc.groupby([T, "node"])[cols].mean().reset_index().rename(columns={"node": "drone"})
    return wide.melt(id_vars=[T, "drone"], var_name="metric", value_name="value").dropna(subset=["value"])


def drone_timeline(flow: pd.DataFrame, disc: pd.DataFrame, drones: list[int],
                   window_s: float, tick_s: float = TICK_S) -> pd.DataFrame:
    """All monitored metrics, per drone and window (tidy); ``tick_s``: the run's tick length."""
    tick_s = tick_s if np.isfinite(tick_s) and tick_s > 0 else TICK_S
    parts = [network_timeline(flow, drones, window_s, tick_s),
             discrepancy_timeline(disc, drones, window_s, tick_s)]
    parts = [p for p in parts if len(p)]
    if not parts:
        return pd.DataFrame(columns=COLUMNS)
    out = pd.concat(parts, ignore_index=True)
    out["drone"] = out["drone"].astype("int64")
    out["value"] = out["value"].astype("float64")
    return out.sort_values(["metric", T, "drone"]).reset_index(drop=True)
