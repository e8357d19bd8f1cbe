"""Network metrics from the messages tables, on the unified clock.

Every message is followed from its ``send`` row (one per destination) to the destination's ``recv``
row, matched on ``(msg_id, dst)`` with the receiving node as ``dst`` *and by time*: a receive belongs
to the latest send of its key before it (up to 5 ms of clock-estimation error earlier), never to a
later one, and only within the run's plausible latency bound. A node that restarts numbers its
messages from 0 again: its second life's sends are not matched to its first life's receives, and one
lost after the restart comes out lost. Definitions:

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

from collections.abc import Callable

import numpy as np
import pandas as pd
from scipy.sparse.csgraph import connected_components

from swarmbox.analysis import flow, windows
from swarmbox.analysis.flow import pair_keys
from swarmbox.analysis.load import NET
from swarmbox.analysis.unify import T

_LAT = "latency_ms"


def message_flow(messages: pd.DataFrame, tick_s: float = 0.0, max_latency_s: float = np.inf) -> pd.DataFrame:
    """One row per (message, destination): send/receive times, latency, delivered / lost / in flight.

    ``tick_s``: a message is handled at the first tick after its arrival, so one more tick of
    margin is given to messages at the end of the run. ``max_latency_s``: a receive later than this
    after the send is not its receive (:func:`swarmbox.analysis.sampling.max_latency_s` gives a run's).
    Columns: msg_id, type, src, dst, nbytes, t_send, t_recv, drop_reason, latency_ms, delivered,
    counted, lost (type only when ``messages`` has it); sorted by (t_send, msg_id, dst). Matched by
    sorted keys (:mod:`swarmbox.analysis.flow`): no join of the whole table.
    """
    return flow.message_flow(messages, tick_s, max_latency_s)


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
    """Counts, loss ratio, latency mean/p50/p95/max and bytes/s of ``frame`` grouped by ``keys``.

    One grouping for the sums and one for the latencies of the delivered messages (both quantiles
    from one sort: the same values as two ``quantile`` calls, half the work).
    """
    grouped = frame.groupby(keys)
    sums = grouped[["counted", "delivered", "lost", "nbytes"]].sum()
    out = pd.DataFrame({name: sums[col].astype("int64") for name, col in
                        (("sent", "counted"), ("delivered", "delivered"), ("lost", "lost"))})
    out["loss_ratio"] = (out["lost"] / out["sent"]).where(out["sent"] > 0)
    # the keys and latencies of the delivered rows, not a copy of every column of them (~0.5 GB a minute
    # of a 1,000-drone flow): the same groups, values and order
    lat = frame.loc[frame["delivered"].to_numpy(dtype=bool), [*keys, _LAT]].groupby(keys)[_LAT]
    top = lat.max()
    quantiles = lat.quantile([0.5, 0.95]).to_numpy().reshape(-1, 2)   # per group: p50, p95
    out["latency_ms_mean"] = lat.mean()
    out["latency_ms_p50"] = pd.Series(quantiles[:, 0], index=top.index)
    out["latency_ms_p95"] = pd.Series(quantiles[:, 1], index=top.index)
    out["latency_ms_max"] = top
    out["bytes_per_s"] = sums["nbytes"] / span_s if span_s > 0 else np.nan
    return out


def link_stats(flow: pd.DataFrame, span_s: float) -> pd.DataFrame:
    """Per directed link (src, dst): counts, loss ratio, latency mean/p50/p95/max, bytes/s.

    A few links at a time (:func:`_link_chunks`, ranges of links in their order): each link is whole
    in its chunk, its rows in the flow's order, so its numbers are those of the flow grouped at once;
    only a chunk's rows are copied and grouped (grouping a 1,000-drone minute at once took ~0.4 GB
    beyond the flow)."""
    src, dst = flow["src"].to_numpy(), flow["dst"].to_numpy()
    chunks = _link_chunks(src, dst, windows.TOUCH_ROWS)
    got = flow["delivered"].to_numpy(dtype=bool)
    if len(chunks) > 1 and not sorted_where(got, src, dst):
        parts = []
        for rows in chunks:
            part = pd.DataFrame({c: flow[c].to_numpy()[rows] for c in _LINK_READ}, copy=False)
            mine = part["delivered"].to_numpy(dtype=bool)
            if sorted_keys(part["src"].to_numpy()[mine], part["dst"].to_numpy()[mine]):
                break   # pandas would average this chunk another way than the whole: at once
            parts.append(grouped_stats(part, ["src", "dst"], span_s))
            del part
        else:
            return pd.concat(parts).reset_index()
    return grouped_stats(flow, ["src", "dst"], span_s).reset_index()


_LINK_READ = ("src", "dst", "counted", "delivered", "lost", _LAT, "nbytes")


def _link_codes(src: np.ndarray, dst: np.ndarray, lo: int, hi: int, base: tuple[int, int, int]) -> np.ndarray:
    """Rows lo:hi's links as int64 codes in (src, dst) order, -1 where an end is unknown (NaN)."""
    s, d = src[lo:hi], dst[lo:hi]
    known = ~(np.isnan(s) | np.isnan(d)) if s.dtype.kind == "f" or d.dtype.kind == "f" else None
    s_min, d_min, span = base
    if known is not None:
        s, d = np.where(known, s, s_min), np.where(known, d, d_min)
    code = (s.astype(np.int64) - s_min) * span + (d.astype(np.int64) - d_min)
    return code if known is None else np.where(known, code, -1)


