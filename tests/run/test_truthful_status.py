"""A run is ``ok`` only if its mission completed, by the same rules in both runtimes."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
ONE_CRASHES = ["algo=hover", "mission=hover", "algo.drone._target_=tests.run.algos.OneCrashingDrone",
               "algo.params.hover_s=3"]


def test_an_agent_whose_hook_raised_fails_the_run_in_both_runtimes(tmp_path, run):
    single, _ = run(*ONE_CRASHES)
    assert single["status"] == "failed" and "drone 1: exec_loop" in single["reason"]

    env = {k: v for k, v in os.environ.items() if k != "SWARMBOX_NET_KEY"}
    env["PYTHONPATH"] = str(ROOT)
    run_dir = tmp_path / "processes"
    proc = subprocess.run([sys.executable, "-m", "swarmbox.run", "run.runtime=processes", "backend=mavsim",
                           f"run.out_dir={run_dir}", "run.progress=false", *ONE_CRASHES],
                          capture_output=True, text=True, env=env, timeout=300)
    manifest = json.loads((run_dir / "run.json").read_text())
    assert proc.returncode == 1, proc.stdout + proc.stderr
    assert manifest["status"] == "failed", manifest["reason"]
    assert manifest["reason"].startswith("drone_1 failed")
    assert "AlgorithmError: drone 1: exec_loop/exec_complete raised ZeroDivisionError" in manifest["reason"]
    # the others completed the mission: the ground alone would have called it ok
    assert manifest["node_results"]["ground"]["status"] == "ok"
    assert all(manifest["node_results"][f"drone_{i}"]["status"] == "ok" for i in (0, 2, 3))


def test_when_the_leader_aborts_the_mission_goes_on_under_the_ground(run):
    """leader_follower: the leader's battery failsafe 2 s into the hover. Its followers hand over to
    the ground, which holds EXECUTION until they have joined and completed it; it once counted the
    aborted leader as done and landed everyone in the same tick, with the run ``ok``."""
    from tests.conftest import table

    manifest, d = run("algo=hover", "mission=hover", "topology=leader_follower", "fault=battery_failsafe",
                      "fault.targets=[0]", "fault.onset_s=5")
    assert manifest["status"] == "ok", manifest["reason"]
    assert "drones [0] aborted" in manifest["reason"]
    ground = table(d, "ground", "stages").set_index("name")["t_s"]
    joined = table(d, "ground", "events").query("name == 'inferior_joined' and subject != 0")
    assert sorted(joined["subject"]) == [1, 2, 3] and (joined["t_s"] < 5.2).all()
    for follower in (1, 2, 3):
        done = table(d, f"drone_{follower}", "events").query("name == 'exec_complete'")["t_s"]
        assert len(done) == 1 and 5.0 < done.iloc[0] < ground["LANDING"]
        assert list(table(d, f"drone_{follower}", "stages")["name"])[-1] == "TERMINATION"


def test_when_the_leader_aborts_and_no_drone_takes_over_the_run_is_aborted(run):
    """The followers are cut off from the ground (and the leader) just before the leader's failsafe:
    nobody can carry the mission on. It once landed at once and recorded the run ``ok``."""
    from tests.conftest import table

    manifest, d = run("algo=hover", "mission=hover", "topology=leader_follower",
                      "fault=[partition,battery_failsafe]", "fault.partition.targets=[1,2,3]",
                      "fault.partition.onset_s=4.9", "fault.battery_failsafe.targets=[0]",
                      "fault.battery_failsafe.onset_s=5", "run.min_alive=0")
    assert manifest["status"] == "aborted"
    assert manifest["reason"].startswith("every drone the ground commands aborted (drone 0) and none took "
                                         "over: the EXECUTION was cut short")
    ground = list(table(d, "ground", "stages")["name"])
    assert ground[-1] == "ABORT" and "LANDING" not in ground


def test_ctrl_c_ends_a_processes_run_interrupted_as_in_one_process(tmp_path):
    import signal
    import time

    env = {k: v for k, v in os.environ.items() if k != "SWARMBOX_NET_KEY"}
    env["PYTHONPATH"] = str(ROOT)
    run_dir = tmp_path / "run"
    proc = subprocess.Popen([sys.executable, "-m", "swarmbox.run", "run.runtime=processes", "backend=mavsim",
                             "algo=hover", "mission=hover", "algo.params.hover_s=60",
                             f"run.out_dir={run_dir}", "run.progress=false"],
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, env=env)
    try:
        deadline = time.monotonic() + 300
        while not (run_dir / "nodes" / "start.json").exists():
            assert proc.poll() is None and time.monotonic() < deadline, proc.communicate()
            time.sleep(0.1)
        time.sleep(3.0)
        proc.send_signal(signal.SIGINT)
        out, _ = proc.communicate(timeout=120)
    finally:
        proc.kill()
    assert proc.returncode == 130, out
    manifest = json.loads((run_dir / "run.json").read_text())
    assert manifest["status"] == "interrupted" and manifest["reason"] == "interrupted by SIGINT"
    assert manifest["sim_time_s"] > 1.0
    assert {r["status"] for r in manifest["node_results"].values()} == {"aborted"}   # stopped, logs closed
    assert all((run_dir / "logs" / f"drone_{i}" / "state.parquet").is_file() for i in range(4))
