"""The failure battery: every bad input and failure a user meets, through the real command line.

Each case asserts the exit code, that one stderr line names the key / file / drone, that no
traceback reaches the terminal, and the state of the disk afterwards (config errors: nothing at
all; failures: a complete, truthful run directory). Config errors stop before any flight, and the
runtime cases fly a 4-drone hover of a few simulated seconds.
"""

from __future__ import annotations

import json
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import pandas as pd
import pytest

from tests import realtime
from tests.conftest import ROOT, sweep_job

HOVER = ("algo=hover", "mission=hover", "algo.params.hover_s=1", "run.progress=false")
SAME_POINT = "{0:[0,0],1:[0,0],2:[10,0],3:[15,0]}"


def swarmbox(tmp: Path, *args: str, env: dict | None = None) -> subprocess.CompletedProcess:
    """``python -m swarmbox.run`` with Hydra's own output directory inside ``tmp``."""
    cmd = [sys.executable, "-m", "swarmbox.run", *HOVER, f"hydra.run.dir={tmp / 'hydra'}", *args]
    return subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, timeout=120, env=env)


def files(root: Path) -> list[str]:
    return sorted(str(p.relative_to(root)) for p in root.rglob("*")) if root.exists() else []


MISSION_FILES = {
    "duplicate_id": "drone_config:\n  initial_positions:\n    0: [0, 0]\n    1: [5, 0]\n    1: [9, 0]\n"
                    "    2: [12, 0]\nmission_config:\n  type: dup\n",
    "no_mission_config": "drone_config:\n  initial_positions:\n    0: [0, 0]\n",
    "empty": "",
    "not_yaml": "drone_config: [unclosed\n  : :\n",
    "binary": bytes(range(256)) * 4,
    "text_positions": "drone_config:\n  initial_positions:\n    0: [north, east]\nmission_config: {}\n",
}

CONFIG_CASES = [   # (case id, overrides, text the one-line message must contain)
    ("1-unknown-key", ["nosuchkey=1"], "nosuchkey"),
    ("2-misspelt-backend-key", ["backend.max_speedd=5"], "backend.max_speedd"),
    ("3-seed-type", ["seed=abc"], "seed"),
    ("3-backend-type", ["backend.mpc_xy_vel_max_m_s=fast"], "backend.mpc_xy_vel_max_m_s"),
    ("3-mavsim-sim-type", ["backend=mavsim", "backend.sim.mass_kg=heavy"], "backend.sim.mass_kg"),
    ("4-tick-hz", ["run.tick_hz=0"], "run.tick_hz"),
    ("4-loss", ["network.loss_prob=1.5"], "network.loss_prob"),
    ("4-latency", ["network.latency_ms=-3"], "network.latency_ms"),
    ("4-backend-range", ["backend.mass_kg=-1"], "mass_kg"),
    ("5-algo", ["algo=nosuch"], "algo"),
    ("6-cycle", ["topology=explicit", "topology.superiors={0:1,1:0,2:-1,3:-1}"], "topology.superiors: cycle"),
    ("6-self", ["topology=explicit", "topology.superiors={0:0,1:-1,2:-1,3:-1}"], "its own superior"),
    ("6-out-of-range", ["topology=explicit", "topology.superiors={0:-1,1:9,2:-1,3:-1}"],
     "unknown superior 9"),
    ("6-missing-drone", ["topology=explicit", "topology.superiors={0:-1,1:0,2:0}"],
     "drones [3] have no superior"),
    ("7-size", ["mission.swarm_size=5"], "swarm_size 5 disagrees"),
    ("7-same-point", ["mission.initial_positions=null", f"mission.initial_positions={SAME_POINT}"],
     "drones 0 and 1 start 0.00 m apart"),
    ("7-duplicate-id", ["mission.file=@duplicate_id"], "key 1 is given twice"),
    ("8-no-mission-config", ["mission.file=@no_mission_config"], "mission_config"),
    ("8-empty", ["mission.file=@empty"], "the file is empty"),
    ("8-not-yaml", ["mission.file=@not_yaml"], "not valid YAML"),
    ("8-binary", ["mission.file=@binary"], "not a text file"),
    ("8-text-positions", ["mission.file=@text_positions"], "position of drone 0"),
    ("8-missing-file", ["mission.file=/nonexistent/mission.yaml"], "no such file: /nonexistent/mission.yaml"),
    ("9-target-99", ["fault=gps_drift", "fault.targets=[99]"], "unknown drone 99"),
    ("9-onset", ["fault=packet_loss", "fault.onset_s=500"], "onset_s 500 s is after the mission's end"),
    ("9-drift-rate", ["fault=gps_drift", "fault.rate_m_s=-2"], "rate_m_s must be >= 0"),
    ("9-loss", ["fault=packet_loss", "fault.loss_prob=1.5"], "loss_prob must be within [0, 1]"),
    ("10-out-dir-not-writable", ["run.out_dir=@file/run"], "run directory"),
]


