"""End-to-end runs on the pymunk backend: lifecycle, determinism, topologies, failures."""

import math

import numpy as np
import pandas as pd
import pytest

from swarmbox.core.stages import Stage
from swarmbox.core.topology import TopologyError
from swarmbox.run.build import ConfigError
from tests.conftest import table

NODES = ["ground", "drone_0", "drone_1", "drone_2", "drone_3"]
TABLES = {"ground": ["messages", "stages", "events"],
          **{f"drone_{i}": ["state", "messages", "stages", "events", "setpoints"] for i in range(4)}}


def stages(run_dir, node):
    return list(table(run_dir, node, "stages")["stage"])


def test_default_formation_runs_to_termination(run):
    manifest, d = run()
    assert manifest["status"] == "ok", manifest["reason"]
    assert manifest["choices"]["algo"] == "formation" and manifest["n_drones"] == 4
    assert manifest["real_time_factor"] > 1
    for node, tables in TABLES.items():
        for t in tables:
            assert (d / "logs" / node / f"{t}.parquet").is_file(), (node, t)
    for node in NODES:
        assert stages(d, node) == [1, 2, 3, 4, 5], node
    # The leader flew a circle of radius 9 m at 3 m: its track spans ~18 m north-south.
    st = table(d, "drone_0", "state")
    airborne = st[st["true_d"] < -2.5]
    assert 17.0 < airborne["true_n"].max() - airborne["true_n"].min() < 19.5
    assert airborne["true_d"].median() == pytest.approx(-3.0, abs=0.2)
    # Every drone landed back near home and disarmed.
    for i, home in enumerate([(0, 0), (-3, -3), (-3, 3), (-6, -6)]):
        last = table(d, f"drone_{i}", "state").iloc[-1]
        assert not last["armed"] and last["landed"]
        assert math.hypot(last["true_n"] - home[0], last["true_e"] - home[1]) < 1.5


def _logs(run_dir):
    return {(n, t): table(run_dir, n, t) for n, ts in TABLES.items() for t in ts}


def test_same_seed_gives_identical_logs_and_other_seeds_differ(run):
    a, da = run("seed=5", "network=wifi")
    b, db = run("seed=5", "network=wifi")
    c, dc = run("seed=6", "network=wifi")
    la, lb, lc = _logs(da), _logs(db), _logs(dc)
    for key in la:
        pd.testing.assert_frame_equal(la[key], lb[key], obj=str(key))
    assert a["sim_time_s"] == b["sim_time_s"] and a["ticks"] == b["ticks"]
    assert not la[("drone_1", "state")].equals(lc[("drone_1", "state")])


@pytest.mark.parametrize("topology", ["centralized", "leader_follower", "chain", "tree"])
def test_every_topology_completes_the_formation(run, topology):
    manifest, d = run(f"topology={topology}")
    assert manifest["status"] == "ok", manifest["reason"]
    for node in NODES:
        assert stages(d, node)[-1] == Stage.TERMINATION, node
    reporters = set(table(d, "ground", "messages").query("kind == 'recv' and type == 'report'")["src"])
    expected = {"centralized": {0, 1, 2, 3}, "leader_follower": {0}, "chain": {0}, "tree": {0}}
    assert reporters == expected[topology]


@pytest.mark.parametrize("superiors, cause", [
    ("{0:1,1:0,2:-1,3:-1}", "cycle"),
    ("{0:-1,1:9,2:-1,3:-1}", "unknown superior 9"),
])
def test_bad_topology_is_refused_with_the_cause_and_nothing_written(run, tmp_path, superiors, cause):
    with pytest.raises(TopologyError, match=f"topology.superiors: .*{cause}"):
        run("topology=explicit", f"topology.superiors={superiors}", name="bad")
    assert not (tmp_path / "bad").exists()


