"""Loading run directories (complete, partial, malformed) and clock unification."""

from __future__ import annotations

import json
import shutil

import numpy as np
import pytest

from swarmbox.analysis.load import GROUND, NET, RunLoadError, find_runs, load_run, node_id
from swarmbox.analysis.unify import T, unify

TICK = 0.025


def test_node_ids():
    assert node_id("ground") == GROUND and node_id("net") == NET and node_id("drone_12") == 12
    assert node_id("drone_x") is None and node_id("tables") is None


def test_load_complete_run(make_run):
    run = load_run(make_run(n_drones=3, speeds_m_s=(1, 1, 1)))
    assert run.problems == [] and not run.incomplete
    assert run.nodes == [NET, GROUND, 0, 1, 2] and run.drones == [0, 1, 2]
    assert sorted(run.tables["state"]["node"].unique()) == [0, 1, 2]
    assert len(run.tables["state"]) == 3 * 800
    assert run.config["algo"]["metrics"] == []


def test_missing_required_file_marks_run_incomplete(make_run):
    run = load_run(make_run(skip_files=("drone_1/state",)))
    assert run.incomplete
    assert any("drone_1/state.parquet missing" in p for p in run.problems)
    assert sorted(run.tables["state"]["node"].unique()) == [0, 2, 3]


def test_drone_without_logs_marks_run_incomplete(make_run):
    path = make_run()
    shutil.rmtree(path / "logs" / "drone_3")
    run = load_run(path)
    assert run.incomplete and "node drone_3 listed in run.json has no logs" in run.problems


def test_corrupt_file_is_reported_not_raised(make_run):
    path = make_run()
    (path / "logs" / "drone_0" / "events.parquet").write_bytes(b"not parquet")
    run = load_run(path)
    assert any("drone_0/events.parquet: unreadable" in p for p in run.problems)
    assert run.incomplete   # a damaged record is never analyzed as if it were whole


def test_missing_or_broken_manifest_raises(tmp_path, make_run):
    with pytest.raises(RunLoadError, match="no run.json"):
        load_run(tmp_path)
    path = make_run()
    (path / "run.json").write_text("{broken")
    with pytest.raises(RunLoadError, match="unreadable"):
        load_run(path)


def test_find_runs_walks_a_sweep(tmp_path, make_run):
    a, b = make_run("x/1"), make_run("x/2")
    assert find_runs(tmp_path) == [a, b]
    assert find_runs(a) == [a]


def test_offset_and_drift_recovered(make_run):
    clocks = {"drone_1": (-0.3, -50.0), "drone_2": (0.5, 100.0), "drone_3": (2.0, 0.0)}
    run = load_run(make_run(clocks=clocks, ticks=1200))
    est = unify(run).set_index("node")
    for name, (offset, drift) in clocks.items():
        node = node_id(name)
        assert abs(est.loc[node, "offset_s"] - offset) < TICK / 25   # well within one tick
        assert abs(est.loc[node, "drift_ppm"] - drift) < 1.0
        assert est.loc[node, "method"] == "two-way"
    assert est.loc[0, "offset_s"] == pytest.approx(0.0, abs=1e-9)
    assert abs(est.loc[2, "offset_error_ms"]) < 1.0


def test_unified_times_land_on_the_ground_clock(make_run):
    run = load_run(make_run(clocks={"drone_2": (0.5, 100.0)}))
    unify(run)
    state = run.tables["state"]
    err = state[T] - state["tick"] * TICK
    assert np.abs(err).max() < 1e-3
    stages = run.tables["stages"]
    d2_exec = stages[(stages["node"] == 2) & (stages["stage"] == 3)][T].iloc[0]
    assert d2_exec == pytest.approx(81 * TICK, abs=1e-3)


def test_offset_through_a_leader(make_run):
    """Drone 3 talks only to drone 0, which talks to the ground: its offset is still recovered."""
    run = load_run(make_run(superiors={3: 0}, clocks={"drone_0": (0.2, 0.0), "drone_3": (-0.7, 0.0)}))
    est = unify(run).set_index("node")
    assert est.loc[3, "offset_s"] == pytest.approx(-0.7, abs=1e-3)
    assert est.loc[0, "offset_s"] == pytest.approx(0.2, abs=1e-3)


def test_longer_symmetric_delay_cancels(make_run):
    """3-tick delays both ways on one drone's links: the offset is still exact."""
    run = load_run(make_run(extra_delay_ticks={1: 2}, clocks={"drone_1": (1.0, 0.0)}))
    est = unify(run).set_index("node")
    assert est.loc[1, "offset_s"] == pytest.approx(1.0, abs=1e-6)


def test_one_way_link_uses_the_typical_delay(make_run):
    """Drone 2 never logs the ground's Heartbeats: only its Reports tell its clock, with the 25 ms
    delay measured on the two-way links."""
    run = load_run(make_run(clocks={"drone_2": (0.5, 0.0)}))
    msgs = run.tables["messages"]
    run.tables["messages"] = msgs[~((msgs["node"] == 2) & (msgs["kind"] == "recv"))]
    est = unify(run).set_index("node")
    assert est.loc[2, "method"] == "one-way"
    assert est.loc[2, "offset_s"] == pytest.approx(0.5, abs=1e-6)


def test_isolated_node_keeps_zero_offset(make_run):
    path = make_run()
    manifest = json.loads((path / "run.json").read_text())
    run = load_run(path)
    msgs = run.tables["messages"]
    run.tables["messages"] = msgs[(msgs["src"] != 2) & (msgs["dst"] != 2)]
    est = unify(run).set_index("node")
    assert est.loc[2, "method"] == "assumed" and est.loc[2, "offset_s"] == 0.0
    assert manifest["nodes"][0] == "ground"
