"""The dashboard in a real terminal: a mavsim mission under tmux, screens captured as it flies.

Four MAVLink vehicles over UDP on 127.0.0.1, the run loop at 4x real time, and drone 2's radio cut
12 s in: the ground must show the stages as they pass, four drones, then drone 2 as LOST.
"""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import sys
import time
import uuid
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]

pytestmark = [pytest.mark.slow,
              pytest.mark.skipif(shutil.which("tmux") is None, reason="tmux not installed")]

ROW = re.compile(r"^\s+(\d+)\s+(alive|LOST [\d.]+s)\s+([A-Z]+)\s", re.M)


def _tmux(socket: str, *args: str) -> str:
    return subprocess.run(["tmux", "-L", socket, *args], capture_output=True, text=True, check=False).stdout


def test_dashboard_shows_stages_drones_and_a_lost_link(tmp_path):
    socket, run_dir = f"swarmbox-{uuid.uuid4().hex[:8]}", tmp_path / "run"
    cmd = (f"cd {ROOT} && PYTHONPATH={os.environ.get('PYTHONPATH', ROOT)} {sys.executable} -m swarmbox.run "
           f"backend=mavsim run.speed=4 algo=hover mission=hover algo.params.hover_s=16 "
           f"fault=link_cut 'fault.targets=[2]' fault.onset_s=12 run.out_dir={run_dir}; "
           f"echo EXIT=$?; sleep 600")
    _tmux(socket, "new-session", "-d", "-s", "run", "-x", "110", "-y", "40", cmd)
    screens: list[str] = []
    try:
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline:
            screen = _tmux(socket, "capture-pane", "-p", "-t", "run")
            screens.append(screen)
            if "EXIT=" in screen:
                break
            time.sleep(0.5)
    finally:
        _tmux(socket, "kill-server")
    final = screens[-1]
    assert "EXIT=0" in final, final
    manifest = json.loads((run_dir / "run.json").read_text())
    assert manifest["monitor"]["frames"] > 10        # auto: on for a real-time backend on a terminal

    seen_stages = set()
    for s in screens:
        seen_stages |= set(re.findall(r"stage (ICEBREAK|PREPARATION|EXECUTION|LANDING|TERMINATION)", s))
    assert {"EXECUTION", "LANDING", "TERMINATION"} <= seen_stages

    flying = [s for s in screens if "stage EXECUTION" in s and "drones 4/4 alive" in s]
    assert flying, "no screen with the four drones flying"
    assert {int(m[0]) for m in ROW.findall(flying[-1])} == {0, 1, 2, 3}

    cut = [s for s in screens if "1 lost" in s]
    assert cut, "the lost link never showed"
    rows = {int(m[0]): m[1] for m in ROW.findall(cut[0])}
    assert rows[2].startswith("LOST") and all(rows[i] == "alive" for i in (0, 1, 3)), cut[0]
    assert "drones 3/4 alive" in cut[0]
    assert "inferior_lost (drone 2)" in "".join(screens)
