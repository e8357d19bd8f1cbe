"""The spill of a run and its cut into per-node files (used by the recorder's thread or its process).

Chunks of rows (all nodes at once, each node's rows contiguous) become record batches with a ``node``
column: the first ``SpillFile.HOLD_BYTES`` of them are kept in memory, the rest appended as row groups
to a run-wide ``<run>/.spill/<table>.parquet``. At the end the spill and the rows still buffered are cut
into ``logs/<node>/<table>.parquet``: zero-copy slices, each file written as ``*.partial`` and renamed
once complete, so a reader never sees half a file under its final name.
"""

from __future__ import annotations

import os
from collections.abc import Mapping, Sequence
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from swarmbox.record.columns import NODE, arrow_schema, batch, numbers, spill_schema, text_columns
from swarmbox.record.schema import node_name

TABLES = ("state", "messages", "stages", "events", "setpoints")
#: where each node's rows of each row group went: table -> row group -> [(node, offset, count)]
Layout = dict[str, list[list[tuple[int, int, int]]]]


class Chunk:
    """One hand-over of one table: the nodes in order and their rows, concatenated (as tuples, or
    already as a record batch)."""

    __slots__ = ("table", "nodes", "counts", "rows", "data")

    def __init__(self, table: str, nodes: list[int], counts: list[int], rows: list[tuple],
                 data: pa.RecordBatch | None = None) -> None:
        self.table, self.nodes, self.counts, self.rows = table, nodes, counts, rows
        self.data = data

    def batch(self, node: np.ndarray | None = None) -> pa.RecordBatch:
        """The rows as a record batch; with ``node``, in the spill schema."""
        if self.data is None:
            return batch(self.table, self.rows, node)
        if node is None:
            return self.data
        return pa.RecordBatch.from_arrays([*self.data.columns, numbers(node, NODE.type)],
                                          schema=spill_schema(self.table))

    def __len__(self) -> int:
        return sum(self.counts)


class SpillFile:
    """Chunks in, row groups out; remembers where each node's rows went.

    The first ``hold_bytes`` of record batches stay in memory (a short or small run never writes and
    reads back a spill file); the rest are appended to the spill file as row groups.
    """

    HOLD_BYTES = 128 << 20

    def __init__(self, root: Path, hold_bytes: int | None = None) -> None:
        self.root = root
        self.hold_bytes = self.HOLD_BYTES if hold_bytes is None else hold_bytes
        self.writers: dict[str, pq.ParquetWriter] = {}
        self.layout: Layout = {}
        #: per table, per entry of its layout: the batch held in memory, or None (next row group on disk)
        self.held: dict[str, list[pa.RecordBatch | None]] = {}
        self._held_bytes = 0

    def write(self, chunk: Chunk) -> None:
        node = np.repeat(np.asarray(chunk.nodes, np.int16), chunk.counts)
        data = chunk.batch(node)
        if self._held_bytes + data.nbytes <= self.hold_bytes:
            self._held_bytes += data.nbytes
            self.held.setdefault(chunk.table, []).append(data)
        else:
            self._spill(chunk.table, data)
            self.held.setdefault(chunk.table, []).append(None)
        offsets = np.concatenate([[0], np.cumsum(chunk.counts)[:-1]]).tolist()
        self.layout.setdefault(chunk.table, []).append(
            [(n, o, c) for n, o, c in zip(chunk.nodes, offsets, chunk.counts, strict=True)])

    def _spill(self, table: str, data: pa.RecordBatch) -> None:
        writer = self.writers.get(table)
        if writer is None:
            self.root.mkdir(parents=True, exist_ok=True)
            writer = pq.ParquetWriter(self.root / f"{table}.parquet", spill_schema(table),
                                      compression="lz4", use_dictionary=text_columns(table))
            self.writers[table] = writer
        writer.write_batch(data, row_group_size=len(data))

    def close(self) -> None:
        for writer in self.writers.values():
            writer.close()
        self.writers.clear()


def split(spill: SpillFile, tails: Mapping[str, Chunk], root: Path,
          nodes: Mapping[int, Sequence[str]]) -> list[str]:
    """Cut the (closed) spill's batches and buffered tails into ``<root>/<node>/<table>.parquet`` for
    every node and each of its tables (``nodes``: node id -> table names); returns what could not be
    written."""
    errors: list[str] = []
    with ThreadPoolExecutor(max_workers=2) as pool:
        for table in TABLES:
            owners = [node for node, tables in nodes.items() if table in tables]
            if not owners:
                continue
            pieces: dict[int, list[pa.Table]] = {}
            try:
                _spilled(spill, table, pieces)
                if table in tails:
                    _buffered(tails[table], pieces)
            except Exception as exc:  # noqa: BLE001 - keep going: other tables may be fine
                errors.append(f"{table}: {type(exc).__name__}: {exc}")
            jobs = [pool.submit(_write_node_file, root / node_name(node) / f"{table}.parquet", table,
                                pieces.get(node, [])) for node in owners]
            errors += [str(e) for e in (j.exception() for j in jobs) if e is not None]
    return errors


def _buffered(chunk: Chunk, pieces: dict[int, list[pa.Table]]) -> None:
    data = pa.Table.from_batches([chunk.batch()])
    offset = 0
    for node, count in zip(chunk.nodes, chunk.counts, strict=True):
        pieces.setdefault(node, []).append(data.slice(offset, count))
        offset += count


def _spilled(spill: SpillFile, table: str, pieces: dict[int, list[pa.Table]]) -> None:
    groups = spill.layout.get(table, [])
    if not groups:
        return
    held_all = spill.held[table]
    disk = None if all(h is not None for h in held_all) else pq.ParquetFile(spill.root / f"{table}.parquet")
    on_disk = 0
    for spans, held in zip(groups, held_all, strict=True):
        if held is None:
            group = disk.read_row_group(on_disk)
            on_disk += 1
        else:
            group = pa.Table.from_batches([held])
        group = group.drop_columns(["node"])
        for node, offset, count in spans:
            pieces.setdefault(node, []).append(group.slice(offset, count))


def _write_node_file(path: Path, table: str, pieces: list[pa.Table]) -> None:
    schema = arrow_schema(table)
    # an empty table from no batches: Schema.empty_table() would import pandas into the runner
    data = pa.concat_tables(pieces).replace_schema_metadata(schema.metadata) if pieces else \
        pa.Table.from_batches([], schema=schema)
    data = data.cast(schema)
    path.parent.mkdir(parents=True, exist_ok=True)
    partial = path.with_name(path.name + ".partial")
    pq.write_table(data, partial, compression="zstd", use_dictionary=text_columns(table))
    os.replace(partial, path)
