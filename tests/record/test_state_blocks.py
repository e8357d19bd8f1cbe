"""The columnar state buffer: rows written in place survive growth, mix with per-node tuple rows,
come out ordered by node then tick, and the hand-over owns its data (the buffers are reused)."""

from __future__ import annotations

import numpy as np
import pytest

from swarmbox.core.clock import ClockSpec, NodeClock, TimeSource, readings
from swarmbox.record.blocks import N_VALUES, StateBlocks
from swarmbox.record.writer import NodeLog


def _fill(blocks: StateBlocks, tick: int, nodes: list[int]) -> None:
    a, b = blocks.reserve(len(nodes))
    cols = blocks.columns
    blocks.nodes[a:b] = nodes
    cols[0][a:b] = [tick * 0.025 + 0.001 * n for n in nodes]
    cols[1][a:b] = tick
    cols[2][a:b] = 3
    cols[3][a:b] = [n % 2 == 0 for n in nodes]
    cols[4][a:b] = False
    cols[5][a:b] = ["OFFBOARD"] * len(nodes)
    blocks.values[:, a:b] = np.arange(N_VALUES)[:, None] + 100.0 * tick + np.array(nodes)[None, :]
    blocks.commit(b)


def test_rows_survive_growth_and_come_out_by_node_then_tick():
    blocks = StateBlocks(capacity=4)
    for tick in range(50):
        _fill(blocks, tick, [2, 0, 1])
    blocks.add(np.array([0, 1], dtype=np.int16),
               [np.array([9.0, 9.0]), [50, 50], [1, 1], [True, True], [True, True], ["HOLD", "HOLD"],
                *([[7.0, 8.0]] * N_VALUES)])
    assert blocks.rows == 152
    ids, counts, data = blocks.take({})
    assert ids == [0, 1, 2] and counts == [51, 51, 50]
    rows = data.to_pydict()
    assert rows["tick"][:51] == list(range(51)) and rows["tick"][51:102] == list(range(51))
    assert rows["mode"][50] == "HOLD" and rows["mode"][0] == "OFFBOARD"
    assert rows["pos_n"][3] == 300.0 and rows["pos_n"][51 + 3] == 301.0   # node 1 at tick 3
    assert rows["battery_frac"][51 + 50] == 8.0 and rows["armed"][:2] == [True, True]
    # taken rows are copies: refilling the buffers does not change them
    _fill(blocks, 99, [0, 1, 2])
    assert data.column("tick").to_pylist()[0] == 0 and blocks.rows == 3


def test_rows_reserved_but_never_filled_are_not_taken():
    """A Ctrl-C between reserving a tick's rows and filling them: the hand-over at the end holds the
    filled rows only (it once took the half-filled ones and failed on their None texts)."""
    blocks = StateBlocks(capacity=4)
    _fill(blocks, 0, [0, 1])
    blocks.reserve(2)                      # interrupted before the rows were written
    assert blocks.rows == 2
    ids, counts, data = blocks.take({})
    assert ids == [0, 1] and counts == [1, 1] and data.column("mode").to_pylist() == ["OFFBOARD"] * 2
    assert blocks.reserve(3) == (0, 3)     # the span is reused


def test_block_rows_and_per_node_tuples_merge():
    blocks = StateBlocks()
    _fill(blocks, 1, [0, 1])
    log = NodeLog(1, ("state",))
    log.appender("state")((0.0, 0, 2, False, True, "IDLE", *([0.5] * N_VALUES)))
    ids, counts, data = blocks.take({1: log})
    assert ids == [0, 1] and counts == [1, 2]
    assert data.column("tick").to_pylist() == [1, 0, 1]
    assert data.column("mode").to_pylist() == ["OFFBOARD", "IDLE", "OFFBOARD"]
    assert not log.rows["state"]


def test_add_rejects_a_short_block():
    with pytest.raises(ValueError, match="columns"):
        StateBlocks().add(np.array([0], dtype=np.int16), [[1.0]])


def test_readings_into_a_buffer_equal_each_clock():
    src = TimeSource()
    clocks = [NodeClock(src, ClockSpec(offset_s=0.1 * k, drift_ppm=37.0 * k)) for k in range(5)]
    clocks[3].skew(2.0, step_s=0.4, drift_ppm=-500.0)
    src.t_s = 12.345
    out = np.zeros(8)
    readings(clocks, src.t_s, out=out[2:7])
    assert out[2:7].tolist() == [c.now() for c in clocks]
    assert readings(clocks, src.t_s).tolist() == [c.now() for c in clocks]
