"""The live monitor: when it is on, what it reads, and what it shows at the end of a run."""

from __future__ import annotations

import subprocess
import sys

import pytest

from swarmbox.monitor import rerun_target, wanted
from tests.conftest import table

CROSSING = ("algo=crossing", "mission=crossing", "run.proximity_m=10")


def test_on_by_default_only_for_real_time_backends_on_a_terminal():
    assert wanted("auto", realtime=True, multirun=False, tty=True)
    assert not wanted("auto", realtime=False, multirun=False, tty=True)     # simulation
    assert not wanted("auto", realtime=True, multirun=True, tty=True)       # a sweep
    assert not wanted("auto", realtime=True, multirun=False, tty=False)     # output to a file or pipe
    assert wanted("on", realtime=False, multirun=True, tty=False)
    assert not wanted("off", realtime=True, multirun=False, tty=True)
    with pytest.raises(ValueError, match="run.monitor must be one of auto, on, off"):
        wanted("yes", realtime=True, multirun=False)


def test_simulation_run_with_the_monitor_on_shows_the_final_state(run, capsys):
    manifest, d = run(*CROSSING, "run.monitor=on", "run.monitor_hz=50")
    assert manifest["status"] == "ok", manifest["reason"]
    mon = manifest["monitor"]
    assert mon["frames"] >= 1 and mon["snapshots"] >= 1 and 0 < mon["cpu_share"] < 1
    screen = capsys.readouterr().err
    assert "stage TERMINATION" in screen and "drones 4/4 alive" in screen
    # both proximity episodes of the crossing, as the ground logged them
    assert "proximity 0-1 over: closest 2.0 m" in screen and "proximity 0-2 over: closest 8.5 m" in screen
    for i in range(4):
        assert f"\n    {i}  alive" in screen


def test_monitor_leaves_the_logs_unchanged(run):
    _, plain = run(*CROSSING, "run.monitor=off")
    _, watched = run(*CROSSING, "run.monitor=on")
    for node, name in (("ground", "events"), ("ground", "messages"), ("drone_1", "state")):
        a, b = table(plain, node, name), table(watched, node, name)
        assert a.equals(b), (node, name)


def test_a_relative_rerun_path_is_inside_the_run_directory(tmp_path):
    run_dir = tmp_path / "runs" / "r1"
    assert rerun_target("live.rrd", run_dir) == str(run_dir / "live.rrd")
    assert rerun_target("rec/live.rrd", run_dir) == str(run_dir / "rec" / "live.rrd")
    assert rerun_target(str(tmp_path / "x.rrd"), run_dir) == str(tmp_path / "x.rrd")
    url = "rerun+http://127.0.0.1:9876/proxy"
    assert rerun_target(url, run_dir) == url


@pytest.mark.replay
def test_live_stream_to_a_rerun_recording(run, tmp_path, monkeypatch):
    rrc = pytest.importorskip("rerun.chunk", reason="needs the replay extra (Rerun)")

    cwd = tmp_path / "cwd"
    cwd.mkdir()
    monkeypatch.chdir(cwd)
    manifest, run_dir = run(*CROSSING, "run.monitor=off", "run.rerun=live/stream.rrd", "run.monitor_hz=40")
    assert manifest["status"] == "ok", manifest["reason"]
    target = run_dir / "live" / "stream.rrd"    # a relative path lands in the run dir, not the cwd
    assert target.is_file() and list(cwd.iterdir()) == []
    assert manifest["monitor"]["rerun_frames"] >= 1
    entities, texts = set(), []
    for chunk in rrc.RrdReader(target).store().stream():
        entities.add(chunk.entity_path)
        if chunk.entity_path == "/events":
            texts += chunk.to_record_batch().column("TextLog:text").to_pylist()
    assert {f"/world/drones/{i}" for i in range(4)} <= entities
    assert {f"/world/links/ground_drone_{i}" for i in range(4)} <= entities
    flat = " ".join(str(t) for t in texts)
    assert "stage TERMINATION" in flat and "proximity 0-1 over" in flat


@pytest.mark.slow
@pytest.mark.replay
def test_live_stream_to_a_rerun_server_over_grpc(run, tmp_path):
    """The same stream to a real Rerun server on 127.0.0.1, which saves what it receives."""
    import signal
    import socket
    import subprocess
    import sys
    import time
    import warnings

    rrc = pytest.importorskip("rerun.chunk", reason="needs the replay extra (Rerun)")

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    saved = tmp_path / "server.rrd"
    server = subprocess.Popen([sys.executable, "-m", "rerun", "--bind", "127.0.0.1", "--port", str(port),
                               "--save", str(saved)], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        deadline = time.monotonic() + 30
        while time.monotonic() < deadline:
            with socket.socket() as probe:
                if probe.connect_ex(("127.0.0.1", port)) == 0:
                    break
            time.sleep(0.2)
        manifest, _ = run(*CROSSING, "run.monitor=off", f"run.rerun=rerun+http://127.0.0.1:{port}/proxy")
        assert manifest["status"] == "ok" and manifest["monitor"]["rerun_frames"] >= 1
        time.sleep(2)
    finally:
        server.send_signal(signal.SIGINT)
        try:
            server.wait(timeout=15)
        except subprocess.TimeoutExpired:
            server.kill()
            server.wait()
    rows: dict[str, int] = {}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")   # the server's file is a plain stream (no footer)
        for chunk in rrc.RrdReader(saved).stream():
            rows[chunk.entity_path] = rows.get(chunk.entity_path, 0) + chunk.num_rows
    assert all(rows.get(f"/world/drones/{i}", 0) == manifest["monitor"]["rerun_frames"] for i in range(4))
    assert rows["/events"] >= 4


def test_a_rerun_target_without_the_replay_extra_is_refused_before_anything_is_written(tmp_path):
    """Without the rerun package, run.rerun is a bad input (exit 2, one line), not a failed run."""
    out = tmp_path / "run"
    code = ("import sys; sys.modules['rerun'] = None; "   # as if the replay extra were not installed
            f"sys.argv = ['swarmbox run', 'run.rerun=live.rrd', 'run.out_dir={out}']; "
            "from swarmbox.run.__main__ import cli; cli()")
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2, proc.stderr
    assert proc.stderr.strip().count("\n") == 0 and "swarmbox[replay]" in proc.stderr
    assert not out.exists()