def _link_chunks(src: np.ndarray, dst: np.ndarray, rows: int) -> list[np.ndarray]:
    """The flow's row numbers of ranges of links (in (src, dst) order; two links at least each) that hold
    at most ``rows`` rows each; none (group at once) when that many hold them all, or when the links
    cannot be coded in 62 bits. Codes are made a block of rows at a time: no array of
    every row's link."""
    s_ok, d_ok = (v if v.dtype.kind != "f" else v[~np.isnan(v)] for v in (src, dst))
    if len(src) <= rows or not len(s_ok) or not len(d_ok):
        return []
    base = (int(s_ok.min()), int(d_ok.min()), int(d_ok.max()) - int(d_ok.min()) + 1)
    if (int(s_ok.max()) - base[0] + 1) * base[2] >= 2**62:
        return []
    counts = _blockwise(lambda lo, hi: pd.Series(_link_codes(src, dst, lo, hi, base)).value_counts(),
                        len(src), rows).sort_index()
    counts = counts[counts.index >= 0]
    edges, held, links = [], 0, 0
    for code, size in zip(counts.index.tolist(), counts.tolist(), strict=True):
        if links >= 2 and held + size > rows:
            edges.append(code)
            held, links = 0, 0
        held, links = held + size, links + 1
    if links == 1 and edges:
        edges.pop()   # the last link joins the chunk before it
    bounds = [counts.index[0], *edges, counts.index[-1] + 1]
    out = []
    for a, b in zip(bounds[:-1], bounds[1:], strict=True):
        out.append(np.concatenate([lo + np.flatnonzero((c >= a) & (c < b)) for lo in range(0, len(src), rows)
                                   for c in [_link_codes(src, dst, lo, lo + rows, base)]]))
    return out


def touching(flow: pd.DataFrame, columns: list[str] | None = None, agents: list[int] | None = None,
             where: np.ndarray | None = None) -> pd.DataFrame:
    """Each message twice: once for its sender (``agent`` = src), once for its destination.

    ``columns``: keep only these columns of ``flow`` (besides ``agent``). A large run's flow has
    millions of rows: doubling only the columns a metric reads keeps the copy small. ``agents`` and
    ``where`` (a mask over the flow's rows) keep only the rows of those agents and messages: the same
    rows, in the same order, as filtering the whole doubled frame, without making it first (its index
    is then a fresh range).
    """
    columns = list(flow.columns) if columns is None else columns
    halves = [flow["src"].to_numpy(), flow["dst"].to_numpy()]
    keep = [None, None]
    if agents is not None or where is not None:
        mask = np.ones(len(flow), dtype=bool) if where is None else np.asarray(where, dtype=bool)
        keep = [mask & np.isin(half, agents) if agents is not None else mask for half in halves]
    out = {c: np.concatenate([_rows(flow[c].to_numpy(), k) for k in keep]) for c in columns}
    out["agent"] = np.concatenate([_rows(half, k) for half, k in zip(halves, keep, strict=True)])
    frame = pd.DataFrame(out, copy=False)
    for c in columns:
        if frame[c].dtype != flow[c].dtype:
            frame[c] = frame[c].astype(flow[c].dtype)
    return frame


def _rows(values: np.ndarray, keep: np.ndarray | None) -> np.ndarray:
    return values if keep is None else values[keep]


