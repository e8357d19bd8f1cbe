"""A published Heartbeat: one send row for all subscribers (schema 2), expanded back per destination."""

from __future__ import annotations

import numpy as np
import pyarrow as pa

from swarmbox.core.clock import NodeClock, TimeSource
from swarmbox.core.messages import BROADCAST, Heartbeat
from swarmbox.core.rows import unpacking
from swarmbox.net.medium import LinkSpec, SimMedium
from swarmbox.record.broadcast import expand_broadcasts
from swarmbox.record.columns import batch

TICK = 0.025


def _net(default=LinkSpec()):
    time = TimeSource()
    drops: list[tuple] = []
    medium = SimMedium(time, np.random.default_rng(3), default, None, unpacking(drops))
    logs = {n: [] for n in (-1, 0, 1, 2)}
    inbox = {n: medium.register(n, NodeClock(time), unpacking(logs[n])) for n in logs}
    for n in (0, 1, 2):
        medium.subscribe(n, -1)
    return time, medium, logs, inbox, drops


def _tick(time, medium):
    time.tick += 1
    time.t_s = time.tick * TICK
    medium.deliver_due()


def _heartbeat(seq=1):
    return Heartbeat(seq, 0.0, -1, 1, (), (0.0, 0.0, 0.0), (0.0, 0.0, 0.0))


def test_one_send_row_per_published_heartbeat_and_one_recv_row_per_subscriber():
    time, medium, logs, inbox, _ = _net()
    medium.publish(_heartbeat())
    _tick(time, medium)
    assert [(r[2], r[6], r[9]) for r in logs[-1]] == [("send", BROADCAST, "0,1,2")]
    for n in (0, 1, 2):
        assert [(r[2], r[6]) for r in logs[n]] == [("recv", n)] and len(inbox[n]) == 1


def test_a_disconnected_subscriber_gets_a_drop_row_and_the_others_still_receive():
    time, medium, logs, inbox, drops = _net()
    medium.disconnect(1)
    medium.publish(_heartbeat())
    _tick(time, medium)
    assert [(r[6], r[9]) for r in drops] == [(1, "unreachable")]
    assert len(inbox[0]) == len(inbox[2]) == 1 and not inbox[1]
    assert logs[-1][0][6] == BROADCAST   # still logged once at the sender


def test_lossy_links_still_log_one_send_row_but_draw_per_destination():
    time, medium, logs, inbox, drops = _net(LinkSpec(loss_prob=0.5))
    for seq in range(1, 201):
        medium.publish(_heartbeat(seq))
    _tick(time, medium)
    assert len(logs[-1]) == 200
    received = sum(len(inbox[n]) for n in (0, 1, 2))
    assert received + len(drops) == 600 and 200 < received < 400


def test_expansion_gives_the_version_1_rows_in_order():
    time, medium, logs, _, _ = _net()
    medium.publish(_heartbeat())
    medium.send(_heartbeat(2)._replace(msg_id=2), 0)   # a direct send stays as it is
    table = pa.Table.from_batches([batch("messages", logs[-1])])
    out = expand_broadcasts(table)
    assert out.column("dst").to_pylist() == [0, 1, 2, 0]
    assert out.column("msg_id").to_pylist() == [1, 1, 1, 2]
    assert out.column("reason").to_pylist() == ["", "", "", ""]
    assert out.schema == table.schema
    assert expand_broadcasts(out).equals(out)   # version-1 rows pass through unchanged


def test_expanding_a_thousand_drone_broadcast_does_not_copy_its_destination_list():
    """600 broadcasts to 1,000 drones: copying each 4 KB list to every copy would need 2.4 GB of string
    data (past Arrow's 2 GB per array); the copies get an empty ``reason`` instead."""
    dsts = ",".join(map(str, range(1000)))
    n = 600
    table = pa.table({"kind": ["send"] * n, "dst": pa.array([BROADCAST] * n, pa.int16()),
                      "reason": [dsts] * n, "t_s": np.arange(n) * TICK})
    out = expand_broadcasts(table)
    assert len(out) == n * 1000
    assert out.column("dst").to_numpy()[:1000].tolist() == list(range(1000))
    assert set(out.column("reason").unique().to_pylist()) == {""}
