"""What the px4 bridge does when a vehicle cannot be trusted or does not obey, end to end through
the runner with mavsim vehicles on 127.0.0.1: an impostor with drone 1's system id, an autopilot that
denies arming, a vehicle whose heartbeat stops. Each ends with the drone's own event and stage
reason, nothing left armed, and the run over once nothing is left flying."""

from __future__ import annotations

import json
import signal
import subprocess
import sys
from pathlib import Path

import pytest

from tests import realtime
from tests.conftest import table

ROOT = Path(__file__).resolve().parents[2]
HOVER = ("algo=hover", "mission=hover", "algo.params.hover_s=6", "run.speed=4", "backend=mavsim",
         "backend.link_timeout_s=2", "backend.command_retries=2", "mission.max_sim_time_s=120")
HOMES = [(0, 0), (5, 0), (10, 0), (15, 0)]
#: For the default test run: the pace the machine allows now, and a link timeout that load alone
#: (a vehicle process kept off the CPU for a while) cannot reach; what it checks is counted by the
#: protocol (the autopilot's refusals, each retry), not timed.
UNDER_LOAD = (*(x for x in HOVER if not x.startswith(("run.speed=", "backend.link_timeout_s="))),
              f"run.speed={realtime.speed(4.0)}", "backend.link_timeout_s=8")


def events(d: Path, i: int, kind: str | None = None):
    ev = table(d, f"drone_{i}", "events")
    return ev if kind is None else ev[ev["kind"] == kind]


def stage_reason(d: Path, i: int) -> tuple[str, str]:
    last = table(d, f"drone_{i}", "stages").iloc[-1]
    return last["name"], last["reason"]


def assert_nothing_armed_in_the_air(d: Path, skip: tuple[int, ...] = ()) -> None:
    for i in range(4):
        if i not in skip:
            last = table(d, f"drone_{i}", "state").iloc[-1]
            assert last["landed"] and not last["armed"], f"drone {i} left armed or airborne"


@pytest.mark.slow
def test_impostor_with_drone_1s_system_id_is_dropped_and_flagged(run):
    impostors: list[subprocess.Popen] = []

    def impostor(swarm) -> None:
        port = swarm.backend.local_ports[1]    # a second vehicle, 53 m away, speaking as system 2
        impostors.append(subprocess.Popen(
            [sys.executable, "-m", "swarmbox.hal.mavsim.process", "--instance", "1", "--system-id", "2",
             "--home-n", "53", "--port-plan", f"{port}:0", "--speed", "4", "--max-wall-s", "60"],
            cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL))

    try:
        manifest, d = run(*HOVER, prepare=lambda s: s.schedule(1.0, impostor))
    finally:
        for p in impostors:
            p.kill()
            p.wait()
    assert manifest["status"] == "ok", manifest["reason"]
    conflict = events(d, 1, "link")
    conflict = conflict[conflict["name"] == "conflict"]
    assert len(conflict) == 1
    data = json.loads(conflict["data"].iloc[0])
    assert data["system_id"] == 2 and data["action"] == "dropped" and data["address"] != data["bound"]
    st = table(d, "drone_1", "state")
    assert (st["pos_n"] - HOMES[1][0]).abs().max() < 1.0, "the impostor's position leaked in"
    assert (st["armed"].astype(int).diff().abs() > 0).sum() == 2, "armed flipped more than arm + disarm"
    assert_nothing_armed_in_the_air(d)


def test_autopilot_denying_arm_aborts_that_drone_with_the_reason(run):
    manifest, d = run(*UNDER_LOAD, "+backend.refuse.drone_1=[arm]")
    failure = events(d, 1, "failure")
    assert list(failure["name"]) == ["command_failed"]
    data = json.loads(failure["data"].iloc[0])
    assert data["command"] == "arm_disarm" and data["result"] == "denied" and data["tries"] == 3
    stage, reason = stage_reason(d, 1)
    assert stage == "ABORT" and reason == "autopilot refused arm_disarm (denied after 3 tries)"
    for i in (0, 2, 3):
        assert stage_reason(d, i)[0] == "TERMINATION"
    reason = manifest["reason"]
    assert ("drones [1] aborted" in reason
            or "drone 1 landed and disarmed (ABORT: autopilot refused arm_disarm" in reason), manifest
    assert manifest["sim_time_s"] < 60
    assert_nothing_armed_in_the_air(d)


@pytest.mark.slow
def test_vehicle_heartbeat_stopping_is_a_lost_link_and_the_run_ends(run):
    pytest.importorskip("swarmbox.core.ending", reason="needs the run end when every drone is down or lost")
    frozen: list = []

    def freeze(swarm) -> None:
        proc = swarm.backend.processes[2]
        proc.send_signal(signal.SIGSTOP)
        frozen.append(proc)

    try:
        manifest, d = run(*HOVER, prepare=lambda s: s.schedule(6.0, freeze))
    finally:
        for p in frozen:
            p.send_signal(signal.SIGCONT)
    lost = events(d, 2, "link")
    lost = lost[lost["name"] == "lost"]
    assert len(lost) == 1 and 6.0 < lost["t_s"].iloc[0] < 8.5     # link_timeout_s after the last heartbeat
    stage, reason = stage_reason(d, 2)
    assert stage == "ABORT" and reason == "link to the autopilot lost"
    assert_nothing_armed_in_the_air(d, skip=(2,))
    assert "drone 2 link lost" in manifest["reason"] or "lost drones [2]" in manifest["reason"], manifest
    assert manifest["sim_time_s"] < 60, "the run idled after the last drone was down or lost"
