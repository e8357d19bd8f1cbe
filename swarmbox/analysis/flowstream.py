"""The message flow of a run matched window by window from its files: the messages table is never held.

:func:`partition` reads every node's ``messages.parquet`` a Parquet batch at a time (broadcast rows
expanded, text as codes into run-wide word lists), puts each row on the ground clock and appends it
to the scratch file of its send-time window (``window_s`` of unified time) in a temporary directory:
one pass, the rows of a window in the order the loaded table has them. :func:`message_flow` then
matches the sends of each window against the receives and drops of that window and of its
neighbours as far as the run's latency bound reaches (:func:`~swarmbox.analysis.flow.matched_sends`),
so only ``1 + 2 * ceil(reach / window_s)`` windows of message rows are held at once, and completes the
whole flow (in flight, counted) with the run's last record and the largest latency of each link
(:func:`~swarmbox.analysis.flow.finish_flow`): the flow :func:`swarmbox.analysis.network.message_flow`
gives from the loaded table, row for row (``tests/analysis/test_memory_windows.py``).

A run with a message row whose time is unknown cannot be windowed (such a send takes its key's first
receive anywhere in the run): :attr:`Partitions.timeless` says so, and the caller loads the table.
"""

from __future__ import annotations

import ctypes
import math
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.compute as pc

from swarmbox.analysis import flow, windows
from swarmbox.analysis.load import NET, RunData, node_id, read_streamed
from swarmbox.analysis.readers import read_batches
from swarmbox.analysis.unify import T, to_unified, unify_messages

#: The messages' columns the flow reads.
COLUMNS = ("t_s", "kind", "msg_id", "type", "src", "dst", "nbytes", "reason")
_TEXT = ("kind", "type", "reason")
_NUMBERS = ("msg_id", "src", "dst", "nbytes")


@dataclass
class Partitions:
    """A run's message rows split by send-time window into scratch files (see the module doc)."""

    root: Path
    width_s: float
    files: dict[int, Path] = field(default_factory=dict)
    words: dict[str, dict[str, int]] = field(default_factory=lambda: {c: {} for c in _TEXT})
    logged: set[int] = field(default_factory=set)   # nodes that logged a message row (not the network)
    t_min: float = np.nan
    t_max: float = np.nan
    rows: int = 0
    timeless: int = 0

    def table(self, k: int) -> pa.Table:
        with pa.memory_map(str(self.files[k])) as source:
            return pa.ipc.open_file(source).read_all()


@contextmanager
def partition(run: RunData, clocks: pd.DataFrame, width_s: float | None = None,
              batch_rows: int | None = None) -> Iterator[Partitions]:
    """Split ``run``'s messages (left in their files: ``run.streamed``) by window; the scratch files
    are removed on leaving the context."""
    width = windows.window_s() if width_s is None else width_s
    with tempfile.TemporaryDirectory(prefix="swarmbox-flow-") as tmp:
        parts = Partitions(Path(tmp), width)
        writers: dict[int, pa.ipc.RecordBatchFileWriter] = {}
        try:
            for nid, path in _message_files(run):
                notes: list[str] = []   # the loader named this file's problems already
                for batch in read_batches(path, "messages", nid, notes, COLUMNS,
                                          batch_rows or windows.BATCH_ROWS):
                    _split(parts, writers, _coded(parts, batch, nid, clocks))
        finally:
            for writer in writers.values():
                writer.close()
        yield parts


def run_flow(run: RunData, clocks: pd.DataFrame, tick_s: float, max_latency_s: float,
             sent_times: bool = True) -> tuple[pd.DataFrame | None, float, float]:
    """The flow of a run whose messages were left in their files, with the first and last unified time
    of its message rows; (None, NaN, NaN) when the messages are loaded (the caller matches them), as
    they are after this when a row has no time (then unified as :func:`~.unify.unify` does)."""
    if "messages" not in run.streamed:
        return None, np.nan, np.nan
    with partition(run, clocks) as parts:
        if not parts.timeless:
            matched = message_flow(parts, tick_s, max_latency_s)
            _give_back()
            return matched, parts.t_min, parts.t_max
    read_streamed(run, "messages")
    unify_messages(run, clocks, sent_times)
    return None, np.nan, np.nan


def _give_back() -> None:
    """Return to the system the heap the windows' arrays were freed into. The C allocator keeps freed
    blocks below its (growing) mapping threshold for reuse: after the windows of a 1,000-drone minute
    that was ~300 MB the rest of the analysis never reused. A no-op where the C library has no
    ``malloc_trim`` (not glibc)."""
    try:
        ctypes.CDLL(None).malloc_trim(0)
    except (OSError, AttributeError):
        pass


