"""Packed rows (messages, setpoints): the bytes the tick loop appends decode to the rows a tuple gave."""

from __future__ import annotations

import math

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from swarmbox.core.rows import DROP, NO_TEXT, RECV, SEND, TEXTS, pack_message, pack_setpoint, unpack_row
from swarmbox.record.columns import arrow_schema, batch
from swarmbox.record.packed import packed_batch
from swarmbox.record.writer import Recorder


def _message_rows(n: int) -> list[tuple]:
    rng = np.random.default_rng(5)
    kinds, types = ("send", "recv", "drop"), ("report", "heartbeat", "task")
    reasons = ("", "", "", "loss", "0,1,2,7", "gnss_dropout é")   # free text, not only ASCII
    return [(float(rng.random() * 100), int(i), kinds[i % 3], (5 << 40) | i, types[i % 2 + (i % 5 == 0)],
             int(rng.integers(-3, 1000)), int(rng.integers(-4, 1000)), int(rng.integers(20, 4000)),
             float("nan") if i % 17 == 0 else float(rng.random() * 100), reasons[i % 6]) for i in range(n)]


def _pack(row: tuple) -> bytes:
    t, tick, kind, msg_id, typ, src, dst, nbytes, sent, reason = row
    return pack_message(t, tick, TEXTS.code(kind), msg_id, TEXTS.code(typ), src, dst, nbytes, sent,
                        TEXTS.code(reason))


def test_packed_messages_decode_to_the_batch_their_tuples_give():
    rows = _message_rows(500)
    packed = packed_batch("messages", b"".join(map(_pack, rows)))
    expected = batch("messages", rows)
    assert packed.schema.equals(arrow_schema("messages"), check_metadata=True)
    assert packed.to_pandas().equals(expected.to_pandas())   # NaN where NaN


def test_a_text_column_with_one_value_and_an_empty_hand_over():
    rows = [pack_setpoint(0.025 * i, i, TEXTS.code("position"), 1.0, 2.0, -3.0, math.nan, TEXTS.code("ok"),
                          NO_TEXT) for i in range(10)]
    data = packed_batch("setpoints", b"".join(rows))
    assert set(data.column("kind").to_pylist()) == {"position"}
    assert set(data.column("reason").to_pylist()) == {""}
    assert unpack_row("setpoints", rows[3])[:3] == (0.025 * 3, 3, "position")
    empty = packed_batch("setpoints", b"")
    assert empty.num_rows == 0 and empty.schema == arrow_schema("setpoints")


def test_a_recorder_writes_packed_rows_per_node_in_order(tmp_path):
    rec = Recorder(tmp_path, flush_rows=40)
    logs = {n: rec.node(n).appender("messages") for n in (-1, 0, 1)}
    sent = {n: [] for n in logs}
    for tick in range(100):
        for n, append in logs.items():
            kind = (SEND, RECV, DROP)[(tick + n) % 3]
            append(pack_message(tick * 0.025, tick, kind, tick, TEXTS.code("ack"), n, -1, 8, 0.0,
                                TEXTS.code(f"r{tick % 4}") if kind == DROP else NO_TEXT))
            sent[n].append((tick, kind))
        if tick % 10 == 0:
            rec.maybe_flush()
    rec.close()
    names = {n: "ground" if n == -1 else f"drone_{n}" for n in logs}
    for n, name in names.items():
        table = pq.read_table(tmp_path / "logs" / name / "messages.parquet")
        assert table.column("tick").to_pylist() == list(range(100))
        assert table.column("kind").to_pylist() == [TEXTS.texts[k] for _, k in sent[n]]
        drops = table.filter(pa.compute.equal(table.column("kind"), "drop"))
        assert drops.column("reason").to_pylist() == [f"r{t % 4}" for t, k in sent[n] if k == DROP]
