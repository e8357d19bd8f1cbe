"""A GNSS fault in a distributed run: the agent owning the vehicle has its autopilot fail the receiver
(MAV_CMD_INJECT_FAILURE), and the analyzer's diagnosis names that drone. The vehicles fly in one
shared mavsim host (``run.net.vehicle_host=shared``), which this test also covers."""

from __future__ import annotations

import json
import subprocess

import pandas as pd
import pytest

from swarmbox.analysis import diagnosis as dg
from swarmbox.analysis.load import load_run
from swarmbox.analysis.unify import unify
from tests.run.test_distributed import SHORT_FORMATION, events, finish, launch, wait_started

pytestmark = pytest.mark.slow


def test_gps_failure_on_one_agent_is_diagnosed_on_that_drone(tmp_path):
    run_dir = tmp_path / "run"
    proc = launch(run_dir, *SHORT_FORMATION, "run.net.vehicle_host=shared", "fault=gps_failure",
                  "fault.targets=[2]", "fault.onset_s=15", "fault.gps_failure.failure=wrong")
    try:
        plan = wait_started(run_dir)
        patterns = [f"mavsim.process .*--parent-pid {plan['pids'][f'drone_{i}']}" for i in range(4)]
        own_vehicles = [subprocess.run(["pgrep", "-f", pat], capture_output=True, text=True).stdout.strip()
                        for pat in patterns]
        manifest = finish(proc, run_dir)
    finally:
        proc.kill()
    assert manifest["status"] == "ok", manifest["_console"][-3000:]
    # one host flies every vehicle: no agent started its own
    assert own_vehicles == [""] * 4 and plan["vehicles"]["drone_2"]["system_ids"] == [3]
    assert manifest["vehicle_host"]["vehicles"] == 4 and manifest["vehicle_host"]["vmhwm_mb"] > 0
    log = (run_dir / "nodes" / "mavsim_host.log").read_text()
    assert log.count("mavsim host: system") == 4 and "4 vehicles stopped" in log
    # the fault: sent by drone 2's agent to its own autopilot only, and accepted
    ev = events(run_dir, "drone_2")
    accepted = ev.query("kind == 'fault' and name == 'inject_accepted'")
    assert len(accepted) >= 1 and json.loads(accepted["data"].iloc[0])["type"] == "wrong"
    for other in (0, 1, 3):
        assert not (events(run_dir, f"drone_{other}")["name"] == "inject_accepted").any()
    ground = events(run_dir, "ground")
    assert ((ground["kind"] == "fault") & (ground["name"].str.contains("gps_failure"))).any()
    state = pd.read_parquet(run_dir / "logs" / "drone_2" / "state.parquet")
    assert ((state["gnss_n"] - state["pos_n"]).abs() > 5.0).any()   # the wrong fixes reached the bridge
    # the analyzer, from the logs alone, names drone 2
    run = load_run(run_dir)
    unify(run)
    found = dg.finding(dg.scan(dg.drone_series(run)))
    assert found["detected"] and found["drone"] == 2 and found["metric"].startswith("disc_"), found
    assert found["t_u"] >= 15.0 - 0.5
