"""Per-node logs of one run, written off the tick thread.

The tick loop only appends tuples to per-node lists. Once ``flush_rows`` rows are buffered (the
runner checks once per simulated second, so the check costs nothing per row) the recorder *hands the
lists over*: it copies their contents into one chunk per table and empties them, which is a pointer
copy. A background thread turns each chunk — all nodes at once — into one Arrow batch and appends it
as a row group to a run-wide spill file ``<run>/.spill/<table>.parquet`` (rows carry a ``node``
column). The loop never waits for disk, only for a full hand-over queue (bounded memory).

At the end the spill files are cut into the per-node layout of :mod:`swarmbox.record.schema`,
``logs/<node>/<table>.parquet``: each node's rows of a row group are contiguous (chunks are built
node by node), so the cut is zero-copy slicing. Every file is written as ``*.partial`` and renamed
once complete, so a reader never sees half a file under its final name; on failure the run still
closes everything it has, so partial logs survive.
"""

from __future__ import annotations

import os
import queue
import shutil
import threading
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from swarmbox.record.blocks import StateBlocks
from swarmbox.record.columns import NODE, arrow_schema, batch, numbers, spill_schema, text_columns
from swarmbox.record.schema import node_name

GROUND_TABLES = ("messages", "stages", "events")
DRONE_TABLES = ("state", "messages", "stages", "events", "setpoints")
NET_TABLES = ("messages",)
_ALL_TABLES = ("state", "messages", "stages", "events", "setpoints")


class NodeLog:
    """One node's tables. ``appender(table)`` returns a bound ``list.append`` for the hot path."""

    def __init__(self, node_id: int, tables: tuple[str, ...]) -> None:
        self.node_id, self.node = node_id, node_name(node_id)
        self.tables = tables
        self.rows: dict[str, list[tuple]] = {t: [] for t in tables}

    def appender(self, table: str) -> Callable[[tuple], None]:
        # Hand-overs empty this same list in place, so the bound method stays valid.
        return self.rows[table].append

    def pending_rows(self) -> int:
        return sum(map(len, self.rows.values()))


class _Chunk:
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


class _SpillWriter(threading.Thread):
    """Background thread: chunks in, Parquet row groups out; remembers where each node's rows went."""

    def __init__(self, root: Path, max_chunks: int) -> None:
        super().__init__(name="swarmbox-recorder", daemon=True)
        self.root = root
        self.inbox: queue.Queue[_Chunk | None] = queue.Queue(maxsize=max_chunks)
        self.writers: dict[str, pq.ParquetWriter] = {}
        #: table -> row group index -> [(node, offset, count)]
        self.layout: dict[str, list[list[tuple[int, int, int]]]] = {}
        self.errors: list[str] = []

    def run(self) -> None:
        while (chunk := self.inbox.get()) is not None:
            try:
                self._write(chunk)
            except Exception as exc:  # noqa: BLE001 - reported by close(); later chunks still written
                self.errors.append(f"{chunk.table} rows of nodes {chunk.nodes[:5]}...: "
                                   f"{type(exc).__name__}: {exc}")

    def _write(self, chunk: _Chunk) -> None:
        node = np.repeat(np.asarray(chunk.nodes, np.int16), chunk.counts)
        data = chunk.batch(node)
        writer = self.writers.get(chunk.table)
        if writer is None:
            self.root.mkdir(parents=True, exist_ok=True)
            writer = pq.ParquetWriter(self.root / f"{chunk.table}.parquet", spill_schema(chunk.table),
                                      compression="lz4", use_dictionary=text_columns(chunk.table))
            self.writers[chunk.table] = writer
        writer.write_batch(data, row_group_size=len(chunk))
        offsets = np.concatenate([[0], np.cumsum(chunk.counts)[:-1]]).tolist()
        self.layout.setdefault(chunk.table, []).append(
            [(n, o, c) for n, o, c in zip(chunk.nodes, offsets, chunk.counts, strict=True)])

    def finish(self) -> None:
        if self.is_alive():
            self.inbox.put(None)
            self.join()
        for writer in self.writers.values():
            writer.close()
        self.writers.clear()


