"""Network metrics from the messages tables, on the unified clock.

Every message is followed from its ``send`` row (one per destination) to the destination's ``recv``
row, matched on ``(msg_id, dst)`` with the receiving node as ``dst``. Definitions:

- latency of a delivered message = unified receive time - unified send time (ms);
- a send with no matching receive is *lost*, except when it was still *in flight* at the end of the
  run (sent later than ``t_end - max latency seen on that link - one tick``, ``t_end`` the last
  message record, and no ``drop`` row of the network says otherwise) or its destination wrote no
  messages table at all (nothing can be said): both are left out of the counts. ``drop`` rows of
  the network (node ``net``) give the reason (``drop_reason``) but are not needed to count;
- loss ratio = lost / (delivered + lost), per link (src, dst) or per agent (messages it sent or that
  were sent to it);
- bytes/s of an agent = bytes it sent (``tx``) or received (``rx``) in the interval / interval length;
- the communication graph of a window has an (undirected) edge between two nodes when at least one
  message between them was delivered in the window (by receive time); its algebraic connectivity is
  the second-smallest eigenvalue of the graph Laplacian (0 when disconnected).
"""

from __future__ import annotations

import numpy as np
import pandas as pd
from scipy.sparse.csgraph import connected_components

from swarmbox.analysis import flow
from swarmbox.analysis.load import NET
from swarmbox.analysis.unify import T

_LAT = "latency_ms"


def message_flow(messages: pd.DataFrame, tick_s: float = 0.0) -> pd.DataFrame:
    """One row per (message, destination): send/receive times, latency, delivered / lost / in flight.

    ``tick_s``: a message is handled at the first tick after its arrival, so one more tick of
    margin is given to messages at the end of the run. Columns: msg_id, type, src, dst, nbytes,
    t_send, t_recv, drop_reason, latency_ms, delivered, counted, lost; sorted by (t_send, msg_id,
    dst). Matched in Arrow (:mod:`swarmbox.analysis.flow`): no pandas join of the whole table.
    """
    return flow.message_flow(messages, tick_s)


def between(flow: pd.DataFrame, t0: float, t1: float) -> pd.DataFrame:
    """Messages sent in [t0, t1] (unified clock).

    A flow from :func:`message_flow` is sorted by send time (unknown times last), so the window is
    one slice of it, not a filtered copy: at 1,000 drones that copy was ~0.8 GB.
    """
    t = flow["t_send"]
    known = int(t.notna().sum())
    if t.iloc[:known].is_monotonic_increasing and t.iloc[known:].isna().all():
        values = t.to_numpy(dtype="float64")[:known]
        lo, hi = np.searchsorted(values, t0, side="left"), np.searchsorted(values, t1, side="right")
        return flow.iloc[lo:max(lo, hi)]
    return flow[(t >= t0) & (t <= t1)]


def grouped_stats(frame: pd.DataFrame, keys: list[str], span_s: float) -> pd.DataFrame:
    """Counts, loss ratio, latency mean/p50/p95/max and bytes/s of ``frame`` grouped by ``keys``."""
    grouped = frame.groupby(keys)
    out = pd.DataFrame({
        "sent": grouped["counted"].sum().astype("int64"),
        "delivered": grouped["delivered"].sum().astype("int64"),
        "lost": grouped["lost"].sum().astype("int64"),
    })
    out["loss_ratio"] = (out["lost"] / out["sent"]).where(out["sent"] > 0)
    lat = frame[frame["delivered"]].groupby(keys)[_LAT]
    out["latency_ms_mean"] = lat.mean()
    out["latency_ms_p50"] = lat.quantile(0.5)
    out["latency_ms_p95"] = lat.quantile(0.95)
    out["latency_ms_max"] = lat.max()
    out["bytes_per_s"] = grouped["nbytes"].sum() / span_s if span_s > 0 else np.nan
    return out


def link_stats(flow: pd.DataFrame, span_s: float) -> pd.DataFrame:
    """Per directed link (src, dst): counts, loss ratio, latency mean/p50/p95/max, bytes/s."""
    return grouped_stats(flow, ["src", "dst"], span_s).reset_index()