def _message_files(run: RunData) -> list[tuple[int, Path]]:
    """Each node's messages file, in the order the loader concatenates them (directory names)."""
    logs = run.path / "logs"
    out = []
    for child in sorted(logs.iterdir()) if logs.is_dir() else []:
        nid = node_id(child.name) if child.is_dir() else None
        if nid is not None:
            out.append((nid, child / "messages.parquet"))
    return out


def _coded(parts: Partitions, batch: pa.Table, node: int, clocks: pd.DataFrame) -> pa.Table:
    """A batch as the scratch files hold it: unified time, text as run-wide codes, numbers as read."""
    t_s = pc.cast(batch.column("t_s"), pa.float64()).to_numpy(zero_copy_only=False)
    nodes = np.full(len(t_s), node, dtype=np.int16)
    t_u = to_unified(pd.Series(t_s), pd.Series(nodes), clocks).to_numpy()
    columns = {T: pa.array(t_u)}
    for name in _TEXT:
        words = parts.words[name]
        text = pc.fill_null(batch.column(name).cast(pa.string()), "").combine_chunks().dictionary_encode()
        seen = text.dictionary.to_pylist()
        lookup = np.array([words.setdefault(w, len(words)) for w in seen], dtype=np.int16)
        columns[name] = pa.array(lookup[text.indices.to_numpy(zero_copy_only=False)] if len(lookup)
                                 else np.zeros(0, dtype=np.int16))
    for name in _NUMBERS:
        columns[name] = batch.column(name).combine_chunks()
    columns["node"] = pa.array(nodes)
    if len(t_s) and node != NET:
        parts.logged.add(node)
    return pa.table(columns)


def _split(parts: Partitions, writers: dict, table: pa.Table) -> None:
    t_u = table.column(T).to_numpy()
    known = ~np.isnan(t_u)
    parts.rows += len(t_u)
    parts.timeless += int((~known).sum())
    if not known.any():
        return
    parts.t_min = float(np.fmin(parts.t_min, t_u[known].min()))
    parts.t_max = float(np.fmax(parts.t_max, t_u[known].max()))
    k = np.floor(t_u[known] / parts.width_s) if math.isfinite(parts.width_s) else np.zeros(int(known.sum()))
    rows = np.flatnonzero(known)
    order = np.argsort(k, kind="stable")   # each window's rows in log order
    k, rows = k[order].astype(np.int64), rows[order]
    cuts = np.flatnonzero(np.diff(k)) + 1
    for lo, hi in zip([0, *cuts.tolist()], [*cuts.tolist(), len(k)], strict=True):
        key = int(k[lo])
        piece = table.take(pa.array(rows[lo:hi]))
        if key not in writers:
            parts.files[key] = parts.root / f"{key}.arrow"
            writers[key] = pa.ipc.new_file(str(parts.files[key]), piece.schema)
        writers[key].write_table(piece)


def _frame(parts: Partitions, tables: list[pa.Table]) -> pd.DataFrame:
    """Scratch rows as the flow reads a loaded messages table: text as categoricals, integers with a
    missing value as floats."""
    data = pa.concat_tables(tables)
    out: dict[str, object] = {T: data.column(T).to_numpy()}
    for name in _TEXT:
        words = list(parts.words[name])
        out[name] = pd.Categorical.from_codes(data.column(name).to_numpy(), categories=words or [""])
    for name in (*_NUMBERS, "node"):
        column = data.column(name)
        out[name] = (pc.cast(column, pa.float64()) if column.null_count else column).to_numpy()
    return pd.DataFrame(out, copy=False)


def message_flow(parts: Partitions, tick_s: float, max_latency_s: float,
                 slack_s: float = flow.SLACK_S) -> pd.DataFrame:
    """The run's message flow from its partitions (see the module doc)."""
    reach = max_latency_s + slack_s + flow.EDGE_S
    bounded = math.isfinite(reach) and math.isfinite(parts.width_s)
    ahead = math.ceil(reach / parts.width_s) if bounded else None   # windows a send's events may lie in
    keys = sorted(parts.files)
    held: dict[int, pa.Table] = {}
    pieces: list[dict[str, np.ndarray]] = []
    for k in keys:
        near = [j for j in keys if ahead is None or k - ahead <= j <= k + ahead]
        for j in [j for j in held if j not in near]:
            del held[j]   # behind the reach: no later window needs it
        tables = [held.setdefault(j, parts.table(j)) for j in near]
        if ahead is not None:   # of the neighbours, only the rows within reach of this window's sends
            lo, hi = k * parts.width_s - reach, (k + 1) * parts.width_s + reach
            tables = [t if j == k else _within(t, lo, hi) for j, t in zip(near, tables, strict=True)]
            held = {j: (_within(t, lo + parts.width_s, np.inf) if j <= k else t) for j, t in held.items()}
        own = np.concatenate([np.full(len(t), j == k) for j, t in zip(near, tables, strict=True)])
        pieces.append(flow.matched_sends(_frame(parts, tables), slack_s, max_latency_s, np.inf, own))
    held.clear()
    logged = np.sort(np.array(sorted(parts.logged), dtype=np.int64))
    return _finish(parts, pieces, logged, parts.t_max, tick_s)


