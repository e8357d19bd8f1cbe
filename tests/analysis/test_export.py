"""Replay exports of the default mission, read back with the MCAP and Rerun libraries' own readers:
topics and entities, message counts, and a time range equal to the run's."""

from __future__ import annotations

import subprocess
import sys
from collections import Counter
from datetime import datetime
from pathlib import Path

import pandas as pd
import pytest

from swarmbox.analysis.export import export_main
from tests.conftest import ROOT, run_config

# The replay extra (Rerun, MCAP): not in the test extra; CI runs these in its '.[test,replay]' venv.
rrc = pytest.importorskip("rerun.chunk", reason="needs the replay extra: pip install -e '.[test,replay]'")
make_reader = pytest.importorskip("mcap.reader").make_reader
DecoderFactory = pytest.importorskip("mcap_protobuf.decoder").DecoderFactory
pytest.importorskip("foxglove_schemas_protobuf")
pytestmark = pytest.mark.replay

NS = 1_000_000_000


@pytest.fixture(scope="module")
def default_run(tmp_path_factory):
    run_dir = tmp_path_factory.mktemp("export") / "run"
    manifest = run_config(run_dir, [])
    assert manifest["status"] == "ok"
    return run_dir, manifest


def _logs(run_dir: Path, table: str) -> pd.DataFrame:
    frames = [pd.read_parquet(p).assign(node=p.parent.name)
              for p in sorted((run_dir / "logs").glob(f"*/{table}.parquet"))]
    return pd.concat(frames, ignore_index=True)


def _export(run_dir: Path, *args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "swarmbox.export", str(run_dir), *args], cwd=ROOT,
                          capture_output=True, text=True, timeout=120, check=False)


def _run_span(run_dir: Path) -> tuple[float, float]:
    times = pd.concat([_logs(run_dir, t)["t_s"] for t in ("state", "stages", "events", "setpoints")])
    return float(times.min()), float(times.max())


@pytest.mark.slow
def test_mcap_and_rerun_exports_of_the_default_mission(default_run):
    run_dir, manifest = default_run
    done = _export(run_dir)
    assert done.returncode == 0, done.stderr
    state, stages, events = _logs(run_dir, "state"), _logs(run_dir, "stages"), _logs(run_dir, "events")
    setpoints = _logs(run_dir, "setpoints")
    t0, t1 = _run_span(run_dir)
    start_ns = int(datetime.fromisoformat(manifest["started_at"]).timestamp()) * NS

    with open(run_dir / "replay" / "run.mcap", "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        summary = reader.get_summary()
        counts = {summary.channels[c].topic: n for c, n in summary.statistics.channel_message_counts.items()}
        assert summary.statistics.message_start_time == start_ns + round(t0 * NS)
        assert summary.statistics.message_end_time == start_ns + round(t1 * NS)
        schemas = {summary.channels[c].topic: summary.schemas[summary.channels[c].schema_id].name
                   for c in summary.channels}
        first_pose = next(m for _, _, _, m in reader.iter_decoded_messages(topics=["/drone_2/pose"]))
    for node, n in state.groupby("node").size().items():
        assert counts[f"/{node}/pose"] == counts[f"/{node}/state"] == n
        assert schemas[f"/{node}/pose"] == "foxglove.PoseInFrame"
    for node, n in setpoints.groupby("node").size().items():
        assert counts[f"/{node}/setpoint"] == n
    assert counts["/stages"] == len(stages) and counts["/events"] == len(events)
    assert schemas["/links"] == "foxglove.SceneUpdate" and schemas["/events"] == "foxglove.Log"
    assert {f"/link/ground_drone_{i}" for i in range(4)} <= set(counts)
    assert {f"/drone_{i}/metrics" for i in range(4)} <= set(counts)
    first = state[state["node"] == "drone_2"].iloc[0]      # ENU: x east, y north, z up
    assert first_pose.pose.position.x == pytest.approx(first["pos_e"])
    assert first_pose.pose.position.y == pytest.approx(first["pos_n"])

    store = rrc.RrdReader(run_dir / "replay" / "run.rrd").store()
    rows: Counter = Counter()
    times: list[pd.Series] = []
    for chunk in store.stream():
        if not chunk.is_static:
            rows[chunk.entity_path] += chunk.num_rows
            times.append(chunk.to_record_batch().column("run_time").to_pandas())
    for node, n in state.groupby("node").size().items():
        assert rows[f"/world/drones/{node.split('_')[1]}"] == n
    assert rows["/stages"] == len(stages) and rows["/events"] == len(events)
    assert {f"/metrics/latency_ms/drone_{i}" for i in range(4)} <= set(rows)
    assert {f"/world/links/ground_drone_{i}" for i in range(4)} <= set(rows)
    all_t = pd.concat(times).dt.total_seconds()
    assert all_t.min() == pytest.approx(t0, abs=1e-9) and all_t.max() == pytest.approx(t1, abs=1e-9)


def test_a_time_window_and_bad_input(default_run, capsys):
    run_dir, _ = default_run
    assert export_main([str(run_dir), "--format", "mcap", "--from", "10", "--to", "20"]) == 0
    state = _logs(run_dir, "state")
    inside = state[(state["t_s"] >= 10) & (state["t_s"] <= 20)]
    with open(run_dir / "replay" / "run_10-20.mcap", "rb") as f:
        stats = make_reader(f).get_summary()
    counts = {stats.channels[c].topic: n for c, n in stats.statistics.channel_message_counts.items()}
    assert counts["/drone_0/pose"] == (inside["node"] == "drone_0").sum()
    span_s = (stats.statistics.message_end_time - stats.statistics.message_start_time) / NS
    assert 9.9 < span_s <= 10.0
    assert export_main([str(run_dir), "--format", "mcap", "--from", "10", "--to", "20"]) == 2
    assert "already exists" in capsys.readouterr().err
    assert export_main([str(run_dir), "--from", "5000", "-o", str(run_dir / "late")]) == 2
    assert "empty window" in capsys.readouterr().err
