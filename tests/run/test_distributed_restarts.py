"""kill -9 and restart of the ground and of a leader agent in the middle of EXECUTION, over real node
processes (``run.runtime=processes``, Zenoh on 127.0.0.1, mavsim autopilots).

Each node is started again with the launcher's own command line (``python -m swarmbox.run.node
ground|agent --drone I --run-dir RUN``, the key in ``SWARMBOX_NET_KEY``). The restarted ground adopts
EXECUTION from the drones' Reports; every reliable task sent after the restarts reaches its
receiver's ``on_task`` exactly once or is logged undelivered, and no message seems to arrive before
it was sent (message ids stay unique across the restarts).
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pandas as pd
import pytest

from swarmbox.analysis.load import load_run
from tests.run.test_distributed import ROOT, events, finish, launch, wait_started

pytestmark = pytest.mark.slow
TASKING = ["algo=hover", "mission=hover", "topology=leader_follower", "algo.params.hover_s=20",
           "algo.drone._target_=tests.run.restart_algos.TaskingDrone",
           "+algo.ground._target_=tests.run.restart_algos.TaskingGround",
           # followers and the ground must outlast a restart (a few seconds) before handing over
           "run.lost_superior_ticks=600", "run.timeouts_s.EXECUTION=300"]


def restart_node(run_dir: Path, key: str, role: list[str], pid: int) -> subprocess.Popen:
    """kill -9 ``pid``, then start the node again exactly as the launcher did (same arguments)."""
    os.kill(pid, signal.SIGKILL)
    env = dict(os.environ, PYTHONPATH=str(ROOT), SWARMBOX_NET_KEY=key)
    return subprocess.Popen([sys.executable, "-m", "swarmbox.run.node", *role, "--run-dir", str(run_dir)],
                            env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT)


def wait_ready_pid(run_dir: Path, name: str, pid: int, timeout_s: float = 120.0) -> None:
    ready = run_dir / "nodes" / f"{name}.ready"
    deadline = time.monotonic() + timeout_s
    while not (ready.exists() and ready.read_text().strip() == str(pid)):
        assert time.monotonic() < deadline, f"restarted {name} never became ready"
        time.sleep(0.2)


def marks(run_dir: Path, node: str, name: str) -> pd.DataFrame:
    ev = events(run_dir, node)
    ev = ev[(ev["kind"] == "marker") & (ev["name"] == name)].copy()
    fields = ev["data"].map(json.loads)
    for col in ("dst", "src", "seq", "data"):
        ev[col] = fields.map(lambda f, c=col: f.get(c))
    return ev


def undelivered_keys(run_dir: Path, node: str) -> set[tuple[int, int]]:
    ev = events(run_dir, node)
    ev = ev[ev["name"] == "task_undelivered"]
    return {(int(r.subject), json.loads(r.data)["seq"]) for r in ev.itertuples()}


def skipped_keys(run_dir: Path, node: str, src: int) -> set[int]:
    ev = events(run_dir, node)
    out: set[int] = set()
    for r in ev[(ev["name"] == "task_skipped") & (ev["subject"] == src)].itertuples():
        f = json.loads(r.data)
        out.update(range(f["first"], f["last"] + 1))
    return out


def check_tasks_after(run_dir: Path, sender: str, sender_id: int, receivers: list[int], t0: float) -> int:
    """Every task ``sender``'s (final) process sent after ``t0``: delivered once, or logged undelivered."""
    sent = marks(run_dir, sender, "task_sent")
    sent["seq"] = sent.groupby("dst").cumcount() + 1          # the k-th reliable task to dst is number k
    lost = undelivered_keys(run_dir, sender)
    checked = 0
    for dst in receivers:
        got = marks(run_dir, f"drone_{dst}", "task_got")
        got = got[got["src"] == sender_id]
        skipped = skipped_keys(run_dir, f"drone_{dst}", sender_id)
        for r in sent[(sent["dst"] == dst) & (sent["t_s"] > t0)].itertuples():
            times = int((got["data"] == r.data).sum())
            logged = (dst, r.seq) in lost or r.seq in skipped
            assert times == 1 or (times == 0 and logged), \
                f"{sender} -> drone_{dst} task {r.seq} ({r.data}) delivered {times} times, logged {logged}"
            checked += 1
    return checked


