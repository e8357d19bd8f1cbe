"""The log writer process: same files as the writer thread, and a clear error if it dies."""

from __future__ import annotations

import time

import pyarrow.parquet as pq
import pytest

from swarmbox.record.spill import SpillFile
from swarmbox.record.writer import Recorder
from tests.conftest import run_config


def _tables(run_dir):
    files = sorted((run_dir / "logs").rglob("*.parquet"))
    return {p.relative_to(run_dir).as_posix(): pq.read_table(p) for p in files}


def test_a_run_logs_the_same_tables_whichever_writer_encodes_them(tmp_path, monkeypatch):
    # small hand-overs: most rows go through the spill file (the writer process's own, or the thread's)
    monkeypatch.setattr(Recorder, "FLUSH_ROWS", 3000)
    manifests, tables = {}, {}
    for writer in ("thread", "process"):
        run_dir = tmp_path / writer
        manifests[writer] = run_config(run_dir, ["algo=formation", "mission=formation",
                                                 f"run.log_writer={writer}"])
        tables[writer] = _tables(run_dir)
        assert not (run_dir / ".spill").exists()
    assert manifests["process"]["log_writer"] == "process" and manifests["thread"]["log_writer"] == "thread"
    assert manifests["process"]["status"] == manifests["thread"]["status"] == "ok"
    assert tables["process"].keys() == tables["thread"].keys()
    for name, table in tables["thread"].items():
        other = tables["process"][name]
        assert other.schema.equals(table.schema, check_metadata=True), name
        assert other.to_pandas().equals(table.to_pandas()), name   # NaN where NaN


def _stages(run_dir):
    return pq.read_table(run_dir / "logs" / "drone_0" / "stages.parquet").column("tick").to_pylist()


def test_a_writer_process_that_dies_fails_the_close_naming_it_and_the_tails_are_still_written(tmp_path):
    rec = Recorder(tmp_path, flush_rows=5, writer="process")
    append = rec.node(0).appender("stages")
    for tick in range(10):
        append((tick * 0.025, tick, 1, "ICEBREAK", ""))
    rec.flush()
    rec._handover.finish()   # the first chunk was sent: the process is up
    rec._process._proc.kill()
    rec._process._proc.wait()
    for tick in range(10, 14):   # buffered when the run ends: written by the run's own process
        append((tick * 0.025, tick, 1, "ICEBREAK", ""))
    with pytest.raises(OSError, match="log writer process failed"):
        rec.close()
    assert _stages(tmp_path) == [10, 11, 12, 13]


def test_a_chunk_sent_to_a_dead_writer_process_goes_to_the_thread_and_the_loss_is_named(tmp_path):
    """A hand-over after the process died: the rows the process had taken are lost (and said so),
    the later ones are written by the run's own process."""
    rec = Recorder(tmp_path, flush_rows=5, writer="process")
    append = rec.node(0).appender("stages")
    for tick in range(10):
        append((tick * 0.025, tick, 1, "ICEBREAK", ""))
    rec.flush()
    deadline = time.monotonic() + 30
    while not rec._process._sent and time.monotonic() < deadline:   # the first chunk reached it
        time.sleep(0.01)
    rec._process._proc.kill()
    rec._process._proc.wait()
    for tick in range(10, 20):
        append((tick * 0.025, tick, 1, "ICEBREAK", ""))
    rec.flush()
    for tick in range(20, 23):
        append((tick * 0.025, tick, 1, "ICEBREAK", ""))
    with pytest.raises(OSError, match="log writer process gone .*the rows it had taken are lost"):
        rec.close()
    assert rec.writer.startswith("process, then thread")
    assert _stages(tmp_path) == list(range(10, 23))


def test_a_writer_process_that_cannot_start_leaves_every_hand_over_to_the_thread(tmp_path, monkeypatch):
    """Past the hold size the thread's own hand-overs are encoded batches for the spill file: the
    one sink takes both kinds (it once took only chunks, and these rows were lost)."""
    monkeypatch.setattr("sys.executable", str(tmp_path / "no-such-python"))
    monkeypatch.setattr(SpillFile, "HOLD_BYTES", 0)   # every hand-over goes to the spill file
    rec = Recorder(tmp_path, flush_rows=5, writer="process")
    append = rec.node(0).appender("stages")
    for tick in range(5):
        append((tick * 0.025, tick, 1, "ICEBREAK", ""))
    rec.flush()
    deadline = time.monotonic() + 30
    while not rec.writer.startswith("thread (writer process unavailable"):   # it failed to start
        assert time.monotonic() < deadline
        time.sleep(0.01)
    for tick in range(5, 40):   # hand-overs encoded on this thread from now on
        append((tick * 0.025, tick, 1, "ICEBREAK", ""))
        rec.maybe_flush()
    rec.close()
    assert _stages(tmp_path) == list(range(40))


def test_a_short_run_never_starts_the_process(tmp_path):
    rec = Recorder(tmp_path, writer="process")
    rec.node(0).appender("stages")((0.0, 0, 1, "ICEBREAK", ""))
    rec.close()
    assert not rec._process.started
    assert pq.read_table(tmp_path / "logs" / "drone_0" / "stages.parquet").num_rows == 1


def test_a_writer_process_that_cannot_start_leaves_the_rows_to_the_thread(tmp_path, monkeypatch):
    monkeypatch.setattr("sys.executable", str(tmp_path / "no-such-python"))
    rec = Recorder(tmp_path, flush_rows=5, writer="process")
    append = rec.node(0).appender("stages")
    for tick in range(20):
        append((tick * 0.025, tick, 1, "ICEBREAK", ""))
        rec.maybe_flush()
    rec.close()
    assert rec.writer.startswith("thread (writer process unavailable: cannot start")
    ticks = pq.read_table(tmp_path / "logs" / "drone_0" / "stages.parquet").column("tick").to_pylist()
    assert ticks == list(range(20))
