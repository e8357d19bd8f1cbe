"""Buffered, atomic Parquet writers for per-node logs.

Nodes append plain tuples (the fastest thing Python can do in the tick loop); the recorder turns
them into columns and writes them as Parquet row groups in the background of the run — every
``flush_rows`` rows and at the end. A file is written as ``<table>.parquet.partial`` and renamed to
``<table>.parquet`` only once complete, so a reader never sees half a file under the final name;
on failure the run still closes (and renames) everything it has, so partial logs survive.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from swarmbox.record.schema import SCHEMA_VERSION, TABLES, node_name

_TYPES = {"float64": pa.float64(), "int64": pa.int64(), "int32": pa.int32(), "int16": pa.int16(),
          "int8": pa.int8(), "bool": pa.bool_(), "string": pa.string()}


def arrow_schema(table: str) -> pa.Schema:
    cols = TABLES[table]
    fields = [pa.field(c.name, _TYPES[c.dtype], metadata={"unit": c.unit, "doc": c.doc}) for c in cols]
    return pa.schema(fields, metadata={"swarmbox.schema": SCHEMA_VERSION, "swarmbox.table": table})


class _TableLog:
    __slots__ = ("path", "schema", "rows", "writer")

    def __init__(self, path: Path, table: str) -> None:
        self.path, self.schema = path, arrow_schema(table)
        self.rows: list[tuple] = []
        self.writer: pq.ParquetWriter | None = None

    def flush(self) -> None:
        if not self.rows and self.writer is not None:
            return
        if self.writer is None:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            self.writer = pq.ParquetWriter(_partial(self.path), self.schema, compression="zstd")
        cols = list(zip(*self.rows, strict=True)) if self.rows else [() for _ in self.schema]
        batch = pa.RecordBatch.from_arrays(
            [_column(c, f.type) for c, f in zip(cols, self.schema, strict=True)], schema=self.schema)
        self.writer.write_batch(batch)
        self.rows.clear()

    def close(self) -> None:
        self.flush()
        if self.writer is not None:
            self.writer.close()
            os.replace(_partial(self.path), self.path)
            self.writer = None


_NUMPY = {pa.float64(): np.float64, pa.int64(): np.int64, pa.int32(): np.int32, pa.int16(): np.int16,
          pa.int8(): np.int8}


def _column(values: Sequence, typ: pa.DataType) -> pa.Array:
    """One Arrow column built from raw buffers.

    (``pa.array`` on Python objects would import pandas, which an agent process must not load.)
    """
    n = len(values)
    if typ == pa.string():
        encoded = [v.encode() for v in values]
        offsets = np.zeros(n + 1, dtype=np.int32)
        np.cumsum([len(b) for b in encoded], out=offsets[1:])
        return pa.Array.from_buffers(typ, n, [None, pa.py_buffer(offsets), pa.py_buffer(b"".join(encoded))])
    if typ == pa.bool_():
        bits = np.packbits(np.asarray(values, dtype=bool), bitorder="little")
        return pa.Array.from_buffers(typ, n, [None, pa.py_buffer(bits)])
    return pa.Array.from_buffers(typ, n, [None, pa.py_buffer(np.asarray(values, dtype=_NUMPY[typ]))])


def _partial(path: Path) -> Path:
    return path.with_name(path.name + ".partial")


class NodeLog:
    """One node's tables. ``appender(table)`` returns a bound ``list.append`` for the hot path."""

    def __init__(self, root: Path, node_id: int, tables: tuple[str, ...]) -> None:
        self.node = node_name(node_id)
        self._tables = {t: _TableLog(root / self.node / f"{t}.parquet", t) for t in tables}

    def appender(self, table: str) -> Callable[[tuple], None]:
        # Flushing empties this same list in place, so the bound method stays valid.
        return self._tables[table].rows.append

    def pending_rows(self) -> int:
        return sum(len(t.rows) for t in self._tables.values())

    def flush(self) -> None:
        for t in self._tables.values():
            t.flush()

    def close(self) -> None:
        for t in self._tables.values():
            t.close()


GROUND_TABLES = ("messages", "stages", "events")
DRONE_TABLES = ("state", "messages", "stages", "events", "setpoints")
NET_TABLES = ("messages",)


class Recorder:
    """All node logs of one run, under ``<run>/logs/``."""

    def __init__(self, run_dir: Path, flush_rows: int = 2_000_000) -> None:
        self.root = Path(run_dir) / "logs"
        self.flush_rows = flush_rows
        self.logs: dict[int, NodeLog] = {}

    def node(self, node_id: int) -> NodeLog:
        if node_id not in self.logs:
            tables = GROUND_TABLES if node_id == -1 else NET_TABLES if node_id == -2 else DRONE_TABLES
            self.logs[node_id] = NodeLog(self.root, node_id, tables)
        return self.logs[node_id]

    def maybe_flush(self) -> None:
        """Write buffered rows out once they exceed ``flush_rows`` in total (bounds memory)."""
        if sum(log.pending_rows() for log in self.logs.values()) >= self.flush_rows:
            for log in self.logs.values():
                log.flush()

    def close(self) -> None:
        errors = []
        for log in self.logs.values():
            try:
                log.close()
            except Exception as exc:  # keep closing the others; report all at the end
                errors.append(f"{log.node}: {exc}")
        if errors:
            raise OSError("could not finish logs: " + "; ".join(errors))