@pytest.mark.parametrize("case, overrides, named", CONFIG_CASES, ids=[c[0] for c in CONFIG_CASES])
def test_config_error_is_one_line_exit_2_and_writes_nothing(tmp_path, case, overrides, named):
    inputs = tmp_path / "inputs"
    inputs.mkdir()
    (inputs / "file").write_text("a file, not a directory\n")
    for name, content in MISSION_FILES.items():
        path = inputs / f"{name}.yaml"
        path.write_bytes(content if isinstance(content, bytes) else content.encode())
    args = [o.replace("mission.file=@", f"mission.file={inputs}/").replace("=@file", f"={inputs}/file")
            for o in overrides]
    args = [f"{a}.yaml" if a.startswith(f"mission.file={inputs}") else a for a in args]
    before = files(inputs)
    out = tmp_path / "out"
    proc = swarmbox(tmp_path, *([] if any(a.startswith("run.out_dir") for a in args) else
                                [f"run.out_dir={out}"]), *args)
    assert proc.returncode == 2, proc.stderr
    assert named in proc.stderr, proc.stderr
    assert len(proc.stderr.strip().splitlines()) == 1, proc.stderr
    assert "Traceback" not in proc.stderr
    assert not out.exists() and not (tmp_path / "hydra").exists()
    assert files(inputs) == before


def _run_json(path: Path) -> dict:
    return json.loads((path / "run.json").read_text())


def test_refused_run_on_a_finished_directory_touches_nothing(tmp_path):
    done = tmp_path / "done"
    assert swarmbox(tmp_path, f"hydra.run.dir={done}").returncode == 0
    snapshot = {p: p.read_bytes() for p in done.rglob("*") if p.is_file()}
    for target in (f"hydra.run.dir={done}", f"run.out_dir={done}"):
        proc = swarmbox(tmp_path, "seed=9", target)
        assert proc.returncode == 2 and "refusing to overwrite" in proc.stderr
        assert "Traceback" not in proc.stderr
    assert {p: p.read_bytes() for p in done.rglob("*") if p.is_file()} == snapshot
    assert not (done / ".hydra").exists()


def _runtime(tmp_path: Path, *args: str) -> tuple[subprocess.CompletedProcess, Path, dict]:
    out = tmp_path / "run"
    proc = swarmbox(tmp_path, f"run.out_dir={out}", *args)
    assert not list(out.rglob("*.partial"))
    return proc, out, _run_json(out)


@pytest.mark.parametrize("case, algo, extra, named", [
    ("11-hook-raises", "CrashingDrone", [], "drone 0: exec_loop/exec_complete raised ZeroDivisionError"),
    ("13-returns-tuple", "TupleDrone", [], "drone 0: exec_loop returned tuple"),
    ("14-never-returns", "HangingDrone", ["run.hook_timeout_s=0.5"],
     "drone 1: exec_loop/exec_complete did not return within 0.5 s (run.hook_timeout_s)"),
    ("14-sleeps-forever", "HangingDrone", ["run.hook_timeout_s=0.5", "+algo.params.hang=sleep"],
     "drone 1: exec_loop/exec_complete did not return within 0.5 s"),
])
def test_failing_hook_fails_the_run_truthfully(tmp_path, case, algo, extra, named):
    proc, out, manifest = _runtime(tmp_path, f"algo.drone._target_=tests.run.algos.{algo}", *extra)
    assert proc.returncode == 1, proc.stderr
    assert named in proc.stderr and str(out) in proc.stderr
    assert "Traceback" not in proc.stderr and "run.json" in proc.stderr
    assert manifest["status"] == "failed" and named in manifest["reason"]
    assert "Traceback" in manifest["traceback"]
    assert manifest["sim_time_s"] > 0.5 and manifest["ticks"] > 20
    state = pd.read_parquet(out / "logs" / "drone_0" / "state.parquet")
    assert state["t_s"].max() == pytest.approx(manifest["sim_time_s"], abs=0.1)