def test_removed_drone_does_not_stall_the_swarm(run):
    manifest, d = run(prepare=lambda s: s.schedule(40.0, lambda sw: sw.remove_agent(2)))
    assert manifest["status"] == "ok" and "lost drones [2]" in manifest["reason"]
    ev = table(d, "ground", "events")
    lost = ev[(ev["name"] == "inferior_lost") & (ev["subject"] == 2)]
    assert len(lost) == 1 and 40.0 < lost["t_s"].iloc[0] < 41.0
    assert stages(d, "ground")[-1] == Stage.TERMINATION


def test_lost_middle_of_a_chain_hands_over_to_the_successor(run):
    manifest, d = run("topology=chain", prepare=lambda s: s.schedule(40.0, lambda sw: sw.remove_agent(1)))
    assert manifest["status"] == "ok", manifest["reason"]
    ev = table(d, "drone_2", "events")
    handover = ev[ev["name"] == "handover"]
    assert len(handover) == 1 and '"new": 0' in handover["data"].iloc[0]
    assert stages(d, "drone_2")[-1] == Stage.TERMINATION and stages(d, "drone_3")[-1] == Stage.TERMINATION


def test_losing_the_ground_triggers_return_to_launch(run):
    manifest, d = run(prepare=lambda s: s.schedule(40.0, lambda sw: sw.medium.disconnect(-1)))
    assert manifest["status"] == "aborted"
    for i, home in enumerate([(0, 0), (-3, -3), (-3, 3), (-6, -6)]):
        ev = table(d, f"drone_{i}", "events")
        assert (ev["name"] == "superior_lost").sum() == 1
        st = table(d, f"drone_{i}", "state")
        assert "rtl" in set(st["mode"])
        last = st.iloc[-1]
        assert last["landed"] and math.hypot(last["true_n"] - home[0], last["true_e"] - home[1]) < 1.0


def test_stage_timeout_aborts_with_a_reason(run):
    manifest, d = run("algo=hover", "mission=hover", "algo.drone._target_=tests.run.algos.NeverDoneDrone",
                      "run.timeouts_s.EXECUTION=5")
    assert manifest["status"] == "aborted"
    assert "EXECUTION timed out after 5 s" in manifest["reason"]
    assert stages(d, "ground")[-1] == Stage.ABORT
    assert all(table(d, f"drone_{i}", "state").iloc[-1]["landed"] for i in range(4))


def test_crashing_algorithm_fails_the_run_and_keeps_the_logs(run):
    manifest, d = run("algo=hover", "mission=hover", "algo.drone._target_=tests.run.algos.CrashingDrone")
    assert manifest["status"] == "failed"
    assert "exec_loop" in manifest["reason"] and "ZeroDivisionError" in manifest["traceback"]
    st = table(d, "drone_0", "state")
    assert len(st) > 40 and (st["stage"] == Stage.EXECUTION).any()
    assert not list((d / "logs").rglob("*.partial"))


def test_hover_holds_altitude(run):
    manifest, d = run("algo=hover", "mission=hover", "algo.params.altitude_m=4")
    assert manifest["status"] == "ok"
    st = table(d, "drone_3", "state")
    hover = st[st["stage"] == Stage.EXECUTION].tail(40)
    assert np.allclose(hover["true_d"], -4.0, atol=0.3)


def test_node_clock_offsets_are_applied_and_recorded(run):
    manifest, d = run("algo=hover", "mission=hover", "run.clocks={drone_2: {offset_s: 0.5, drift_ppm: 100}}")
    assert manifest["clocks"] == {"drone_2": {"offset_s": 0.5, "drift_ppm": 100}}
    g, d2 = table(d, "ground", "stages"), table(d, "drone_2", "stages")
    # Both enter ICEBREAK at true time 0: the drone's local clock reads the offset.
    assert d2["t_s"].iloc[0] - g["t_s"].iloc[0] == pytest.approx(0.5)


def test_unknown_clock_node_is_refused(run, tmp_path):
    with pytest.raises(ConfigError, match="run.clocks: unknown node 'drone_9'"):
        run("algo=hover", "mission=hover", "run.clocks={drone_9: {offset_s: 1}}", name="bad")
    assert not (tmp_path / "bad").exists()
