"""State rows written as one fleet block per tick equal the rows each agent would log itself, and a
run's messages load the same from schema 1 (one send row per destination) and schema 2 files."""

from __future__ import annotations

import pandas as pd
import pyarrow.parquet as pq
import pytest

from swarmbox.analysis.load import load_run
from swarmbox.record.broadcast import expand_broadcasts

HOVER = ("algo=hover", "mission=hover", "algo.params.hover_s=2", "topology.peers=all")


def _crash_drone_1(swarm) -> None:
    """The vehicle of drone 1 crashes at 6 s but its node keeps running: frozen telemetry rows."""
    def crash(s) -> None:
        s.backend.crashed[1] = True
    swarm.schedule(6.0, crash)


def _per_agent_rows(swarm) -> None:
    _crash_drone_1(swarm)
    swarm.state_log = None
    for agent in swarm.agents:
        agent.own_state_rows = True


@pytest.mark.slow   # two runs: ~5 s on a quiet machine
def test_fleet_block_rows_equal_per_agent_rows(run):
    swarms = []

    def fleet(swarm) -> None:
        swarms.append(swarm)
        _crash_drone_1(swarm)

    _, block = run(*HOVER, prepare=fleet)
    assert swarms[0].state_log is not None   # the sim backend exports its arrays
    _, rows = run(*HOVER, prepare=_per_agent_rows)
    for drone in ("drone_0", "drone_1", "drone_3"):
        a = pq.read_table(block / "logs" / drone / "state.parquet")
        b = pq.read_table(rows / "logs" / drone / "state.parquet")
        assert a.schema.equals(b.schema, check_metadata=True)
        pd.testing.assert_frame_equal(a.to_pandas(), b.to_pandas())
    frozen = pq.read_table(block / "logs" / "drone_1" / "state.parquet").to_pandas()
    late = frozen[frozen["t_s"] > 7.0]
    assert len(late) and late["pos_d"].nunique() == 1   # the crashed vehicle's telemetry is frozen


def test_loader_reads_schema_1_and_2_messages_alike(run, tmp_path):
    _, run_dir = run(*HOVER)
    sends = pq.read_table(run_dir / "logs" / "ground" / "messages.parquet").to_pandas()
    assert (sends["dst"] == -4).any()        # heartbeats to all drones: one row each
    old = tmp_path / "v1"
    old.mkdir()
    for item in run_dir.iterdir():
        if item.is_file():
            (old / item.name).write_bytes(item.read_bytes())
    for path in (run_dir / "logs").rglob("*.parquet"):
        table = pq.read_table(path)
        if path.name == "messages.parquet":
            table = expand_broadcasts(table)
        meta = {**table.schema.metadata, b"swarmbox.schema": b"1"}
        target = old / path.relative_to(run_dir)
        target.parent.mkdir(parents=True, exist_ok=True)
        pq.write_table(table.replace_schema_metadata(meta), target)
    new, v1 = load_run(run_dir), load_run(old)
    assert not new.problems and not v1.problems
    for table in ("messages", "state", "events"):
        pd.testing.assert_frame_equal(new.tables[table], v1.tables[table])
    msgs = new.tables["messages"]
    assert not (msgs["dst"] == -4).any()
    assert len(msgs[(msgs["kind"] == "send") & (msgs["node"] == -1)]) > len(sends[sends["kind"] == "send"])