def _blockwise(part: Callable[[int, int], pd.Series], rows: int, block: int) -> pd.Series:
    """The sum, by index, of ``part(lo, hi)`` over blocks of ``block`` rows: sums of whole numbers
    (counts, message sizes) as exact as summed at once, holding one block's grouping."""
    parts = [part(lo, min(lo + block, rows)) for lo in range(0, max(rows, 1), block)]
    return parts[0] if len(parts) == 1 else pd.concat(parts).groupby(level=0).sum()


def _traffic(flow: pd.DataFrame, agents: pd.Index, span_s: float) -> pd.DataFrame:
    """Bytes per second each of ``agents`` sent (tx) and received (rx, delivered messages only); summed a
    block of the flow at a time (sizes are whole numbers of bytes: the sums are exact either way)."""
    nbytes, src, dst = flow["nbytes"], flow["src"], flow["dst"]
    got = flow["delivered"].to_numpy(dtype=bool)   # only the columns read, not a copy of the flow

    def sent(lo: int, hi: int) -> pd.Series:
        return nbytes.iloc[lo:hi].groupby(src.iloc[lo:hi]).sum()

    def received(lo: int, hi: int) -> pd.Series:
        mine = got[lo:hi]
        return nbytes.iloc[lo:hi][mine].groupby(dst.iloc[lo:hi][mine]).sum()

    tx = _blockwise(sent, len(flow), windows.TOUCH_ROWS).reindex(agents).fillna(0.0)
    rx = _blockwise(received, len(flow), windows.TOUCH_ROWS).reindex(agents).fillna(0.0)
    return pd.DataFrame({"tx_bytes_per_s": tx / span_s if span_s > 0 else np.nan,
                         "rx_bytes_per_s": rx / span_s if span_s > 0 else np.nan}, index=agents)


def agent_stats(flow: pd.DataFrame, span_s: float) -> pd.DataFrame:
    """Per agent, over the messages it sent or that were sent to it; plus tx/rx bytes per second.

    A few agents at a time (:func:`agent_chunks`): each agent's rows are those, in the order, of the
    whole doubled flow, so its numbers are too; only a chunk's doubled rows are held."""
    cols = ["counted", "delivered", "lost", _LAT, "nbytes"]
    chunks = agent_chunks(flow)
    parts: list[pd.DataFrame] | None = [] if len(chunks) > 1 and not _whole_sorted(flow) else None
    for agents in chunks if parts is not None else []:
        both = touching(flow, cols, agents)
        got = both["agent"].to_numpy()[both["delivered"].to_numpy(dtype=bool)]
        if sorted_keys(got):   # pandas would average this chunk another way than the whole: no chunks
            parts = None
            break
        parts.append(grouped_stats(both, ["agent"], span_s).drop(columns="bytes_per_s"))
        del both
    if parts is None:
        both = touching(flow, cols)
        parts = [grouped_stats(both, ["agent"], span_s).drop(columns="bytes_per_s")]
        del both
    out = parts[0] if len(parts) == 1 else pd.concat(parts)
    return out.join(_traffic(flow, out.index, span_s)).reset_index()


def sorted_keys(*keys: np.ndarray) -> bool:
    """Whether rows come in ascending order of their keys (compared in turn). Pandas averages the
    groups of such rows by slices, and other rows one value at a time with compensation, which can
    differ in the last bit: a chunk of rows is grouped as the whole only if both are sorted or neither is.
    """
    if len(keys[0]) < 2:
        return True
    ahead = np.zeros(len(keys[0]) - 1, dtype=bool)
    tied = np.ones(len(keys[0]) - 1, dtype=bool)
    for key in keys:
        a, b = key[:-1], key[1:]
        ahead |= tied & (b > a)
        tied &= b == a
    return bool((ahead | tied).all())


def _whole_sorted(flow: pd.DataFrame) -> bool:
    """:func:`sorted_keys` of the agents of the doubled flow's delivered rows (without doubling it)."""
    got = flow["delivered"].to_numpy(dtype=bool)
    src, dst = flow["src"].to_numpy(), flow["dst"].to_numpy()
    ends = np.concatenate([src[got][-1:], dst[got][:1]]) if got.any() else src[:0]
    return sorted_keys(ends) and sorted_where(got, src) and sorted_where(got, dst)


def sorted_where(where: np.ndarray, *keys: np.ndarray, block: int | None = None) -> bool:
    """:func:`sorted_keys` of the rows ``where`` marks, a block of rows at a time: no copy of the keys
    of every marked row (at 1,000 drones, 100 MB a minute of flow)."""
    block = windows.BATCH_ROWS if block is None else block
    last: list[np.ndarray] = [key[:0] for key in keys]   # the previous block's last marked row
    for lo in range(0, len(where), block):
        mine = where[lo:lo + block]
        part = [np.concatenate([prev, key[lo:lo + block][mine]])
                for prev, key in zip(last, keys, strict=True)]
        if not sorted_keys(*part):
            return False
        last = [p[-1:] for p in part]
    return True


