"""``run.runtime=processes``: the ground and each agent as OS processes talking over Zenoh.

Real processes, real sockets on 127.0.0.1, real mavsim autopilots, paced on the wall clock: each test
takes one to two minutes, hence ``slow``. Timeouts are generous because the machine is shared.
"""

from __future__ import annotations

import json
import os
import signal
import struct
import subprocess
import sys
import threading
import time
from pathlib import Path

import pandas as pd
import pytest
import zenoh

from swarmbox.analysis.load import load_run
from swarmbox.analysis.unify import unify
from swarmbox.core.messages import Heartbeat, Report
from swarmbox.net.auth import VERSION, mission_tag
from swarmbox.net.codec import encode
from swarmbox.net.zenoh_medium import session_config
from swarmbox.run.processes import free_ports

pytestmark = pytest.mark.slow
ROOT = Path(__file__).resolve().parents[2]
#: the formation, shortened for CI: circle from 5 s of EXECUTION, one lap in ~25 s
SHORT_FORMATION = ["algo.params.start_s=5", "algo.params.angular_rate_rad_s=0.25",
                   "algo.params.complete_after_s=32"]


def launch(run_dir: Path, *overrides: str, key: str | None = None) -> subprocess.Popen:
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    env.pop("SWARMBOX_NET_KEY", None)
    if key:
        env["SWARMBOX_NET_KEY"] = key
    return subprocess.Popen([sys.executable, "-m", "swarmbox.run", "run.runtime=processes", "backend=mavsim",
                             f"run.out_dir={run_dir}", "run.progress=false", *overrides],
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, env=env)


def wait_started(run_dir: Path, timeout_s: float = 300.0) -> dict:
    """The launch plan and start instant once every node is ready."""
    deadline = time.monotonic() + timeout_s
    while not (run_dir / "nodes" / "start.json").exists():
        assert time.monotonic() < deadline, "the nodes never became ready"
        time.sleep(0.2)
    plan = json.loads((run_dir / "nodes" / "plan.json").read_text())
    plan.update(json.loads((run_dir / "nodes" / "start.json").read_text()))
    plan["pids"] = json.loads((run_dir / "nodes" / "pids.json").read_text())
    return plan


def finish(proc: subprocess.Popen, run_dir: Path, timeout_s: float = 600.0) -> dict:
    out, _ = proc.communicate(timeout=timeout_s)
    manifest = json.loads((run_dir / "run.json").read_text())
    manifest["_console"] = out.decode(errors="replace")
    return manifest


def events(run_dir: Path, node: str) -> pd.DataFrame:
    return pd.read_parquet(run_dir / "logs" / node / "events.parquet")


def messages(run_dir: Path, node: str) -> pd.DataFrame:
    return pd.read_parquet(run_dir / "logs" / node / "messages.parquet")


def intrude(plan: dict, stop: threading.Event) -> None:
    """A stranger on the network: unsigned, forged (no key) and replayed (captured) frames."""
    port = free_ports(1)[0]
    session = zenoh.open(session_config(f"tcp/127.0.0.1:{port}", list(plan["locators"].values())))
    prefix = f"swarmbox/{plan['mission_id']}"
    captured: list[bytes] = []
    sub = session.declare_subscriber(f"{prefix}/hb/-1",
                                     lambda s: captured.append(bytes(s.payload.to_bytes())))
    to_ground = session.declare_publisher(f"{prefix}/to/-1")
    ground_hb = session.declare_publisher(f"{prefix}/hb/-1")
    fake_report = Report(1, 0.0, 0, -1, 5, True, 1, 1, (0.0,) * 3, (0.0,) * 3, None, "", ())
    fake_abort = Heartbeat(2, 0.0, -1, -1, (), (0.0,) * 3, (0.0,) * 3)         # stage -1 = ABORT
    try:
        while not stop.wait(0.5):
            head = b"SB" + bytes([VERSION]) + mission_tag(plan["mission_id"]) + struct.pack("<hQd", -1, 2**62,
                                                                                       time.time())
            forged = head + encode(fake_abort) + bytes(16)    # right mission, fresh, but no key
            to_ground.put(encode(fake_report))         # unsigned
            ground_hb.put(encode(fake_abort))          # unsigned
            ground_hb.put(forged)                      # bad tag
            if captured:
                ground_hb.put(captured[-1])            # a genuine ground Heartbeat, again
    finally:
        sub.undeclare()
        session.close()


