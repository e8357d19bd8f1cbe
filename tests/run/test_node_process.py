"""The node entry point and the launcher's bookkeeping, without starting a whole distributed run."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest
from omegaconf import OmegaConf

from swarmbox.run.node import NodeSetupError, heartbeat_subscribers, mission_key
from swarmbox.run.processes import free_ports, outcome, redact

ROOT = Path(__file__).resolve().parents[2]


def test_an_agent_process_loads_no_analysis_simulator_or_scipy():
    code = ("import sys, swarmbox.run.node, swarmbox.hal.mavsim.backend, swarmbox.hal.px4.backend\n"
            "print(sorted({m.split('.')[0] for m in sys.modules} & "
            "{'pandas', 'matplotlib', 'seaborn', 'pymunk', 'scipy'}))")
    out = subprocess.run([sys.executable, "-c", code], env=dict(os.environ, PYTHONPATH=str(ROOT)),
                         capture_output=True, text=True, timeout=120, check=True)
    assert out.stdout.strip() == "[]"


def test_node_cli_checks_its_role_arguments(tmp_path):
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    run = ["--run-dir", str(tmp_path)]
    for args in (["agent", *run], ["ground", "--drone", "2", *run]):
        proc = subprocess.run([sys.executable, "-m", "swarmbox.run.node", *args], env=env,
                              capture_output=True, text=True, timeout=120)
        assert proc.returncode == 2 and "--drone is required for an agent" in proc.stderr


def test_the_key_comes_from_config_or_environment_and_its_absence_is_named(monkeypatch):
    cfg = OmegaConf.create({"run": {"net": {"key": None, "key_env": "SWARMBOX_TEST_KEY"}}})
    monkeypatch.delenv("SWARMBOX_TEST_KEY", raising=False)
    with pytest.raises(NodeSetupError, match="SWARMBOX_TEST_KEY"):
        mission_key(cfg)
    monkeypatch.setenv("SWARMBOX_TEST_KEY", "from-the-environment")
    assert mission_key(cfg) == b"from-the-environment"
    cfg.run.net.key = "from-the-config"
    assert mission_key(cfg) == b"from-the-config"


def test_heartbeat_subscribers_follow_topology_and_peers():
    sup = {0: -1, 1: 0, 2: 0}
    assert heartbeat_subscribers(sup, "none") == {-1: [0], 0: [1, 2]}
    everyone = heartbeat_subscribers(sup, "all")
    assert sorted(everyone[0]) == [1, 2] and sorted(everyone[1]) == [0, 2] and sorted(everyone[2]) == [0, 1]


def test_run_outcome_is_the_grounds_plus_what_happened_to_agents():
    ok = {"status": "ok", "reason": ""}
    results = {"ground": {**ok, "lost_drones": [3]}, "drone_0": ok,
               "drone_3": {"status": "killed", "reason": "killed by SIGKILL"}}
    assert outcome(results) == ("ok", "lost drones [3]; drone_3 killed: killed by SIGKILL")
    results["ground"] = {"status": "killed", "reason": "killed by SIGKILL"}
    assert outcome(results)[0] == "failed" and outcome(results)[1].startswith("ground killed by SIGKILL")
    assert outcome({"ground": ok, "drone_0": ok}) == ("ok", "")


def test_free_ports_are_distinct_and_bindable():
    ports = free_ports(5)
    assert len(set(ports)) == 5 and all(1024 < p < 65536 for p in ports)


def _refused_before_any_process(tmp_path, override: str) -> dict:
    """A processes-runtime run with ``override`` that fails before it starts a node process."""
    from swarmbox.run.runner import execute
    from tests.conftest import compose_config

    cfg, choices = compose_config(["run.runtime=processes", "backend=mavsim", override, "run.progress=false"])
    manifest = execute(cfg, tmp_path, choices, [])
    assert manifest["status"] == "failed"
    assert not (tmp_path / "nodes").exists()
    return manifest


def test_a_fleet_fault_is_refused_before_any_process_starts(tmp_path):
    manifest = _refused_before_any_process(tmp_path, "fault=gps_drift")
    assert "gps_drift cannot run with run.runtime=processes" in manifest["reason"]
    assert "key: null" in (tmp_path / "config.yaml").read_text()


def test_keys_given_on_the_command_line_are_not_recorded():
    assert redact(["run.net.key=abc", "+backend.signing_key=pass", "seed=3", "run.net.key_env=X"]) == [
        "run.net.key=***", "+backend.signing_key=***", "seed=3", "run.net.key_env=X"]


def test_an_unknown_vehicle_host_is_refused_before_any_process_starts(tmp_path):
    manifest = _refused_before_any_process(tmp_path, "run.net.vehicle_host=cloud")
    assert "run.net.vehicle_host must be one of agent, shared, got 'cloud'" in manifest["reason"]


def test_a_restarted_node_appends_its_rows_after_the_earlier_segments(tmp_path):
    import pyarrow as pa
    import pyarrow.parquet as pq

    from swarmbox.run import node_logs

    logs = tmp_path / "logs" / "drone_3"

    def process_writes(first_t: float) -> None:        # what one process of the node leaves behind
        logs.mkdir(parents=True, exist_ok=True)
        pq.write_table(pa.table({"t_s": [first_t, first_t + 1.0], "tick": [1, 2]}), logs / "events.parquet")

    process_writes(0.0)                                 # first process, stopped by SIGTERM
    segments = node_logs.set_aside(tmp_path, "drone_3")
    assert len(segments) == 1 and not logs.exists()
    process_writes(10.0)                                # the restarted process
    node_logs.append_segments(tmp_path, "drone_3", segments)
    assert pq.read_table(logs / "events.parquet").column("t_s").to_pylist() == [0.0, 1.0, 10.0, 11.0]
    segments = node_logs.set_aside(tmp_path, "drone_3")  # restarted once more
    process_writes(20.0)
    node_logs.append_segments(tmp_path, "drone_3", segments)
    times = pq.read_table(logs / "events.parquet").column("t_s").to_pylist()
    assert times == [0.0, 1.0, 10.0, 11.0, 20.0, 21.0]
    assert node_logs.set_aside(tmp_path / "elsewhere", "drone_3") == []