def _finish(parts: Partitions, pieces: list[dict[str, np.ndarray]], logged: np.ndarray, t_end: float,
            tick_s: float) -> pd.DataFrame:
    """:func:`~.flow.finish_flow` of the pieces joined, without joining them: each row's link maximum
    over every piece first, then the pieces finished one by one into the flow's columns, each freed once
    copied. What is held is the flow and the pieces not yet copied (smaller than their rows of the
    flow), where joining then finishing held the pieces' join and the finished columns at once."""
    if not any(len(p["t_send"]) for p in pieces):
        return flow.finish_flow(_joined(parts, pieces), logged, t_end, tick_s)
    link_max = _link_max_s(pieces)
    rows = sum(len(p["t_send"]) for p in pieces)
    out: dict[str, np.ndarray] = {}
    at = 0
    for i, most in enumerate(link_max):
        piece, pieces[i], link_max[i] = pieces[i], {}, np.zeros(0)   # the lists let go of the piece
        columns = flow.finished(piece, most, logged, t_end, tick_s)
        del piece, most
        for name, values in columns.items():
            if name not in out:
                out[name] = np.empty(rows, dtype=values.dtype)
            out[name][at:at + len(values)] = values
        at += len(columns["t_send"])
        del columns
        _give_back()   # the piece's arrays were below the allocator's mapping threshold: kept, not returned
    return flow.flow_frame(out, _words(parts))


def _link_max_s(pieces: list[dict[str, np.ndarray]]) -> list[np.ndarray]:
    """Per piece and row: the largest latency of the row's link (src, dst) over every piece, in s; 0 for
    a link with no latency or a row with an unknown end (``flow._link_max_latency_s`` of the join)."""
    known = [p["s_known"] & p["d_known"] for p in pieces]
    keys = flow.pair_keys([(p["src"][k], p["dst"][k]) for p, k in zip(pieces, known, strict=True)])
    tops = []
    for p, k, key in zip(pieces, known, keys, strict=True):
        lat = ((p["t_recv"] - p["t_send"]) * 1e3)[k]
        tops.append(pd.Series(lat, index=key).groupby(level=0).max())   # NaN: a link with no latency
    best = pd.concat(tops).groupby(level=0).max()
    out = []
    for k, key in zip(known, keys, strict=True):
        per_row = np.zeros(len(k))
        per_row[k] = np.nan_to_num(best.to_numpy()[best.index.get_indexer(key)], nan=0.0)
        out.append(per_row / 1e3)
    return out


def _words(parts: Partitions) -> dict[str, pa.Array]:
    return {"type_words": pa.array(list(parts.words["type"]) or [""], pa.string()),
            "reason_words": pa.array(list(parts.words["reason"]) or [""], pa.string())}


def _within(table: pa.Table, lo: float, hi: float) -> pa.Table:
    t = table.column(T).to_numpy()
    keep = (t >= lo) & (t <= hi)
    return table if keep.all() else table.filter(pa.array(keep))


def _joined(parts: Partitions, pieces: list[dict[str, np.ndarray]]) -> dict[str, np.ndarray]:
    words = _words(parts)
    if not pieces:
        empty = {"msg_id": np.zeros(0, np.int64), "m_known": np.zeros(0, bool), "dst": np.zeros(0, np.int64),
                 "d_known": np.zeros(0, bool), "t_send": np.zeros(0), "t_recv": np.zeros(0),
                 "reason": np.zeros(0, np.int64), "src": np.zeros(0, np.int64), "s_known": np.zeros(0, bool),
                 "nbytes": np.zeros(0), "type": np.zeros(0, np.int16)}
        return empty | words
    out = {}
    for name in [name for name in pieces[0] if not name.endswith("_words")]:
        out[name] = np.concatenate([p.pop(name) for p in pieces])   # each window's copy freed as joined
    return out | words
