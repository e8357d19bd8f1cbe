"""Protocol properties on whole runs (Hypothesis): under random loss, latency, jitter and a
partition, reliable tasks reach the algorithm in order and exactly once (the probe drone raises
otherwise), no node skips a stage, and every drone ends on the ground, disarmed, or in ABORT with
the reason logged."""

import json

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from swarmbox.api import Stage
from tests.conftest import run_config, table

N_TASKS = 12
PROBE = ["algo=hover", "mission=hover", "algo.drone._target_=tests.core.algos.StatefulDrone",
         "+algo.ground._target_=tests.core.algos.NumberedGround", f"+algo.params.n_tasks={N_TASKS}",
         "run.timeouts_s.PREPARATION=20", "mission.max_sim_time_s=90"]


def check_stages(stages: list[int], node: str) -> None:
    forward = [s for s in stages if s != Stage.ABORT]
    assert forward == list(range(1, len(forward) + 1)), f"{node} skipped a stage: {stages}"
    if Stage.ABORT in stages:
        assert stages[-1] == Stage.ABORT and stages.count(Stage.ABORT) == 1, f"{node}: {stages}"


@pytest.mark.slow
@settings(max_examples=8, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(loss=st.floats(0.0, 0.4), latency_ms=st.floats(0.0, 30.0), jitter_ms=st.floats(0.0, 30.0),
       seed=st.integers(0, 10_000),
       partition=st.none() | st.tuples(st.sampled_from([-1, 0, 1, 2, 3]), st.floats(0.5, 12.0),
                                        st.floats(0.1, 3.0)))
def test_delivery_and_lifecycle_hold_under_random_networks(tmp_path_factory, loss, latency_ms, jitter_ms,
                                                          seed, partition):
    overrides = [*PROBE, f"seed={seed}", f"network.loss_prob={loss}", f"network.latency_ms={latency_ms}",
                 f"network.jitter_ms={jitter_ms}"]
    if partition is not None:
        target, onset, duration = partition
        overrides += ["fault=partition", f"fault.targets=[{target}]", f"fault.onset_s={onset}",
                      f"fault.duration_s={duration}"]
    d = tmp_path_factory.mktemp("prop")
    manifest = run_config(d, overrides)
    assert manifest["status"] != "failed", manifest["reason"]      # the probe raises on any breach
    check_stages(list(table(d, "ground", "stages")["stage"]), "ground")
    for i in range(4):
        node = f"drone_{i}"
        stages = table(d, node, "stages")
        check_stages(list(stages["stage"]), node)
        last = table(d, node, "state").iloc[-1]
        if stages["stage"].iloc[-1] == Stage.ABORT:
            assert stages["reason"].iloc[-1], f"{node} aborted without a reason"
        else:
            assert last["landed"] and not last["armed"], f"{node} ended armed or airborne"
        if manifest["status"] == "ok" and Stage.EXECUTION in set(stages["stage"]):
            ev = table(d, node, "events")
            got = [json.loads(x)["received"] for x in ev[ev["name"] == "tasks"]["data"]]
            assert got == [N_TASKS], f"{node} entered EXECUTION with {got} of {N_TASKS} tasks"