def test_formation_over_processes_completes_recovers_offsets_and_drops_intruders(tmp_path):
    run_dir = tmp_path / "run"
    proc = launch(run_dir, "run.clocks={drone_1: {offset_s: 0.2}, drone_2: {offset_s: -0.2}}")
    stop = threading.Event()
    try:
        plan = wait_started(run_dir)
        intruder = threading.Thread(target=intrude, args=(plan, stop))
        intruder.start()
        manifest = finish(proc, run_dir)
    finally:
        stop.set()
        proc.kill()
    intruder.join(timeout=30)
    assert manifest["status"] == "ok", manifest["_console"][-3000:]
    assert manifest["reason"] == ""
    assert sorted(manifest["node_results"]) == ["drone_0", "drone_1", "drone_2", "drone_3", "ground"]
    clocks = unify(load_run(run_dir)).set_index("node")
    assert abs(clocks.loc[1, "offset_s"] - 0.2) < 0.002 and abs(clocks.loc[2, "offset_s"] + 0.2) < 0.002
    assert clocks["offset_error_ms"].abs().max() < 2.0
    ground_drops = set(messages(run_dir, "ground").query("kind == 'drop'")["reason"])
    assert "unsigned" in ground_drops
    drone_msgs = pd.concat([messages(run_dir, f"drone_{i}") for i in range(4)])
    drone_drops = set(drone_msgs.query("kind == 'drop'")["reason"])
    assert {"unsigned", "forged", "replayed"} <= drone_drops
    assert manifest["node_results"]["drone_0"]["rejected"].get("replayed", 0) > 0
    assert not (events(run_dir, "drone_0")["name"] == "superior_aborted").any()
    stages = pd.read_parquet(run_dir / "logs" / "drone_0" / "stages.parquet")["name"].tolist()
    assert "ABORT" not in stages and stages[-1] == "TERMINATION"


def test_kill_9_of_an_agent_is_detected_as_a_lost_drone(tmp_path):
    run_dir = tmp_path / "run"
    proc = launch(run_dir, "algo=hover", "mission=hover", "algo.params.hover_s=20")
    try:
        plan = wait_started(run_dir)
        time.sleep(max(0.0, plan["epoch_wall_s"] + 12.0 - time.time()))
        killed_at = time.time() - plan["epoch_wall_s"]
        os.kill(plan["pids"]["drone_3"], signal.SIGKILL)
        manifest = finish(proc, run_dir)
    finally:
        proc.kill()
    assert manifest["status"] == "ok", manifest["_console"][-3000:]
    assert "lost drones [3]" in manifest["reason"]
    assert "drone_3 killed: killed by SIGKILL" in manifest["reason"]
    lost = events(run_dir, "ground").query("name == 'inferior_lost' and subject == 3")
    assert len(lost) == 1
    cfg_limit_s = 20 / 40.0                          # run.lost_inferior_ticks / run.tick_hz
    assert killed_at < lost["t_s"].iloc[0] < killed_at + cfg_limit_s + 1.0   # one second of load margin


def test_killed_ground_leaves_agents_failing_safe(tmp_path):
    run_dir = tmp_path / "run"
    proc = launch(run_dir, "algo=hover", "mission=hover", "algo.params.hover_s=60")
    try:
        plan = wait_started(run_dir)
        time.sleep(max(0.0, plan["epoch_wall_s"] + 12.0 - time.time()))
        os.kill(plan["pids"]["ground"], signal.SIGKILL)
        manifest = finish(proc, run_dir)
    finally:
        proc.kill()
    assert manifest["status"] == "failed" and "ground killed by SIGKILL" in manifest["reason"]
    for i in range(4):
        result = manifest["node_results"][f"drone_{i}"]
        assert result["status"] == "aborted" and "lost superior -1" in result["reason"], result
        ev = events(run_dir, f"drone_{i}")
        assert (ev["name"] == "superior_lost").any()
        state = pd.read_parquet(run_dir / "logs" / f"drone_{i}" / "state.parquet")
        assert state["armed"].iloc[-1] == False  # noqa: E712  (landed and disarmed)


PX4_BUILD = os.environ.get("SWARMBOX_PX4_BUILD")


