"""The recorder: rows handed to the background writer mid-run come back per node, in order, intact."""

from __future__ import annotations

import math

import pyarrow.parquet as pq
import pytest

from swarmbox.core.rows import NO_TEXT, RECV, SEND, TEXTS, pack_message
from swarmbox.record.schema import SCHEMA_VERSION
from swarmbox.record.spill import SpillFile
from swarmbox.record.writer import WRITERS, Recorder


def _event(tick: int, node: int, name: str = "x") -> tuple:
    return (tick * 0.025, tick, "marker", name, node, "{}")


@pytest.mark.parametrize("hold_bytes", [0, 3000, None])   # every batch on disk, some, none
@pytest.mark.parametrize("writer", WRITERS)
def test_rows_split_per_node_in_order_across_many_handovers(tmp_path, monkeypatch, writer, hold_bytes):
    if hold_bytes is not None:
        monkeypatch.setattr(SpillFile, "HOLD_BYTES", hold_bytes)
    rec = Recorder(tmp_path, flush_rows=7, writer=writer)   # a hand-over every few ticks
    logs = {n: rec.node(n).appender("events") for n in (-1, 0, 1, 2)}
    for tick in range(50):
        for node, append in logs.items():
            if (tick + node) % 3:                   # uneven rows per node and per chunk
                append(_event(tick, node, name="é" if tick == 7 else "x"))
        rec.maybe_flush()
    rec.close()
    for node, name in ((-1, "ground"), (0, "drone_0"), (1, "drone_1"), (2, "drone_2")):
        table = pq.read_table(tmp_path / "logs" / name / "events.parquet")
        assert table.column("tick").to_pylist() == [t for t in range(50) if (t + node) % 3]
        assert set(table.column("subject").to_pylist()) == {node}
        assert table.schema.metadata[b"swarmbox.schema"] == SCHEMA_VERSION.encode()
        assert table.schema.field("t_s").metadata[b"unit"] == b"s"
        names = dict(zip(table.column("tick").to_pylist(), table.column("name").to_pylist(), strict=True))
        assert names.get(7, "é") == "é" and names.get(8, "x") == "x"   # non-ASCII text survives


@pytest.mark.parametrize("writer", WRITERS)
def test_every_expected_file_exists_even_without_rows_and_nothing_else_is_left(tmp_path, writer):
    rec = Recorder(tmp_path, writer=writer)
    rec.node(-1)
    rec.node(3).appender("state")(
        (0.0, 0, 1, False, True, "manual", *(0.0,) * 6, *(math.nan,) * 6, 0.0, 1.0))
    rec.node(-2)
    rec.close()
    logs = tmp_path / "logs"
    assert sorted(p.relative_to(logs).as_posix() for p in logs.rglob("*")) == sorted([
        "drone_3", "ground", "net", "ground/messages.parquet", "ground/stages.parquet",
        "ground/events.parquet", "net/messages.parquet",
        *(f"drone_3/{t}.parquet" for t in ("state", "messages", "stages", "events", "setpoints"))])
    assert pq.read_table(logs / "drone_3" / "state.parquet").num_rows == 1
    assert pq.read_table(logs / "ground" / "events.parquet").num_rows == 0
    assert not (tmp_path / ".spill").exists()


@pytest.mark.parametrize("writer", WRITERS)
def test_a_bad_row_fails_the_close_with_a_named_error_and_keeps_other_tables(tmp_path, writer):
    rec = Recorder(tmp_path, flush_rows=1, writer=writer)
    rec.node(0).appender("events")(("not a time", 0, "marker", "x", 0, "{}"))
    rec.node(0).appender("stages")((0.0, 0, 1, "ICEBREAK", ""))
    rec.maybe_flush()
    with pytest.raises(OSError, match="log writer failed"):
        rec.close()
    assert pq.read_table(tmp_path / "logs" / "drone_0" / "stages.parquet").num_rows == 1
    assert pq.read_table(tmp_path / "logs" / "drone_0" / "events.parquet").num_rows == 0


@pytest.mark.parametrize("writer", WRITERS)
def test_only_text_columns_are_dictionary_encoded(tmp_path, monkeypatch, writer):
    """Numbers (times, positions) rarely repeat: a dictionary tried on them first doubles a write's
    cost and bloats the file; text columns (kind, type, mode) compress far better with one."""
    monkeypatch.setattr(SpillFile, "HOLD_BYTES", 0)
    rec = Recorder(tmp_path, flush_rows=50, writer=writer)   # rows via the spill file and from memory
    append = rec.node(0).appender("messages")
    for tick in range(400):
        append(pack_message(tick * 0.025, tick, SEND if tick % 2 else RECV, tick, TEXTS.code("report"), 0, -1,
                            120, tick * 0.025 - 0.01, NO_TEXT))
        if tick == 200:
            rec.flush()
    rec.close()
    meta = pq.ParquetFile(tmp_path / "logs" / "drone_0" / "messages.parquet").metadata
    for group in range(meta.num_row_groups):
        for i in range(meta.num_columns):
            chunk = meta.row_group(group).column(i)
            dictionary = any("DICTIONARY" in e for e in chunk.encodings)
            assert dictionary == (chunk.path_in_schema in ("kind", "type", "reason")), chunk.path_in_schema


def test_a_failed_spill_write_loses_only_its_own_rows_and_is_named(tmp_path, monkeypatch):
    """Beyond the memory hold, the thread appends batches to the spill file; one failing append (a full
    disk) is reported at close, and every other hand-over's rows still reach the per-node files."""
    monkeypatch.setattr(SpillFile, "HOLD_BYTES", 0)
    real, calls = SpillFile.append_group, []

    def flaky(self, table, data, slot):
        calls.append(slot)
        if len(calls) == 2:
            raise OSError("No space left on device")
        real(self, table, data, slot)

    monkeypatch.setattr(SpillFile, "append_group", flaky)
    rec = Recorder(tmp_path, flush_rows=4, writer="thread")
    append = rec.node(0).appender("events")
    for tick in range(12):
        append(_event(tick, 0))
        rec.maybe_flush()   # hand-overs of ticks 0-3, 4-7, 8-11
    with pytest.raises(OSError, match="events rows of nodes \\[0\\].*No space left on device"):
        rec.close()
    assert len(calls) == 3
    table = pq.read_table(tmp_path / "logs" / "drone_0" / "events.parquet")
    assert table.column("tick").to_pylist() == [0, 1, 2, 3, 8, 9, 10, 11]
