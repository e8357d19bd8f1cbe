"""Throughput benchmarks with a committed baseline (``.ci/bench.sh`` compares against it).

Each entry times one stage that must stay flat per drone as swarms grow: the whole hover run
(tick loop + log writing), the recorder alone (state rows; packed message rows), the k-d tree
separation at 1,000 drones, and the analysis of a 36-drone run. ``extra_info`` carries throughput
figures (agent-steps/s, rows/s). Without ``--benchmark-enable`` each runs once, as an ordinary (fast)
test of its result.

Baseline: ``tests/bench/baseline/`` (``.ci/bench.sh --update-baseline`` after an intended change).
"""

from __future__ import annotations

import numpy as np
import pytest

from swarmbox.analysis import metrics
from swarmbox.analysis.report import analyze_run
from swarmbox.bench.hover import hover_run
from swarmbox.core.rows import NO_TEXT, RECV, SEND, TEXTS, pack_message
from swarmbox.record.writer import Recorder


def test_hover_36_drones_run(benchmark, tmp_path_factory):
    def run():
        return hover_run(36, 1.0, tmp_path_factory.mktemp("hover36") / "run")

    m = benchmark.pedantic(run, rounds=3, iterations=1)
    assert m["status"] == "ok", m["reason"]
    benchmark.extra_info.update(rtf=round(m["real_time_factor"], 2),
                                agent_steps_per_s=round(36 * m["ticks"] / m["wall_time_s"]))


def _fill(recorder: Recorder, drones: int, ticks: int) -> int:
    appenders = [recorder.node(d).appender("state") for d in range(drones)]
    row = (0.0, 0, 3, True, False, "offboard", *(1.0,) * 12, 0.0, 1.0)
    for tick in range(ticks):
        for append in appenders:
            append(row[:1] + (tick,) + row[2:])
        recorder.maybe_flush()
    return drones * ticks


def test_recorder_200_drones(benchmark, tmp_path_factory):
    def write():
        run_dir = tmp_path_factory.mktemp("rec")
        recorder = Recorder(run_dir, flush_rows=20_000)
        rows = _fill(recorder, 200, 400)
        recorder.close()
        return run_dir, rows

    run_dir, rows = benchmark.pedantic(write, rounds=3, iterations=1)
    import pyarrow.parquet as pq

    ticks = pq.read_table(run_dir / "logs" / "drone_199" / "state.parquet", columns=["tick"])["tick"]
    assert ticks.to_pylist() == list(range(400))
    benchmark.extra_info.update(rows=rows)


def test_recorder_messages_200_drones(benchmark, tmp_path_factory):
    """The tick loop's busiest rows: per drone and tick a Report sent and received and a Heartbeat
    received, packed as the medium writes them, handed over and written per node."""
    report, heartbeat = TEXTS.code("report"), TEXTS.code("heartbeat")

    def write():
        run_dir = tmp_path_factory.mktemp("msg")
        recorder = Recorder(run_dir, flush_rows=20_000)
        ground = recorder.node(-1).appender("messages")
        drones = [recorder.node(d).appender("messages") for d in range(200)]
        for tick in range(400):
            t = tick * 0.025
            for d, append in enumerate(drones):
                msg_id = ((d + 2) << 40) | tick
                append(pack_message(t, tick, SEND, msg_id, report, d, -1, 120, t, NO_TEXT))
                ground(pack_message(t + 0.025, tick + 1, RECV, msg_id, report, d, -1, 120, t, NO_TEXT))
                append(pack_message(t, tick, RECV, tick, heartbeat, -1, d, 40, t, NO_TEXT))
            if tick % 40 == 0:
                recorder.maybe_flush()
        recorder.close()
        return run_dir

    run_dir = benchmark.pedantic(write, rounds=3, iterations=1)
    import pyarrow.parquet as pq

    ground = pq.read_table(run_dir / "logs" / "ground" / "messages.parquet", columns=["src", "kind"])
    assert ground.num_rows == 200 * 400 and set(ground.column("kind").to_pylist()) == {"recv"}
    benchmark.extra_info.update(rows=3 * 200 * 400)


def test_separation_1000_drones(benchmark):
    rng = np.random.default_rng(0)
    n, ticks = 1000, 20
    pos = rng.uniform(0, 150, size=(n * ticks, 3))
    import pandas as pd

    state = pd.DataFrame({"node": np.repeat(np.arange(n), ticks), "tick": np.tile(np.arange(ticks), n),
                          "true_n": pos[:, 0], "true_e": pos[:, 1], "true_d": pos[:, 2],
                          "pos_n": pos[:, 0], "pos_e": pos[:, 1], "pos_d": pos[:, 2]})
    sep = benchmark(metrics.separation_by_tick, state, list(range(n)))
    assert len(sep) == ticks and (sep > 0).all()


@pytest.fixture(scope="module")
def run36(tmp_path_factory):
    path = tmp_path_factory.mktemp("an36") / "run"
    assert hover_run(36, 1.0, path)["status"] == "ok"
    return path


def test_analyze_36_drone_run(benchmark, run36):
    analysis = benchmark.pedantic(analyze_run, args=(run36,), rounds=3, iterations=1)
    assert analysis.scalars["n_drones"] == 36
    assert analysis.scalars["min_separation_m"] == pytest.approx(5.0, abs=0.5)   # 5 m grid, hovering
