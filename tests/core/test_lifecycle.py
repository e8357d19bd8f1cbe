"""The lifecycle contract on real runs: stage entry before tasks, in-order exactly-once delivery,
one meaning of ``ctx.tick``, the ground's ``prep_complete``, no wait on aborted drones."""

import json

import pytest

from swarmbox.api import Stage
from tests.conftest import table

PROBE = ["algo=hover", "mission=hover", "algo.drone._target_=tests.core.algos.StatefulDrone",
         "+algo.ground._target_=tests.core.algos.NumberedGround"]
LOSSY = ["network.loss_prob=0.3", "network.jitter_ms=20", "network.latency_ms=5"]


def markers(run_dir, node, name):
    ev = table(run_dir, node, "events")
    return [json.loads(d) for d in ev[(ev["kind"] == "marker") & (ev["name"] == name)]["data"]]


def _check_probe_run(manifest, d):
    assert manifest["status"] == "ok", manifest["reason"]
    for i in range(4):
        assert markers(d, f"drone_{i}", "tasks") == [{"received": 40}], i
        assert list(table(d, f"drone_{i}", "stages")["stage"]) == [1, 2, 3, 4, 5]


def test_tasks_sent_in_ground_prep_once_arrive_after_the_drones_prep_once(run):
    manifest, d = run(*PROBE, *LOSSY, "seed=1")
    _check_probe_run(manifest, d)
    # ctx.tick is 0 on every node's entry tick, and the ground's loop runs in its entry tick too
    assert markers(d, "ground", "ground_prep_once") == [{"tick": 0}]
    assert markers(d, "ground", "ground_prep_loop") == [{"tick": 0}]
    for i in range(4):
        assert markers(d, f"drone_{i}", "drone_prep_once") == [{"tick": 0}]


@pytest.mark.slow
@pytest.mark.parametrize("seed", range(20))
def test_stateful_prep_and_40_reliable_tasks_survive_30pc_loss_and_jitter(run, seed):
    """Acceptance: state set in prep_once, 40 numbered tasks from the ground's prep_once, 30 % loss,
    20 ms jitter: every drone gets all 40, in order, exactly once (the drone raises otherwise)."""
    _check_probe_run(*run(*PROBE, *LOSSY, f"seed={seed}"))


def test_the_ground_announces_a_stage_in_the_tick_it_enters_it(run):
    manifest, d = run(*PROBE, "+algo.params.n_tasks=1")
    assert manifest["status"] == "ok", manifest["reason"]
    ground = table(d, "ground", "stages").set_index("stage")["tick"]
    for i in range(4):
        drone = table(d, f"drone_{i}", "stages").set_index("stage")["tick"]
        for stage in (Stage.PREPARATION, Stage.EXECUTION, Stage.LANDING, Stage.TERMINATION):
            # ideal network: the Heartbeat sent in the ground's entry tick is handled in the next one
            assert drone[stage] == ground[stage] + 1, (i, stage.name)


def test_ground_prep_complete_holds_preparation_open(run):
    manifest, d = run("algo=hover", "mission=hover", "+algo.ground._target_=tests.core.algos.SlowPrepGround")
    assert manifest["status"] == "ok", manifest["reason"]
    st = table(d, "ground", "stages").set_index("stage")["t_s"]
    assert st[Stage.EXECUTION] - st[Stage.PREPARATION] == pytest.approx(3.0, abs=0.05)


def test_the_ground_does_not_wait_out_termination_for_an_aborted_drone(run):
    """A drone that aborted on its own (and landed) keeps reporting ABORT: the ground must finish
    as soon as the others have terminated, not after run.timeouts_s.TERMINATION."""
    manifest, d = run("algo=hover", "mission=hover", "algo.params.hover_s=1", "run.timeouts_s.TERMINATION=30",
                      prepare=_abort_drone_3_after_takeoff)
    assert manifest["status"] == "ok", manifest["reason"]
    assert "drones [3] aborted" in manifest["reason"]
    ground = table(d, "ground", "stages").set_index("stage")["t_s"]
    assert manifest["sim_time_s"] - ground[Stage.TERMINATION] < 2.0


def _abort_drone_3_after_takeoff(swarm):
    def abort(s):
        agent = s._by_id[3]
        agent.enter(Stage.ABORT, "test: local abort", failsafe=False)
    swarm.schedule(4.0, abort)
