"""Per-node logs of one run: encoded in chunks during the loop, written to disk off the tick thread.

The tick loop only appends to per-node buffers: the ``messages`` and ``setpoints`` rows (several per
drone and tick) as rows packed by :mod:`swarmbox.core.rows` onto a ``bytearray``, the rare tables
(``stages``, ``events``) as tuples on a list, and a simulated fleet's ``state`` rows as numpy blocks
(:mod:`swarmbox.record.fleet`). Once ``flush_rows`` rows are buffered (the runner checks once per
simulated second, so the check costs nothing per row) the recorder *hands the buffers over*: one
chunk per table, all nodes at once. With ``writer="thread"`` (the default) the tick thread turns each
chunk into one Arrow batch — for packed rows a numpy view of the joined bytes, no per-row work; for
tuples a column-by-column conversion — kept in memory up to :attr:`SpillFile.HOLD_BYTES
<swarmbox.record.spill.SpillFile.HOLD_BYTES>`; beyond that a background thread appends the batches to
a run-wide spill file as row groups (Parquet encoding and I/O run with the interpreter lock released).
With ``writer="process"`` the tick thread serialises each chunk and a background thread pipes it to a
writer process that does the rest on another core (:mod:`swarmbox.record.worker`).

Why the tick thread encodes: a thread that takes the chunks while the loop runs has to win the
interpreter lock from it for every step of its work, and on a busy 2-core machine those hand-offs cost
more than the work itself. Why packed rows: turning millions of row tuples back into columns, cold in
the cache by the time of the hand-over, cost ~0.7 µs a row — a quarter of a 200-drone tick loop —
while packing a row costs what building the tuple did. Every chunk costs the same per row, so the
loop's cost per row, and its recorded real-time factor, do not depend on how long the run is. The loop
never waits for disk, only for a full hand-over queue (bounded memory).

At the end the spill files and the rows still buffered are cut into the per-node layout of
:mod:`swarmbox.record.schema`, ``logs/<node>/<table>.parquet`` (:mod:`swarmbox.record.spill`); a
short run never touches the spill at all. On failure the run still closes everything it has, so
partial logs survive; a chunk that cannot be encoded or written is named when the logs are closed.
"""

from __future__ import annotations

import logging
import queue
import shutil
import threading
from collections.abc import Callable
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np
import pyarrow as pa

from swarmbox.record.blocks import StateBlocks
from swarmbox.record.packed import PACKED, packed_batch, row_size
from swarmbox.record.schema import node_name
from swarmbox.record.spill import TABLES, Chunk, SpillFile, split
from swarmbox.record.worker import WriterProcess, WriterUnavailable

log = logging.getLogger(__name__)

GROUND_TABLES = ("messages", "stages", "events")
DRONE_TABLES = ("state", "messages", "stages", "events", "setpoints")
NET_TABLES = ("messages",)
#: where the rows are encoded: the recorder's thread, or a process of its own (another core)
WRITERS = ("thread", "process")


