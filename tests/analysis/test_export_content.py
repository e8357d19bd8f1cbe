"""What the replay exports show, checked against a run whose network is known: every link has
50 ms of latency and drone 3's radio is cut at 14 s. Read back with the MCAP and Rerun readers:

- links are lines coloured by their latency (50 ms: yellow; nothing delivered: grey), in both files;
- the per-drone metric series carry the latency and loss the network was set to;
- the mission's markers and the fault are events, with their levels;
- a time window of the Rerun recording covers exactly the window's records.
"""

from __future__ import annotations

import json
from collections import defaultdict

import numpy as np
import pandas as pd
import pytest

from swarmbox.analysis.export import export_main
from tests.conftest import run_config

# The replay extra (Rerun, MCAP): not in the test extra; CI runs these in its '.[test,replay]' venv.
rrc = pytest.importorskip("rerun.chunk", reason="needs the replay extra: pip install -e '.[test,replay]'")
make_reader = pytest.importorskip("mcap.reader").make_reader
DecoderFactory = pytest.importorskip("mcap_protobuf.decoder").DecoderFactory
pytest.importorskip("foxglove_schemas_protobuf")

pytestmark = [pytest.mark.slow, pytest.mark.replay]   # one simulated run and both exports: about 10 s

CUT_S = 14.0
YELLOW, GREY = (1.0, 1.0, 0.0), (0.5, 0.5, 0.5)


@pytest.fixture(scope="module")
def exported(tmp_path_factory):
    run_dir = tmp_path_factory.mktemp("export_content") / "run"
    manifest = run_config(run_dir, ["algo=crossing", "mission=crossing", "run.proximity_m=10",
                                    "network.latency_ms=50", "fault=link_cut", "fault.targets=[3]",
                                    f"fault.onset_s={CUT_S}"])
    assert manifest["status"] == "ok", manifest["reason"]
    assert export_main([str(run_dir)]) == 0
    return run_dir


def _mcap(run_dir):
    protobuf = DecoderFactory()
    with open(run_dir / "replay" / "run.mcap", "rb") as f:
        for schema, channel, message in make_reader(f).iter_messages():
            if channel.message_encoding == "json":
                yield channel.topic, message.log_time, json.loads(message.data)
            else:
                yield channel.topic, message.log_time, protobuf.decoder_for("protobuf", schema)(message.data)


def _rrd(run_dir, name="run.rrd") -> dict[str, pd.DataFrame]:
    out: dict[str, list] = defaultdict(list)
    for chunk in rrc.RrdReader(run_dir / "replay" / name).store().stream():
        if not chunk.is_static:
            out[chunk.entity_path].append(chunk.to_record_batch().to_pandas())
    return {k: pd.concat(v, ignore_index=True) for k, v in out.items()}


def _rgb(packed: int) -> tuple[float, ...]:
    return tuple(round(((packed >> s) & 0xFF) / 255, 2) for s in (24, 16, 8))


def test_links_are_coloured_by_latency_in_both_exports(exported):
    t0 = None
    lines: dict[int, list] = defaultdict(list)
    latency: dict[int, list] = defaultdict(list)
    for topic, t_ns, msg in _mcap(exported):
        if topic == "/links":
            t0 = t_ns if t0 is None else min(t0, t_ns)
            lines[t_ns] += [tuple(round(c, 2) for c in (ln.color.r, ln.color.g, ln.color.b))
                            for ln in msg.entities[0].lines]
        elif topic.startswith("/link/"):
            latency[t_ns].append(msg["latency_ms"])
    assert lines and set(lines) == set(latency)
    colours = set()
    for t_ns, got in lines.items():
        expect = [YELLOW if lat is not None and abs(lat - 50) < 1e-6 else GREY for lat in latency[t_ns]]
        assert sorted(got) == sorted(expect), t_ns
        colours |= set(got)
    assert colours == {YELLOW, GREY}     # grey: drone 3's link after the cut
    rrd = _rrd(exported)
    for name in ("ground_drone_3", "drone_3_ground", "drone_0_ground"):
        link = rrd[f"/world/links/{name}"]
        t = link["run_time"].dt.total_seconds()
        rgb = [_rgb(c[0]) for c in link["LineStrips3D:colors"]]
        assert all(c == YELLOW for c, s in zip(rgb, t, strict=True) if s < CUT_S - 0.5), name
        after = {c for c, s in zip(rgb, t, strict=True) if s > CUT_S + 1}
        assert after == ({GREY} if "3" in name else {YELLOW}), name


def test_per_drone_metric_series_carry_the_network(exported):
    series = defaultdict(list)
    for topic, _, msg in _mcap(exported):
        if topic.endswith("/metrics"):
            series[topic].append(msg)
    assert set(series) == {f"/drone_{i}/metrics" for i in range(4)}
    for i in range(4):
        lat = [m["latency_ms"] for m in series[f"/drone_{i}/metrics"] if m.get("latency_ms") is not None]
        assert len(lat) > 20 and np.allclose(lat, 50.0), i
    rrd = _rrd(exported)
    for i in range(4):
        lat = np.concatenate(rrd[f"/metrics/latency_ms/drone_{i}"]["Scalars:scalars"].to_numpy())
        assert np.allclose(lat, 50.0), i
        loss = rrd[f"/metrics/loss_ratio/drone_{i}"]
        t = loss["run_time"].dt.total_seconds().to_numpy()
        values = np.concatenate(loss["Scalars:scalars"].to_numpy())
        assert np.all(values[t < CUT_S - 0.5] == 0.0), i
        if i == 3:   # nothing of drone 3's arrives after the cut
            assert np.all(values[(t > CUT_S + 1) & (t < CUT_S + 5)] == 1.0)


def test_markers_and_faults_are_events(exported):
    events = pd.concat([pd.read_parquet(p) for p in (exported / "logs").glob("*/events.parquet")])
    markers = int((events["kind"] == "marker").sum())
    assert markers >= 4                                    # near_miss_warning, per drone and neighbour
    logs = [(msg.level, msg.message) for topic, _, msg in _mcap(exported) if topic == "/events"]
    assert sum(1 for _, m in logs if m.startswith("marker/near_miss_warning")) == markers
    faults = [(lvl, m) for lvl, m in logs if m.startswith("fault/")]
    assert faults and all(lvl == 3 for lvl, _ in faults)  # foxglove Log.WARNING
    text = _rrd(exported)["/events"]
    texts = [t[0] for t in text["TextLog:text"]]
    assert sum("marker/near_miss_warning" in t for t in texts) == markers
    assert any("fault/" in t for t in texts)


def test_a_time_window_of_the_rerun_recording(exported):
    assert export_main([str(exported), "--format", "rrd", "--from", "14.5", "--to", "20"]) == 0
    rrd = _rrd(exported, "run_14.5-20.rrd")
    times = pd.concat([f["run_time"] for f in rrd.values()]).dt.total_seconds()
    state = pd.concat([pd.read_parquet(p) for p in (exported / "logs").glob("drone_*/state.parquet")])
    inside = state[(state["t_s"] >= 14.5) & (state["t_s"] <= 20)]["t_s"]
    assert times.min() >= 14.5 and times.max() <= 20.0
    assert times.min() == pytest.approx(inside.min(), abs=0.03)
    assert len(rrd["/world/drones/0"]) > 0
