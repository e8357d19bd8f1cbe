"""The fleet's ``messages`` rows as column chunks: one numpy structured array per batch of rows.

The rows have the layout of the object core's packed rows (:mod:`swarmbox.core.rows`), so handing
them to the recorder is one ``bytes`` copy per node. Rows are kept in the order they happen; a
node's rows stay in that order when the buffer is split by node (a stable sort).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from swarmbox.core.rows import MESSAGE_FIELDS

#: a packed ``messages`` row as a numpy record (little-endian, unpadded: the bytes ``struct`` packs)
_NUMPY = {"d": "<f8", "q": "<i8", "i": "<i4", "h": "<i2", "T": "<i4"}
MESSAGE_ROW = np.dtype([(name, _NUMPY[code]) for name, code in MESSAGE_FIELDS])


def take(records: np.ndarray, index: np.ndarray) -> np.ndarray:
    """``records[index]`` for a structured array, copied as whole records: numpy gathers an unaligned
    record dtype field by field, several times slower."""
    raw = records.view(np.dtype((np.void, records.dtype.itemsize)))
    return raw[index].view(records.dtype)


def concat(parts: list[np.ndarray]) -> np.ndarray:
    """The records of ``parts`` in order, copied as whole records (see :func:`take`)."""
    dtype = parts[0].dtype
    raw = np.dtype((np.void, dtype.itemsize))
    return np.concatenate([p.view(raw) for p in parts]).view(dtype)


def append_by_node(chunks: list[tuple[np.ndarray, np.ndarray]],
                   appenders: dict[int, Callable[[bytes], None]]) -> None:
    """Append the rows of ``chunks`` ((nodes, rows) pairs, in the order they happened) to each
    node's log: one ``bytes`` copy per node, a node's rows in their order (a stable sort)."""
    nodes = np.concatenate([c[0] for c in chunks])
    rows = concat([part for _, part in chunks])
    order = np.argsort(nodes, kind="stable")
    nodes, rows = nodes[order], take(rows, order)
    bounds = [0, *(np.flatnonzero(np.diff(nodes)) + 1).tolist(), len(nodes)]
    for k, node in enumerate(nodes[bounds[:-1]].tolist()):
        appenders[node](rows[bounds[k]:bounds[k + 1]].tobytes())


class MessageRows:
    """Buffered ``messages`` rows of every node, handed to the nodes' logs by :meth:`hand_over`."""

    def __init__(self, appenders: dict[int, Callable[[bytes], None]]) -> None:
        self._appenders = appenders      # node id -> its packed ``messages`` log (bytearray.extend)
        self._chunks: list[tuple[np.ndarray, np.ndarray]] = []   # (nodes, rows)
        self._single_nodes: list[int] = []
        self._single_rows: list[tuple] = []
        self.rows = 0

    def one(self, node: int, row: tuple) -> None:
        """One row (a message sent on its own): kept as a tuple until the next block or hand-over."""
        self._single_nodes.append(node)
        self._single_rows.append(row)

    def block(self, nodes: np.ndarray, columns: dict[str, object], n: int) -> None:
        """``n`` rows: ``nodes`` and one array (or scalar) per column of the row layout."""
        if not n:
            return
        self._settle()
        rows = np.empty(n, dtype=MESSAGE_ROW)
        for name in MESSAGE_ROW.names:
            rows[name] = columns[name]
        self._chunks.append((np.broadcast_to(np.asarray(nodes, dtype=np.int16), (n,)), rows))
        self.rows += n

    def add(self, nodes: np.ndarray, rows: np.ndarray) -> None:
        """Ready rows (``MESSAGE_ROW`` records), written by ``nodes``."""
        self._settle()
        self._chunks.append((nodes, rows))
        self.rows += len(rows)

    def _settle(self) -> None:
        if self._single_rows:
            rows = np.array(self._single_rows, dtype=MESSAGE_ROW)
            self._chunks.append((np.array(self._single_nodes, dtype=np.int16), rows))
            self.rows += len(rows)
            self._single_nodes, self._single_rows = [], []

    def hand_over(self) -> None:
        """Append every buffered row to its node's log, in order, and empty the buffer."""
        self._settle()
        if not self._chunks:
            return
        chunks, self._chunks, self.rows = self._chunks, [], 0
        append_by_node(chunks, self._appenders)
