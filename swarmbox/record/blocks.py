"""Buffered columnar ``state`` blocks (see :mod:`swarmbox.record.fleet`), handed over as one batch.

A block holds one tick's state rows of many drones as numpy columns. A hand-over concatenates the
blocks, adds any state rows that nodes logged one by one (a run on a backend without fleet arrays,
or a mix), and orders the rows by node, then tick: the writer needs each node's rows contiguous.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pyarrow as pa

from swarmbox.record.columns import arrow_schema, batch, column

_STATE = arrow_schema("state")
_TICK = _STATE.names.index("tick")
_STRINGS = {i for i, f in enumerate(_STATE) if f.type == pa.string()}


class StateBlocks:
    """State rows as columnar blocks, until the recorder takes them."""

    def __init__(self) -> None:
        self._blocks: list[tuple[np.ndarray, list[Any]]] = []
        self.rows = 0

    def add(self, nodes: np.ndarray, columns: list[Any]) -> None:
        if len(columns) != len(_STATE):
            raise ValueError(f"a state block needs {len(_STATE)} columns, got {len(columns)}")
        self._blocks.append((nodes, columns))
        self.rows += len(nodes)

    def take(self, logs: dict[int, Any]) -> tuple[list[int], list[int], pa.RecordBatch]:
        """Every buffered block plus every node's buffered state tuples, emptied: (nodes in order,
        their row counts, the rows as one record batch in that order)."""
        parts = [(nodes, cols) for nodes, cols in self._blocks]
        self._blocks, self.rows = [], 0
        for log in logs.values():
            rows = log.rows.get("state")
            if rows:
                data = batch("state", rows)
                cols = [c.to_pylist() if i in _STRINGS else c.to_numpy(zero_copy_only=False)
                        for i, c in enumerate(data.columns)]
                parts.append((np.full(len(rows), log.node_id, dtype=np.int16), cols))
                rows.clear()
        nodes = np.concatenate([p[0] for p in parts]).astype(np.int16)
        columns = [np.concatenate([np.asarray(p[1][i], dtype=object if i in _STRINGS else None)
                                   for p in parts]) for i in range(len(_STATE))]
        order = np.lexsort((columns[_TICK], nodes))   # by node, then tick (blocks arrive in tick order)
        nodes = nodes[order]
        arrays = [column(c[order], f.type) for c, f in zip(columns, _STATE, strict=True)]
        ids, counts = np.unique(nodes, return_counts=True)
        return ids.tolist(), counts.tolist(), pa.RecordBatch.from_arrays(arrays, schema=_STATE)