def agent_chunks(flow: pd.DataFrame, agents: list[int] | None = None,
                 rows: int | None = None) -> list[list[int] | None]:
    """``agents`` (default: every sender and destination) in ascending chunks that touch at most
    ``rows`` rows of the doubled flow each, but of two agents at least (one agent's rows alone are in
    order: pandas would average them another way, :func:`sorted_keys`); ``[agents]`` as given (None:
    all) when one chunk holds them all. The agents' rows are counted a block of the flow at a time."""
    rows = windows.TOUCH_ROWS if rows is None else rows
    if 2 * len(flow) <= rows:
        return [agents]
    src, dst = flow["src"], flow["dst"]
    counts = _blockwise(lambda lo, hi: pd.concat([src.iloc[lo:hi], dst.iloc[lo:hi]]).value_counts(),
                        len(flow), rows)
    ids = counts.index.to_numpy()
    if agents is not None:
        ids = ids[np.isin(ids, agents)]
    ids = np.sort(ids)
    sizes = counts.reindex(ids).to_numpy(dtype=np.int64)
    chunks, current, held = [], [], 0
    for agent, size in zip(ids.tolist(), sizes.tolist(), strict=True):
        if len(current) >= 2 and held + size > rows:
            chunks.append(current)
            current, held = [], 0
        current.append(agent)
        held += size
    if len(current) == 1 and chunks:
        chunks[-1].append(current.pop())   # the last agent joins the chunk before it
    return [*chunks, current] if current else chunks or [[]]


def agent_traffic(flow: pd.DataFrame, span_s: float) -> pd.DataFrame:
    """The tx/rx columns of :func:`agent_stats` alone (``agent``, ``tx_bytes_per_s``, ``rx_bytes_per_s``),
    without the per-agent latency and loss: what a run's scalars read of the agents."""
    ids = np.concatenate([pd.unique(flow["src"].to_numpy()), pd.unique(flow["dst"].to_numpy())])
    return _traffic(flow, pd.Index(np.sort(pd.unique(ids)), name="agent").dropna(), span_s).reset_index()


def overall_stats(flow: pd.DataFrame) -> dict[str, float]:
    """Run-level latency and loss over every message of ``flow``."""
    names = ["loss_ratio", "latency_ms_mean", "latency_ms_p50", "latency_ms_p95", "latency_ms_max"]
    if flow.empty:
        return dict.fromkeys(names, np.nan)
    # the columns grouped_stats reads, not a copy of the whole flow, under one group
    row = grouped_stats(flow[["counted", "delivered", "lost", "nbytes", _LAT]].assign(_all=0), ["_all"], 0.0)
    return {k: float(row[k].iloc[0]) for k in names}


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
    got = flow["delivered"].to_numpy(dtype=bool)
    if not got.any():
        return pd.DataFrame({T: pd.Series(dtype="float64"), "connectivity": pd.Series(dtype="float64")})
    w = np.floor(flow["t_recv"].to_numpy()[got] / window_s).astype("int64")
    src, dst = flow["src"].to_numpy()[got], flow["dst"].to_numpy()[got]
    a, b = np.minimum(src, dst), np.maximum(src, dst)
    (key,) = pair_keys([(w, a)])
    (key,) = pair_keys([(key, b)])   # one int64 per (window, edge), ordered as (window, a, b)
    first = ~pd.Series(key).duplicated().to_numpy()   # the distinct triples, by hashing
    order = np.argsort(key[first], kind="stable")      # then window by window
    w, a, b = w[first][order], a[first][order].tolist(), b[first][order].tolist()
    wins = range(int(w[0]), int(w[-1]) + 1)
    starts = np.searchsorted(w, wins, side="left").tolist()
    ends = np.searchsorted(w, wins, side="right").tolist()
    times, values = [], []
    known: dict[frozenset, float] = {}   # a swarm's graph rarely changes: solve each graph once
    for win, lo, hi in zip(wins, starts, ends, strict=True):
        edges = frozenset(zip(a[lo:hi], b[lo:hi], strict=True))
        if edges not in known:
            known[edges] = algebraic_connectivity(nodes, set(edges))
        times.append((win + 1) * window_s)
        values.append(known[edges])
    return pd.DataFrame({T: times, "connectivity": values})
