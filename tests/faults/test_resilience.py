"""Resilience under faults: successor handover, failsafe return-to-launch, the ground carrying on."""

import json
import math

import pytest

from swarmbox.core.stages import Stage
from tests.conftest import table

HOMES = [(0, 0), (-3, -3), (-3, 3), (-6, -6)]


def stage_names(run_dir, node):
    return list(table(run_dir, node, "stages")["name"])


def formation_errors(run_dir, drone, t0):
    ev = table(run_dir, f"drone_{drone}", "events")
    marks = ev[(ev["name"] == "formation_error") & (ev["t_s"] > t0)]
    return [json.loads(x)["error_m"] for x in marks["data"]]


def _leader_crash(run, *extra):
    return run("topology=leader_follower", "fault=crash", "fault.targets=[0]", "fault.onset_s=40", *extra)


def _check_followers_carry_on(manifest, d):
    assert manifest["status"] == "ok", manifest["reason"]
    assert "lost drones [0]" in manifest["reason"]
    for follower in (1, 2, 3):
        ev = table(d, f"drone_{follower}", "events")
        handover = ev[ev["name"] == "handover"]
        assert len(handover) == 1 and json.loads(handover["data"].iloc[0]) == {"lost": 0, "new": -1}
        assert 40.9 < handover["t_s"].iloc[0] < 41.2          # lost_superior_ticks after the crash
        assert stage_names(d, f"drone_{follower}")[-1] == "TERMINATION"
        # the mission went on: still flying the circle in formation, then home
        errors = formation_errors(d, follower, 43.0)
        assert len(errors) > 20 and max(errors) < 3.0
        last = table(d, f"drone_{follower}", "state").iloc[-1]
        home = HOMES[follower]
        assert last["landed"] and math.hypot(last["true_n"] - home[0], last["true_e"] - home[1]) < 1.5
    ground = table(d, "ground", "events")
    joined = ground[(ground["name"] == "inferior_joined") & (ground["t_s"] > 40)]
    assert sorted(joined["subject"]) == [1, 2, 3]
    tasks = table(d, "ground", "messages").query("kind == 'send' and type == 'task' and t_s > 42")
    assert set(tasks["dst"]) == {1, 2, 3}
    assert stage_names(d, "ground")[-1] == "TERMINATION"


def test_leader_crash_followers_hand_over_and_the_mission_continues(run):
    # The ground loses its only direct inferior (the leader) and waits for the followers to hand
    # over to it instead of aborting on min_alive.
    _check_followers_carry_on(*_leader_crash(run))


@pytest.mark.slow
def test_ground_link_cut_drones_return_home_and_land(run):
    manifest, d = run("fault=link_cut", "fault.targets=[-1]", "fault.onset_s=40")
    assert manifest["status"] == "aborted"
    for i, home in enumerate(HOMES):
        ev = table(d, f"drone_{i}", "events")
        lost = ev[ev["name"] == "superior_lost"]
        assert len(lost) == 1 and json.loads(lost["data"].iloc[0])["action"] == "return_to_launch"
        assert 40.9 < lost["t_s"].iloc[0] < 41.2
        st = table(d, f"drone_{i}", "state")
        assert "rtl" in set(st[st["t_s"] > 41.0]["mode"])
        last = st.iloc[-1]
        assert last["landed"] and not last["armed"]
        assert math.hypot(last["true_n"] - home[0], last["true_e"] - home[1]) < 1.0
        assert table(d, f"drone_{i}", "stages")["stage"].iloc[-1] == Stage.ABORT


@pytest.mark.slow
def test_follower_crash_ground_continues_with_the_alive_drones(run):
    manifest, d = run("fault=crash", "fault.targets=[3]", "fault.onset_s=40")
    assert manifest["status"] == "ok" and "lost drones [3]" in manifest["reason"]
    for node in ("ground", "drone_0", "drone_1", "drone_2"):
        assert stage_names(d, node)[-1] == "TERMINATION", node


@pytest.mark.slow
def test_battery_failsafe_ground_continues_with_the_others(run):
    manifest, d = run("fault=battery_failsafe", "fault.targets=[2]", "fault.onset_s=40",
                      "mission.max_sim_time_s=150")
    assert manifest["status"] == "ok", manifest["reason"]
    assert "drones [2] aborted" in manifest["reason"]
    assert stage_names(d, "drone_2")[-1] == "ABORT"
    for node in ("ground", "drone_0", "drone_1", "drone_3"):
        assert stage_names(d, node)[-1] == "TERMINATION", node
    last = table(d, "drone_2", "state").iloc[-1]
    assert last["landed"] and math.hypot(last["true_n"] - HOMES[2][0], last["true_e"] - HOMES[2][1]) < 1.0
