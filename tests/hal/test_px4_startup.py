"""``backend=px4`` says at once what it does (launch which build, or wait on which ports), and a port
that is taken names the key that moves the run elsewhere. Real subprocesses and real sockets."""

from __future__ import annotations

import json
import os
import socket
import subprocess
import sys
import threading
import time

import pytest

from tests.conftest import ROOT

SHARED_BUILD = ROOT.parent / "shared" / "px4-sitl"
HOVER = ["algo=hover", "mission=hover", "run.monitor=off", "run.progress=false"]
# The child runs the real command on a machine that has no shared PX4 build: the candidates point elsewhere.
NO_SHARED_BUILD = ("import sys, swarmbox.hal.px4.sitl as sitl; sitl.SHARED_BUILDS = (sys.argv.pop(1),); "
                   "from swarmbox.cli import main; sys.exit(main(sys.argv[1:]))")


def start(args, cwd, prelude=None):
    env = {k: v for k, v in os.environ.items() if k != "SWARMBOX_PX4_BUILD"}
    env["PYTHONPATH"] = str(ROOT)
    cmd = [sys.executable, "-c", prelude, *args] if prelude else [sys.executable, "-m", "swarmbox.cli", *args]
    return subprocess.Popen(cmd, cwd=cwd, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def timed_lines(stream, out):
    for line in stream:
        out.append((time.monotonic(), line.rstrip("\n")))


def run_timed(proc, timeout=120):
    """(monotonic time of each stderr line, line), the process's end time and its stdout."""
    lines: list[tuple[float, str]] = []
    reader = threading.Thread(target=timed_lines, args=(proc.stderr, lines), daemon=True)
    reader.start()
    stdout = proc.stdout.read()
    proc.wait(timeout=timeout)
    ended = time.monotonic()
    reader.join(timeout=5)
    return lines, ended, stdout


def free_udp_port():
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_no_build_found_says_so_before_waiting_and_names_the_ports(tmp_path):
    out = tmp_path / "r"
    proc = start([str(tmp_path / "nowhere"), "run", "backend=px4", *HOVER, "backend.connect_timeout_s=3",
                  f"run.out_dir={out}"], tmp_path, prelude=NO_SHARED_BUILD)
    lines, ended, _ = run_timed(proc)
    said = [(t, line) for t, line in lines if line.startswith("px4 backend: no PX4 build found")]
    assert len(said) == 1, [line for _, line in lines]
    t_said, line = said[0]
    assert "SWARMBOX_PX4_BUILD is unset" in line and str(tmp_path / "nowhere") in line
    assert "4 vehicle(s) already running, on UDP ports 14540-14543" in line and "up to 3 s" in line
    assert ended - t_said >= 3.0        # said before the 3 s wait, not after it
    assert proc.returncode == 1
    manifest = json.loads((out / "run.json").read_text())
    assert manifest["status"] == "failed" and "not heard (HEARTBEAT" in manifest["reason"]


def test_launching_names_the_build_and_its_instances(tmp_path):
    if not (SHARED_BUILD / "bin" / "px4").is_file():
        pytest.skip(f"no PX4 SITL build at {SHARED_BUILD}")
    port = 24540 + 41                    # instance 41's bridge port (first_instance=40, vehicle 1)
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as taken:
        taken.bind(("127.0.0.1", port))  # another program holds vehicle 1's port: PX4 never starts
        proc = start(["run", "backend=px4", *HOVER, f"backend.px4_build={SHARED_BUILD}",
                      "backend.sitl.first_instance=40", f"run.out_dir={tmp_path / 'r'}"], tmp_path)
        lines, _, stdout = run_timed(proc)
    text = [line for _, line in lines]
    assert f"px4 backend: launching 4 PX4 SITL instance(s) 40-43 from {SHARED_BUILD.resolve()}" in text[0]
    assert "backend.sitl.first_instance=40" in text[0]
    assert proc.returncode == 1
    reason = json.loads((tmp_path / "r" / "run.json").read_text())["reason"]
    assert reason.startswith(f"OSError: px4 backend: UDP port {port} of vehicle 1 (PX4 instance 41) "
                             "is in use")
    assert "backend.sitl.first_instance=N (now 40" in reason and "\n" not in reason
    failed = [line for line in text if line.startswith("FAILED")]
    assert len(failed) == 1 and "backend.sitl.first_instance=N" in failed[0]
    assert not (tmp_path / "r" / "px4" / "instance_40" / "out.log").exists()   # nothing was launched


def test_a_taken_port_of_a_running_vehicle_names_the_connections_key(tmp_path):
    port = free_udp_port()
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as taken:
        taken.bind(("127.0.0.1", port))
        links = ["udpin:127.0.0.1:0", "udpin:127.0.0.1:0", f"udpin:127.0.0.1:{port}", "udpin:127.0.0.1:0"]
        proc = start(["run", "backend=px4", *HOVER, f"backend.connections=[{','.join(links)}]",
                      f"run.out_dir={tmp_path / 'r'}"], tmp_path)
        lines, _, _ = run_timed(proc)
    assert lines[0][1].startswith(f"px4 backend: connecting to 4 running vehicle(s) at {', '.join(links)}")
    assert proc.returncode == 1
    reason = json.loads((tmp_path / "r" / "run.json").read_text())["reason"]
    assert f"UDP port {port} of vehicle 2" in reason and "backend.connections=[...]" in reason