def test_verbose_switch_prints_the_traceback(tmp_path):
    proc = swarmbox(tmp_path, f"run.out_dir={tmp_path / 'r'}",
                    "algo.drone._target_=tests.run.algos.TupleDrone", "--verbose")
    assert proc.returncode == 1 and "Traceback (most recent call last)" in proc.stderr


@pytest.mark.parametrize("bad, event", [("nan_position", "setpoint_refused"), ("far", "setpoint_refused"),
                                        ("fast", "setpoint_clamped")])
def test_wild_setpoints_are_refused_or_clamped_and_recorded(tmp_path, bad, event):
    proc, out, manifest = _runtime(tmp_path, "algo.drone._target_=tests.run.algos.BadSetpointDrone",
                                   f"+algo.params.bad={bad}")
    assert proc.returncode == 0, proc.stderr
    assert manifest["status"] == "ok"
    assert f"safety: drones [0, 1, 2, 3] {event}" in manifest["reason"], manifest["reason"]
    assert set(manifest["safety"][event]) == {"0", "1", "2", "3"}
    for i in range(4):
        ev = pd.read_parquet(out / "logs" / f"drone_{i}" / "events.parquet")
        assert (ev["name"] == event).any()
        last = pd.read_parquet(out / "logs" / f"drone_{i}" / "state.parquet").iloc[-1]
        assert last["landed"] and not last["armed"]


def wait_for_files(where: Path, n: int, proc: subprocess.Popen, timeout_s: float = 300.0) -> None:
    """Until ``n`` runs have flown their first EXECUTION tick (SlowDrone's ``started_dir``): a loaded
    machine takes longer to get there, so the test waits for it, not for a fixed time."""
    deadline = time.monotonic() + timeout_s
    while len(list(where.iterdir())) < n:
        assert proc.poll() is None, "the run ended before it was interrupted"
        assert time.monotonic() < deadline, f"fewer than {n} runs started within {timeout_s:.0f} s"
        time.sleep(0.02)


