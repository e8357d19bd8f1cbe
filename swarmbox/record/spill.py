"""The spill of a run and its cut into per-node files (used by the recorder's thread or its process).

Chunks of rows (all nodes at once, each node's rows contiguous) become record batches with a ``node``
column: the first ``SpillFile.HOLD_BYTES`` of them are kept in memory, the rest appended as row groups
to a run-wide ``<run>/.spill/<table>.parquet``. At the end the spill and the rows still buffered are cut
into ``logs/<node>/<table>.parquet``: zero-copy slices, each file written as ``*.partial`` and renamed
once complete, so a reader never sees half a file under its final name.
"""

from __future__ import annotations

import os
import re
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
        #: per table, per entry of its layout: the batch held in memory, or the number of its row group
        #: in the spill file (None: not written, its loss already reported)
        self.held: dict[str, list[pa.RecordBatch | int | None]] = {}
        self._groups: dict[str, int] = {}   # row groups written per table
        self._held_bytes = 0

    def write(self, chunk: Chunk) -> None:
        """Encode ``chunk`` and keep it in memory or append it to the spill file."""
        data, spans = self.encode(chunk)
        slot = self.place(chunk.table, data, spans)
        if slot is not None:
            self.append_group(chunk.table, data, slot)

    @staticmethod
    def encode(chunk: Chunk) -> tuple[pa.RecordBatch, list[tuple[int, int, int]]]:
        """The chunk as one spill-schema record batch, and where each node's rows are in it."""
        node = np.repeat(np.asarray(chunk.nodes, np.int16), chunk.counts)
        offsets = np.concatenate([[0], np.cumsum(chunk.counts)[:-1]]).tolist()
        return chunk.batch(node), list(zip(chunk.nodes, offsets, chunk.counts, strict=True))

    def place(self, table: str, data: pa.RecordBatch, spans: list[tuple[int, int, int]]) -> int | None:
        """Take note of an encoded batch. It is held in memory (returns None) while the held batches
        stay under ``hold_bytes``; otherwise the caller appends it with :meth:`append_group` and the
        slot returned, after every earlier batch of the table."""
        nbytes = data.nbytes
        entries = self.held.setdefault(table, [])
        self.layout.setdefault(table, []).append(spans)
        if self._held_bytes + nbytes <= self.hold_bytes:
            self._held_bytes += nbytes
            entries.append(data)
            return None
        entries.append(None)   # the row group's number once written; None if the write failed
        return len(entries) - 1

    def append_group(self, table: str, data: pa.RecordBatch, slot: int) -> None:
        """Append a placed batch to the table's spill file as its next row group."""
        writer = self.writers.get(table)
        if writer is None:
            self.root.mkdir(parents=True, exist_ok=True)
            writer = pq.ParquetWriter(self.root / f"{table}.parquet", spill_schema(table),
                                      compression="lz4", use_dictionary=text_columns(table))
            self.writers[table] = writer
            self._groups[table] = 0
        writer.write_batch(data, row_group_size=len(data))
        self.held[table][slot] = self._groups[table]
        self._groups[table] += 1

    def close(self) -> None:
        for writer in self.writers.values():
            writer.close()
        self.writers.clear()


def split(spill: SpillFile, tails: Mapping[str, Chunk], root: Path,
          nodes: Mapping[int, Sequence[str]]) -> tuple[list[str], list[str]]:
    """Cut the (closed) spill's batches and buffered tails into ``<root>/<node>/<table>.parquet`` for
    every node and each of its tables (``nodes``: node id -> table names). Returns the files not
    written (``<node>/<table>.parquet``) and what went wrong."""
    errors: list[str] = []
    failed: list[str] = []
    causes: dict[str, list[str]] = {}   # cause -> the files it cost
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
            jobs = {f"{node_name(node)}/{table}.parquet": pool.submit(
                _write_node_file, root / node_name(node) / f"{table}.parquet", table, pieces.get(node, []))
                for node in owners}
            for name, job in jobs.items():
                if (exc := job.exception()) is not None:
                    failed.append(name)
                    causes.setdefault(_why(exc), []).append(name)
    errors += [f"{', '.join(names)} not written: {why}" for why, names in causes.items()]
    return failed, errors


def _why(exc: BaseException) -> str:
    """The cause in a few words: ``No space left on device``, ``File too large``."""
    text = exc.strerror if isinstance(exc, OSError) and exc.strerror else str(exc)
    found = re.search(r"\[errno \d+\] (.+)", text)
    return found.group(1).strip() if found else f"{type(exc).__name__}: {text}"


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
    on_disk = any(isinstance(h, int) for h in held_all)
    disk = pq.ParquetFile(spill.root / f"{table}.parquet") if on_disk else None
    for spans, held in zip(groups, held_all, strict=True):
        if held is None:   # its write failed (reported): its rows are lost, the others are not
            continue
        group = disk.read_row_group(held) if isinstance(held, int) else pa.Table.from_batches([held])
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
    try:
        pq.write_table(data, partial, compression="zstd", use_dictionary=text_columns(table))
    except BaseException:
        partial.unlink(missing_ok=True)   # half a file is never left behind, under any name
        raise
    os.replace(partial, path)
