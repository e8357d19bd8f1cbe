"""A GNSS fault in a distributed run: the agent owning the vehicle has its autopilot fail the receiver
(MAV_CMD_INJECT_FAILURE to its mavsim vehicle), and the analyzer's diagnosis names that drone."""

from __future__ import annotations

import json

import pandas as pd
import pytest

from swarmbox.analysis import diagnosis as dg
from swarmbox.analysis.load import load_run
from swarmbox.analysis.unify import unify
from tests.run.test_distributed import events, finish, launch

pytestmark = pytest.mark.slow


def test_gps_failure_on_one_agent_is_diagnosed_on_that_drone(tmp_path):
    run_dir = tmp_path / "run"
    proc = launch(run_dir, "fault=gps_failure", "fault.targets=[2]", "fault.onset_s=25",
                  "fault.gps_failure.failure=wrong")
    try:
        manifest = finish(proc, run_dir)
    finally:
        proc.kill()
    assert manifest["status"] == "ok", manifest["_console"][-3000:]
    ev = events(run_dir, "drone_2")
    accepted = ev.query("kind == 'fault' and name == 'inject_accepted'")
    assert len(accepted) >= 1 and json.loads(accepted["data"].iloc[0])["type"] == "wrong"
    for other in (0, 1, 3):                                     # only the owner's vehicle failed
        assert not (events(run_dir, f"drone_{other}")["name"] == "inject_accepted").any()
    ground = events(run_dir, "ground")
    assert ((ground["kind"] == "fault") & (ground["name"].str.contains("gps_failure"))).any()
    run = load_run(run_dir)
    unify(run)
    found = dg.finding(dg.scan(dg.drone_series(run)))
    assert found["detected"] and found["drone"] == 2 and found["metric"].startswith("disc_"), found
    assert found["t_u"] >= 25.0 - 0.5
    state = pd.read_parquet(run_dir / "logs" / "drone_2" / "state.parquet")
    assert ((state["gnss_n"] - state["pos_n"]).abs() > 5.0).any()   # the wrong fixes reached the bridge