def test_sigterm_marks_a_single_run_interrupted_with_the_time_reached(tmp_path):
    out, started = tmp_path / "run", tmp_path / "started"
    started.mkdir()
    cmd = [sys.executable, "-m", "swarmbox.run", "algo=hover", "mission=hover", "run.progress=false",
           "algo.drone._target_=tests.run.algos.SlowDrone", "+algo.params.delay_s=0.002",
           f"+algo.params.started_dir={started}", "algo.params.hover_s=60", "mission.max_sim_time_s=100",
           f"run.out_dir={out}", f"hydra.run.dir={tmp_path / 'hydra'}"]
    proc = subprocess.Popen(cmd, cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    wait_for_files(started, 1, proc)
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 128 + signal.SIGTERM, err
    manifest = _run_json(out)
    assert manifest["status"] == "interrupted" and "SIGTERM" in manifest["reason"]
    assert manifest["sim_time_s"] > 0 and manifest["ticks"] > 0
    assert "INTERRUPTED" in err and "Traceback" not in err
    assert not list(out.rglob("*.partial"))


def test_sigint_mid_sweep_finishes_the_run_writes_the_summary_and_exits_130(tmp_path):
    sweep, started = tmp_path / "sweep", tmp_path / "started"
    started.mkdir()
    cmd = [sys.executable, "-m", "swarmbox.run", "-m", *HOVER, "seed=range(6)",
           "algo.drone._target_=tests.run.algos.SlowDrone", "+algo.params.delay_s=0.002",
           f"+algo.params.started_dir={started}", f"hydra.sweep.dir={sweep}"]
    proc = subprocess.Popen(cmd, cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    wait_for_files(started, 3, proc)   # runs 0 and 1 done, run 2 flying
    proc.send_signal(signal.SIGINT)
    out, err = proc.communicate(timeout=60)
    assert proc.returncode == 130, err
    runs = [_run_json(d) for d in sweep.iterdir() if (d / "run.json").exists()]
    statuses = {m["seed"]: m["status"] for m in runs}
    assert statuses == {0: "ok", 1: "ok", 2: "interrupted"}
    interrupted = _run_json(sweep_job(sweep, 2))
    assert interrupted["sim_time_s"] > 0 and "SIGINT" in interrupted["reason"]
    summary = json.loads((sweep / "sweep.json").read_text())
    assert summary["counts"] == {"ok": 2, "interrupted": 1} and len(summary["not_started"]) == 3
    assert summary["interrupted_by"] == "SIGINT"
    assert "3 not started" in out and not list(sweep.rglob("*.partial"))
    assert sorted(p.name for p in sweep.iterdir()) == sorted(
        [*(sweep_job(sweep, s).name for s in range(3)), "multirun.yaml", "sweep.json"])


def test_no_vehicle_at_the_configured_port_fails_naming_it(tmp_path):
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    proc, out, manifest = _runtime(tmp_path, "backend=px4", "mission.swarm_size=1",
                                   "mission.initial_positions=null", "mission.initial_positions={0:[0,0]}",
                                   f"backend.connections=[udpin:127.0.0.1:{port}]",
                                   "backend.connect_timeout_s=1")
    assert proc.returncode == 1
    assert f"udpin:127.0.0.1:{port}" in proc.stderr and "not heard" in proc.stderr
    assert "Traceback" not in proc.stderr
    assert manifest["status"] == "failed" and manifest["ticks"] == 0


def test_vehicle_link_lost_ends_the_run_when_the_others_are_down_naming_the_drone(run):
    """Case 19 on the runner side: a vehicle falls silent mid-mission (its mavsim process is killed)."""
    # the pace the machine allows now, and a link timeout (run time) a vehicle process kept off a
    # loaded CPU for a while cannot reach: only the killed vehicle's link is lost
    manifest, d = run("algo=hover", "mission=hover", "algo.params.hover_s=6", "backend=mavsim",
                      f"run.speed={realtime.speed(4.0)}", "backend.link_timeout_s=6",
                      "mission.max_sim_time_s=200",
                      prepare=lambda s: s.schedule(5.0, lambda sw: sw.backend.processes[1].kill()))
    assert "drone 1 link lost" in manifest["reason"], manifest["reason"]
    assert "max_sim_time_s" not in manifest["reason"]
    assert manifest["sim_time_s"] < 60, manifest["reason"]
    for i in (0, 2, 3):
        last = pd.read_parquet(d / "logs" / f"drone_{i}" / "state.parquet").iloc[-1]
        assert last["landed"] and not last["armed"]


def test_ground_link_cut_ends_when_all_drones_are_down_with_the_cause(run):
    manifest, d = run("algo=hover", "mission=hover", "algo.params.hover_s=30", "fault=link_cut",
                      "fault.targets=[-1]", "fault.onset_s=10", "mission.max_sim_time_s=300")
    assert manifest["status"] == "aborted" and manifest["sim_time_s"] < 60
    assert "drones [0, 1, 2, 3] landed and disarmed (ABORT: lost superior -1" in manifest["reason"]


def test_kill_9_leaves_no_finished_run_and_the_analyzer_names_the_directory(tmp_path):
    out = tmp_path / "runs" / "killed"
    cmd = [sys.executable, "-m", "swarmbox.run", "algo=hover", "mission=hover", "run.progress=false",
           "algo.drone._target_=tests.run.algos.SlowDrone", "+algo.params.delay_s=0.002",
           "algo.params.hover_s=60", "mission.max_sim_time_s=100", f"run.out_dir={out}",
           f"hydra.run.dir={tmp_path / 'hydra'}"]
    proc = subprocess.Popen(cmd, cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    while not (out / "config.yaml").exists() and proc.poll() is None:
        time.sleep(0.05)
    time.sleep(0.5)
    proc.kill()
    proc.wait(timeout=30)
    assert not (out / "run.json").exists()
    assert all(p.name.endswith(".partial") for p in (out / "logs").rglob("*") if p.is_file())
    analyze = subprocess.run([sys.executable, "-m", "swarmbox.analyze", str(tmp_path / "runs")], cwd=ROOT,
                             capture_output=True, text=True, timeout=120)
    assert analyze.returncode == 2 and f"skipped: {out}: no run.json" in analyze.stderr