def touching(flow: pd.DataFrame, columns: list[str] | None = None) -> pd.DataFrame:
    """Each message twice: once for its sender (``agent`` = src), once for its destination.

    ``columns``: keep only these columns of ``flow`` (besides ``agent``). A large run's flow has
    millions of rows: doubling only the columns a metric reads keeps the copy small.
    """
    columns = list(flow.columns) if columns is None else columns
    out = {c: np.concatenate([flow[c].to_numpy(), flow[c].to_numpy()]) for c in columns}
    out["agent"] = np.concatenate([flow["src"].to_numpy(), flow["dst"].to_numpy()])
    frame = pd.DataFrame(out, copy=False)
    for c in columns:
        if frame[c].dtype != flow[c].dtype:
            frame[c] = frame[c].astype(flow[c].dtype)
    return frame


def agent_stats(flow: pd.DataFrame, span_s: float) -> pd.DataFrame:
    """Per agent, over the messages it sent or that were sent to it; plus tx/rx bytes per second."""
    both = touching(flow, ["counted", "delivered", "lost", _LAT, "nbytes"])
    out = grouped_stats(both, ["agent"], span_s).drop(columns="bytes_per_s")
    del both
    tx = flow.groupby("src")["nbytes"].sum().reindex(out.index).fillna(0.0)
    rx = flow[flow["delivered"]].groupby("dst")["nbytes"].sum().reindex(out.index).fillna(0.0)
    out["tx_bytes_per_s"] = tx / span_s if span_s > 0 else np.nan
    out["rx_bytes_per_s"] = rx / span_s if span_s > 0 else np.nan
    return out.reset_index()


def overall_stats(flow: pd.DataFrame) -> dict[str, float]:
    """Run-level latency and loss over every message of ``flow``."""
    names = ["loss_ratio", "latency_ms_mean", "latency_ms_p50", "latency_ms_p95", "latency_ms_max"]
    if flow.empty:
        return dict.fromkeys(names, np.nan)
    row = grouped_stats(flow.assign(_all=0), ["_all"], 0.0).iloc[0]
    return {k: float(row[k]) for k in names}


def algebraic_connectivity(nodes: list[int], edges: set[tuple[int, int]]) -> float:
    """Second-smallest Laplacian eigenvalue of the undirected graph (0 when disconnected)."""
    if len(nodes) < 2:
        return np.nan
    index = {n: i for i, n in enumerate(nodes)}
    adj = np.zeros((len(nodes), len(nodes)))
    for a, b in edges:
        if a in index and b in index and a != b:
            adj[index[a], index[b]] = adj[index[b], index[a]] = 1.0
    if connected_components(adj, directed=False, return_labels=False) > 1:
        return 0.0   # no eigen-solve needed (it is O(N^3))
    laplacian = np.diag(adj.sum(axis=1)) - adj
    eig = np.linalg.eigvalsh(laplacian)
    return float(max(eig[1], 0.0))


def connectivity_timeline(flow: pd.DataFrame, nodes: list[int], window_s: float) -> pd.DataFrame:
    """Algebraic connectivity of the communication graph per window: t_u (window end), connectivity."""
    nodes = sorted(n for n in nodes if n != NET)
    got = flow[flow["delivered"]]
    if got.empty:
        return pd.DataFrame({T: pd.Series(dtype="float64"), "connectivity": pd.Series(dtype="float64")})
    w = np.floor(got["t_recv"] / window_s).astype("int64")
    pairs = pd.DataFrame({"w": w, "a": np.minimum(got["src"], got["dst"]),
                          "b": np.maximum(got["src"], got["dst"])}).drop_duplicates()
    rows = []
    grouped = dict(tuple(pairs.groupby("w")))
    known: dict[frozenset, float] = {}   # a swarm's graph rarely changes: solve each graph once
    for win in range(int(w.min()), int(w.max()) + 1):
        part = grouped.get(win)
        edges = frozenset(zip(part["a"].tolist(), part["b"].tolist(), strict=True)) if part is not None \
            else frozenset()
        if edges not in known:
            known[edges] = algebraic_connectivity(nodes, set(edges))
        rows.append({T: (win + 1) * window_s, "connectivity": known[edges]})
    return pd.DataFrame(rows)