class Recorder:
    """All node logs of one run, under ``<run>/logs/``."""

    #: Rows buffered before a hand-over. Small enough that a 20 s, 200-drone run already hands most
    #: of its rows over during the loop, as a long run does: the writer's share of the loop (it holds
    #: the GIL while it converts) is then the same whatever the run's length.
    FLUSH_ROWS = 100_000

    def __init__(self, run_dir: Path, flush_rows: int | None = None, max_chunks: int = 8) -> None:
        self.run_dir = Path(run_dir)
        self.root = self.run_dir / "logs"
        self.flush_rows = flush_rows or self.FLUSH_ROWS
        self.logs: dict[int, NodeLog] = {}
        self._spill = _SpillWriter(self.run_dir / ".spill", max_chunks)
        self._blocks = StateBlocks()

    def node(self, node_id: int) -> NodeLog:
        if node_id not in self.logs:
            tables = GROUND_TABLES if node_id == -1 else NET_TABLES if node_id == -2 else DRONE_TABLES
            self.logs[node_id] = NodeLog(node_id, tables)
        return self.logs[node_id]

    def maybe_flush(self) -> None:
        """Hand the buffers to the writer once they hold ``flush_rows`` rows."""
        if self.pending_rows() >= self.flush_rows:
            self.flush()

    def pending_rows(self) -> int:
        return sum(log.pending_rows() for log in self.logs.values()) + self._blocks.rows

    @property
    def state_blocks(self) -> StateBlocks:
        """The state rows' column buffers (``record.fleet.FleetStateLog`` writes straight into them)."""
        return self._blocks

    def state_block(self, nodes: np.ndarray, columns: list) -> None:
        """State rows of many drones at once: ``nodes`` and one array per column (schema order)."""
        self._blocks.add(nodes, columns)

    def flush(self) -> None:
        """Hand every buffered row to the background writer (the tick thread does no encoding)."""
        if not self._spill.is_alive():
            self._spill.start()
        for table in _ALL_TABLES:
            chunk = self._take(table)
            if chunk is not None:
                self._spill.inbox.put(chunk)

    def _take(self, table: str) -> _Chunk | None:
        """Empty every node's buffer of ``table`` into one chunk (copies pointers only)."""
        if table == "state" and self._blocks.rows:
            nodes, counts, data = self._blocks.take(self.logs)
            return _Chunk(table, nodes, counts, [], data)
        nodes, counts, flat = [], [], []
        for log in self.logs.values():
            rows = log.rows.get(table)
            if rows:
                nodes.append(log.node_id)
                counts.append(len(rows))
                flat.extend(rows)
                rows.clear()
        return _Chunk(table, nodes, counts, flat) if nodes else None

    def close(self) -> None:
        """Write everything out as per-node files; raise OSError naming what could not be written.

        Rows still buffered go straight from memory into the per-node files, not through the spill
        file: a short run never touches the spill at all.
        """
        tails = {t: c for t in _ALL_TABLES if (c := self._take(t)) is not None}
        self._spill.finish()
        errors = [f"log writer failed: {e}" for e in self._spill.errors]
        errors += _split(self._spill.root, self._spill.layout, tails, self.root, self.logs)
        if not errors:
            shutil.rmtree(self._spill.root, ignore_errors=True)
        if errors:
            raise OSError("could not finish logs: " + "; ".join(errors))


def _split(spill: Path, layout: dict[str, list[list[tuple[int, int, int]]]], tails: dict[str, _Chunk],
           root: Path, logs: dict[int, NodeLog]) -> list[str]:
    """Cut spill files and buffered tails into ``<root>/<node>/<table>.parquet`` (every expected file)."""
    errors: list[str] = []
    with ThreadPoolExecutor(max_workers=2) as pool:
        for table in _ALL_TABLES:
            owners = [log for log in logs.values() if table in log.tables]
            if not owners:
                continue
            pieces: dict[int, list[pa.Table]] = {}
            try:
                _spilled(spill / f"{table}.parquet", layout.get(table, []), pieces)
                if table in tails:
                    _buffered(tails[table], pieces)
            except Exception as exc:  # noqa: BLE001 - keep going: other tables may be fine
                errors.append(f"{table}: {type(exc).__name__}: {exc}")
            jobs = [pool.submit(_write_node_file, root / log.node / f"{table}.parquet", table,
                                pieces.get(log.node_id, [])) for log in owners]
            errors += [str(e) for e in (j.exception() for j in jobs) if e is not None]
    return errors


def _buffered(chunk: _Chunk, pieces: dict[int, list[pa.Table]]) -> None:
    data = pa.Table.from_batches([chunk.batch()])
    offset = 0
    for node, count in zip(chunk.nodes, chunk.counts, strict=True):
        pieces.setdefault(node, []).append(data.slice(offset, count))
        offset += count


def _spilled(path: Path, groups: list[list[tuple[int, int, int]]], pieces: dict[int, list[pa.Table]]) -> None:
    if not groups:
        return
    data = pq.ParquetFile(path)
    for index, spans in enumerate(groups):
        group = data.read_row_group(index).drop_columns(["node"])
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
