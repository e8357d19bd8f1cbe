"""Buffered columnar ``state`` rows (see :mod:`swarmbox.record.fleet`), handed over as one batch.

Rows live in growable column buffers, one per schema column plus the writing node, so a tick's rows
of the whole fleet are written with one numpy call per column (:meth:`StateBlocks.reserve`, or
:meth:`StateBlocks.add` for a block of ready columns) and a hand-over is a slice, not a
concatenation of thousands of small blocks. A hand-over adds any state rows that nodes logged one
by one (a run on a backend without fleet arrays, or a mix) and orders the rows by node, then tick:
the writer needs each node's rows contiguous.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pyarrow as pa

from swarmbox.record.columns import arrow_schema, batch, column

_STATE = arrow_schema("state")
_TICK = _STATE.names.index("tick")
_STRINGS = {i for i, f in enumerate(_STATE) if f.type == pa.string()}
_DTYPES = [np.dtype(object if f.type == pa.string() else f.type.to_pandas_dtype()) for f in _STATE]
#: The float columns after ``mode`` (position ... battery) share one (14, rows) buffer.
FIRST_VALUE = _STATE.names.index("pos_n")
N_VALUES = len(_STATE) - FIRST_VALUE


class StateBlocks:
    """State rows in column buffers, until the recorder takes them."""

    def __init__(self, capacity: int = 1024) -> None:
        self.rows = 0
        self._alloc(capacity)

    def _alloc(self, capacity: int) -> None:
        self._cap = capacity
        self.nodes = np.empty(capacity, dtype=np.int16)
        self.values = np.empty((N_VALUES, capacity))
        #: per schema column, its buffer (the value columns are rows of :attr:`values`)
        self.columns: list[np.ndarray] = [np.empty(capacity, dtype=d) for d in _DTYPES[:FIRST_VALUE]]
        self.columns += list(self.values)

    def reserve(self, n: int) -> tuple[int, int]:
        """Room for ``n`` more rows: returns their span ``(start, stop)``; the caller fills
        :attr:`nodes` and every buffer of :attr:`columns` there (the buffers may be new ones after
        this call), then calls :meth:`commit`. Until then the rows are not taken: a Ctrl-C between
        the two leaves no half-filled row (None texts, stale numbers) for the last hand-over."""
        start, stop = self.rows, self.rows + n
        if stop > self._cap:
            old_nodes, old_cols = self.nodes, self.columns
            self._alloc(max(2 * self._cap, stop))
            self.nodes[:start] = old_nodes[:start]
            for new, old in zip(self.columns, old_cols, strict=True):
                new[:start] = old[:start]
        return start, stop

    def commit(self, stop: int) -> None:
        """The rows reserved up to ``stop`` are filled."""
        self.rows = stop

    def add(self, nodes: np.ndarray, columns: list[Any]) -> None:
        """A block of rows: ``nodes`` and one sequence per schema column."""
        if len(columns) != len(_STATE):
            raise ValueError(f"a state block needs {len(_STATE)} columns, got {len(columns)}")
        start, stop = self.reserve(len(nodes))
        self.nodes[start:stop] = nodes
        for buf, col in zip(self.columns, columns, strict=True):
            buf[start:stop] = col
        self.commit(stop)

    def take(self, logs: dict[int, Any]) -> tuple[list[int], list[int], pa.RecordBatch]:
        """Every buffered row plus every node's buffered state tuples, emptied: (nodes in order,
        their row counts, the rows as one record batch in that order)."""
        rows = self.rows
        parts = [(self.nodes[:rows], [c[:rows] for c in self.columns])] if rows else []
        for log in logs.values():
            tuples = log.rows.get("state")
            if tuples:
                data = batch("state", tuples)
                cols = [c.to_pylist() if i in _STRINGS else c.to_numpy(zero_copy_only=False)
                        for i, c in enumerate(data.columns)]
                parts.append((np.full(len(tuples), log.node_id, dtype=np.int16), cols))
                tuples.clear()
        if len(parts) == 1:
            nodes, columns = parts[0]
        else:
            nodes = np.concatenate([p[0] for p in parts]).astype(np.int16)
            columns = [np.concatenate([np.asarray(p[1][i], dtype=object if i in _STRINGS else None)
                                       for p in parts]) for i in range(len(_STATE))]
        order = np.lexsort((columns[_TICK], nodes))   # by node, then tick (blocks arrive in tick order)
        nodes = nodes[order]
        arrays = [column(c[order], f.type) for c, f in zip(columns, _STATE, strict=True)]
        ids, counts = np.unique(nodes, return_counts=True)
        self.rows = 0
        if self._cap > 4 * max(rows, 1024):   # a burst grew the buffers: give the memory back
            self._alloc(max(rows, 1024))
        return ids.tolist(), counts.tolist(), pa.RecordBatch.from_arrays(arrays, schema=_STATE)