class NodeLog:
    """One node's tables. ``appender(table)`` returns a bound method for the hot path: ``list.append``
    of a row tuple, or for the packed tables (``messages``, ``setpoints``) ``bytearray.extend`` of a
    row packed by :mod:`swarmbox.core.rows`."""

    def __init__(self, node_id: int, tables: tuple[str, ...]) -> None:
        self.node_id, self.node = node_id, node_name(node_id)
        self.tables = tables
        self.rows: dict[str, list[tuple]] = {t: [] for t in tables if t not in PACKED}
        self.packed: dict[str, bytearray] = {t: bytearray() for t in tables if t in PACKED}

    def appender(self, table: str) -> Callable[[Any], None]:
        # Hand-overs empty this same list or bytearray in place, so the bound method stays valid.
        packed = self.packed.get(table)
        return packed.extend if packed is not None else self.rows[table].append

    def pending_rows(self) -> int:
        return sum(map(len, self.rows.values())) + sum(len(b) // row_size(t) for t, b in self.packed.items())


class _Group(NamedTuple):
    """An encoded batch bound for the spill file (thread writer): the next row group of ``table``."""

    table: str
    nodes: list[int]
    data: pa.RecordBatch
    slot: int


class _Packed(NamedTuple):
    """A chunk and its serialised message, bound for the writer process."""

    chunk: Chunk
    packed: bytes

    @property
    def table(self) -> str:
        return self.chunk.table

    @property
    def nodes(self) -> list[int]:
        return self.chunk.nodes


class _HandOver(threading.Thread):
    """Background thread: each item in its inbox goes to ``sink``; failures are kept for close()."""

    def __init__(self, sink: Callable[[Any], None], max_chunks: int) -> None:
        super().__init__(name="swarmbox-recorder", daemon=True)
        self.sink = sink
        self.inbox: queue.Queue[_Packed | _Group | None] = queue.Queue(maxsize=max_chunks)
        self.errors: list[str] = []

    def run(self) -> None:
        while (item := self.inbox.get()) is not None:
            try:
                self.sink(item)
            except Exception as exc:  # noqa: BLE001 - reported by close(); later chunks still written
                self.errors.append(f"{item.table} rows of nodes {item.nodes[:5]}...: "
                                   f"{type(exc).__name__}: {exc}")

    def finish(self) -> None:
        if self.is_alive():
            self.inbox.put(None)
            self.join()


class Recorder:
    """All node logs of one run, under ``<run>/logs/``."""

    #: Rows buffered before a hand-over. Small enough that a 20 s run of 36 drones (~6,000 rows per
    #: simulated second) already hands most of its rows over during the loop, as a long run does: the
    #: writer's share of the loop is then the same whatever the run's length (at 100,000 a 20 s,
    #: 36-drone run wrote nearly everything after its loop and looked 25 % faster than a 50 s one).
    FLUSH_ROWS = 20_000

    def __init__(self, run_dir: Path, flush_rows: int | None = None, max_chunks: int = 8,
                 writer: str = "thread") -> None:
        if writer not in WRITERS:
            raise ValueError(f"log writer must be one of {', '.join(WRITERS)}, got {writer!r}")
        self.run_dir = Path(run_dir)
        self.root = self.run_dir / "logs"
        self.flush_rows = flush_rows or self.FLUSH_ROWS
        self.logs: dict[int, NodeLog] = {}
        spill_root = self.run_dir / ".spill"
        self._spill = SpillFile(spill_root)
        self._process = WriterProcess(spill_root, self._spill.hold_bytes) if writer == "process" else None
        # the writer process is dropped on the background thread while the tick thread hands over
        self._swap = threading.Lock()
        # with a process: room for the rows of its start-up (~0.3 s: a tick loop must not wait for it)
        self._handover = _HandOver(self._sink, max_chunks * 8 if self._process else max_chunks)
        self._blocks = StateBlocks()
        self._unavailable = ""
        self._lost = ""                # the writer process died holding rows: they are lost
        self._errors: list[str] = []   # chunks this thread could not encode
        #: ``<node>/<table>.parquet`` files that could not be written (after :meth:`close`)
        self.not_written: list[str] = []

    @property
    def writer(self) -> str:
        """Where the rows are encoded: ``thread``, ``process``, or the thread after a failed start."""
        if self._unavailable:
            return f"thread (writer process unavailable: {self._unavailable})"
        if self._lost:
            return f"process, then thread ({self._lost})"
        return "process" if self._process is not None else "thread"

    def _sink(self, item: _Packed | _Group) -> None:
        """The hand-over thread's one sink: an encoded batch is appended to the spill file; a chunk
        for the writer process goes to it, or — when it cannot start or is gone — into this
        process's spill, as with ``writer="thread"``."""
        if isinstance(item, _Group):
            self._spill.append_group(item.table, item.data, item.slot)
            return
        with self._swap:
            proc = self._process
        if proc is not None:
            try:
                proc.send(item.chunk, item.packed)
                return
            except WriterUnavailable as exc:   # nothing was sent to it, nothing is lost
                self._drop_process(proc, unavailable=str(exc))
            except OSError as exc:             # it took chunks and died: those rows are lost
                self._drop_process(proc, lost=str(exc))
        self._spill.write(item.chunk)

    def _drop_process(self, proc: WriterProcess, unavailable: str = "", lost: str = "") -> None:
        log.warning("log writer process %s: rows are encoded by the run's own thread",
                    f"unavailable ({unavailable})" if unavailable else f"gone ({lost})")
        proc.kill()
        with self._swap:
            self._process = None
            self._unavailable, self._lost = unavailable, lost

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
        """Encode every buffered row (or serialise it for the writer process); what must go to disk
        goes to the background thread."""
        with self._swap:
            to_process = self._process is not None
        for table in TABLES:
            chunk = self._take(table)
            if chunk is None:
                continue
            item = _Packed(chunk, WriterProcess.pack(chunk)) if to_process else self._encode(chunk)
            if item is None:   # held in memory (or its failure noted): nothing for the background thread
                continue
            if not self._handover.is_alive():
                self._handover.start()
            self._handover.inbox.put(item)

    def _encode(self, chunk: Chunk) -> _Group | None:
        """Encode a chunk on this thread (see the module's notes) and keep it in memory (returns
        None), or return what the background thread must append to the spill file."""
        try:
            data, spans = self._spill.encode(chunk)
        except Exception as exc:  # noqa: BLE001 - reported by close(); later chunks still written
            self._errors.append(f"{chunk.table} rows of nodes {chunk.nodes[:5]}...: "
                                f"{type(exc).__name__}: {exc}")
            return None
        slot = self._spill.place(chunk.table, data, spans)
        return None if slot is None else _Group(chunk.table, chunk.nodes, data, slot)

    def _take(self, table: str) -> Chunk | None:
        """Empty every node's buffer of ``table`` into one chunk (copies pointers only)."""
        if table == "state" and self._blocks.rows:
            nodes, counts, data = self._blocks.take(self.logs)
            return Chunk(table, nodes, counts, [], data)
        if table in PACKED:
            return self._take_packed(table)
        nodes, counts, flat = [], [], []
        for log in self.logs.values():
            rows = log.rows.get(table)
            if rows:
                nodes.append(log.node_id)
                counts.append(len(rows))
                flat.extend(rows)
                rows.clear()
        return Chunk(table, nodes, counts, flat) if nodes else None

    def _take_packed(self, table: str) -> Chunk | None:
        """Empty every node's packed rows of ``table`` into one chunk, already a record batch."""
        size = row_size(table)
        nodes, counts, parts = [], [], []
        for log in self.logs.values():
            buf = log.packed.get(table)
            if buf:
                nodes.append(log.node_id)
                counts.append(len(buf) // size)
                parts.append(buf)
        if not nodes:
            return None
        data = packed_batch(table, b"".join(parts))   # a copy: the buffers can be emptied
        for buf in parts:
            del buf[:]
        return Chunk(table, nodes, counts, [], data)

    def close(self) -> None:
        """Write everything out as per-node files; raise OSError naming what could not be written
        (the files: :attr:`not_written`).

        Rows still buffered go straight from memory into the per-node files, not through the spill
        file (with a writer process: through the process, which holds the spilled rows' layout). If
        the process is gone, they are written here, with every row it had not taken.
        """
        tails = {t: c for t in TABLES if (c := self._take(t)) is not None}
        self._handover.finish()
        errors = [f"log writer failed: {e}" for e in self._errors + self._handover.errors]
        if self._lost:
            errors.append(f"log writer process gone ({self._lost}): the rows it had taken are lost")
        nodes = {log.node_id: log.tables for log in self.logs.values()}
        proc = self._process
        if proc is not None and proc.started:
            failed, more = proc.finish(list(tails.values()), nodes, self.root)
            errors += more
            if proc.broken:   # it died at the end: the tails at least, into the files it did not write
                missing = {n: [t for t in tables if not (self.root / node_name(n) / f"{t}.parquet").exists()]
                           for n, tables in nodes.items()}
                failed, more = split(self._spill, tails, self.root, missing)
                errors += more
        else:
            self._spill.close()
            failed, more = split(self._spill, tails, self.root, nodes)
            errors += more
        self.not_written = failed
        if not errors:
            shutil.rmtree(self._spill.root, ignore_errors=True)
        if errors:
            raise OSError("could not finish logs: " + "; ".join(errors))