def test_ground_and_leader_killed_and_restarted_mid_execution(tmp_path):
    run_dir, key = tmp_path / "run", os.urandom(16).hex()
    proc = launch(run_dir, *TASKING, key=key)
    ground = leader = None
    try:
        plan = wait_started(run_dir)
        time.sleep(max(0.0, plan["epoch_wall_s"] + 12.0 - time.time()))
        ground = restart_node(run_dir, key, ["ground"], plan["pids"]["ground"])
        wait_ready_pid(run_dir, "ground", ground.pid)
        time.sleep(4.0)
        leader = restart_node(run_dir, key, ["agent", "--drone", "0"], plan["pids"]["drone_0"])
        wait_ready_pid(run_dir, "drone_0", leader.pid)
        g_out, _ = ground.communicate(timeout=600)
        manifest = finish(proc, run_dir)
        l_out, _ = leader.communicate(timeout=120)
    finally:
        for p in (proc, ground, leader):
            if p is not None:
                p.kill()
    console = (manifest["_console"][-2000:], g_out[-2000:], l_out[-2000:])
    assert manifest["node_results"]["ground"]["incarnation"] == 1, console
    assert manifest["node_results"]["drone_0"]["incarnation"] == 1, console
    # the restarted ground adopted the swarm's stage instead of commanding ICEBREAK and timing out
    g_events = events(run_dir, "ground")
    adopted = g_events[g_events["name"] == "stage_adopted"]
    assert len(adopted) == 1 and json.loads(adopted["data"].iloc[0])["stage"] == "EXECUTION", console
    g_stages = pd.read_parquet(run_dir / "logs" / "ground" / "stages.parquet")["name"].tolist()
    assert g_stages == ["ICEBREAK", "PREPARATION", "EXECUTION", "LANDING", "TERMINATION"], (g_stages, console)
    assert manifest["node_results"]["ground"]["status"] == "ok", console
    leader_back = events(run_dir, "drone_0").query("name == 'process_restarted'")["t_s"].iloc[0]
    # every reliable task sent after both restarts: exactly once, or logged undelivered
    n_ground = check_tasks_after(run_dir, "ground", -1, [0], leader_back)
    n_leader = check_tasks_after(run_dir, "drone_0", 0, [1, 2, 3], leader_back)
    assert n_ground > 10 and n_leader > 30, (n_ground, n_leader)
    # no message arrives before it was sent (one machine, one clock: a receive matched to the wrong
    # send — an id used again by a restarted process — would show as a negative latency)
    msgs = load_run(run_dir).tables["messages"]
    sends = msgs[msgs["kind"] == "send"][["msg_id", "dst", "t_s"]]
    recvs = msgs[msgs["kind"] == "recv"][["msg_id", "dst", "t_s"]]
    assert not sends.duplicated(["msg_id", "dst"]).any()
    matched = recvs.merge(sends, on=["msg_id", "dst"], suffixes=("_recv", "_send"))
    latency = matched["t_s_recv"] - matched["t_s_send"]
    assert len(matched) > 1000 and (latency >= 0).all(), matched[latency < 0].head()
    follower_recv = pd.concat([pd.read_parquet(run_dir / "logs" / f"drone_{i}" / "messages.parquet")
                               for i in (1, 2, 3)])
    from_leader = follower_recv[(follower_recv["kind"] == "recv") & (follower_recv["src"] == 0)]
    assert not from_leader.duplicated(["msg_id", "dst"]).any()