@pytest.mark.skipif(not PX4_BUILD, reason="no PX4 SITL build configured: set SWARMBOX_PX4_BUILD")
def test_formation_over_processes_on_px4_sitl(tmp_path):
    run_dir = tmp_path / "run"
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    proc = subprocess.run([sys.executable, "-m", "swarmbox.run", "run.runtime=processes", "backend=px4",
                           f"backend.px4_build={PX4_BUILD}", f"run.out_dir={run_dir}", "run.progress=false"],
                          capture_output=True, text=True, env=env, timeout=900)
    manifest = json.loads((run_dir / "run.json").read_text())
    assert manifest["status"] == "ok", proc.stdout[-2000:] + manifest["reason"]
    plan = json.loads((run_dir / "nodes" / "plan.json").read_text())
    assert plan["vehicles"]["drone_2"] == {"connections": ["udpin:127.0.0.1:14542"], "system_ids": [3]}
    for i in range(4):
        assert manifest["node_results"][f"drone_{i}"]["status"] == "ok"
        assert (run_dir / "px4" / f"instance_{i}" / "out.log").exists()


def test_network_fault_acts_on_the_real_network(tmp_path):
    run_dir = tmp_path / "run"
    proc = launch(run_dir, "algo=hover", "mission=hover", "fault=packet_loss", "fault.targets=[1]",
                  "fault.onset_s=3", "fault.loss_prob=0.3")
    manifest = finish(proc, run_dir)
    assert manifest["status"] == "ok", manifest["_console"][-3000:]
    msgs = pd.concat([messages(run_dir, n) for n in ("ground", "drone_0", "drone_1", "drone_2", "drone_3")])
    lost = msgs[msgs["reason"] == "fault:packet_loss"]
    assert len(lost) > 20
    assert ((lost["src"] == 1) | (lost["dst"] == 1)).all()          # only drone 1's links
    assert lost["t_s"].min() >= 3.0 - 0.1
    assert (events(run_dir, "ground")["name"] == "packet_loss_start").sum() == 1


def test_agent_killed_in_execution_restarts_rejoins_and_flies_again(tmp_path):
    """kill -9 of drone_3 in EXECUTION of the formation, then the same agent started again by hand
    (same --drone, same run directory): the ground logs ``inferior_rejoined``, the drone arms and
    climbs again, the run ends ok and its record says what happened."""
    run_dir, key = tmp_path / "run", os.urandom(16).hex()
    proc = launch(run_dir, *SHORT_FORMATION, key=key)
    again = None
    try:
        plan = wait_started(run_dir)
        time.sleep(max(0.0, plan["epoch_wall_s"] + 15.0 - time.time()))
        os.kill(plan["pids"]["drone_3"], signal.SIGKILL)
        time.sleep(3.0)
        restarted_at = time.time() - plan["epoch_wall_s"]
        env = dict(os.environ, PYTHONPATH=str(ROOT), SWARMBOX_NET_KEY=key)
        again = subprocess.Popen([sys.executable, "-m", "swarmbox.run.node", "agent", "--drone", "3",
                                  "--run-dir", str(run_dir)], env=env, stdout=subprocess.PIPE,
                                 stderr=subprocess.STDOUT)
        manifest = finish(proc, run_dir)
        out, _ = again.communicate(timeout=120)
    finally:
        proc.kill()
        if again is not None:
            again.kill()
    assert manifest["status"] == "ok", (manifest["reason"], manifest["_console"][-3000:], out[-3000:])
    assert "drone_3 killed by SIGKILL, restarted: ok" in manifest["reason"]
    r3 = manifest["node_results"]["drone_3"]
    assert r3["restarted"] is True and r3["status"] == "ok" and r3["first_exit"] == "killed by SIGKILL"
    ground = events(run_dir, "ground")
    lost = ground.query("name == 'inferior_lost' and subject == 3")
    back = ground.query("name == 'inferior_rejoined' and subject == 3")
    assert len(lost) == 1 and len(back) == 1 and back["t_s"].iloc[0] > lost["t_s"].iloc[0]
    state = pd.read_parquet(run_dir / "logs" / "drone_3" / "state.parquet")
    after = state[state["t_s"] > restarted_at]
    assert after["armed"].any() and (-after["pos_d"]).max() > 2.0    # it flew again
    assert state["armed"].iloc[-1] == False  # noqa: E712  (landed with the others)
    stages = pd.read_parquet(run_dir / "logs" / "drone_3" / "stages.parquet")["name"].tolist()
    assert "EXECUTION" in stages and stages[-1] == "TERMINATION"
    assert (events(run_dir, "drone_3")["name"] == "process_restarted").any()

