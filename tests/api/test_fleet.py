"""The batch algorithm API on real runs: the fleet view, NaN rows, task order, and bad hook output."""

import json
import math

import numpy as np
import pytest

from swarmbox.api import row_norms
from swarmbox.testing import check_batch_matches
from tests.conftest import table

HOVER = ["algo=hover_batch", "mission=hover"]
LOSSY = ["network.loss_prob=0.3", "network.jitter_ms=20", "network.latency_ms=5"]


def test_row_norms_decide_like_math_hypot_at_the_limit():
    rng = np.random.default_rng(3)
    v = rng.normal(size=(20_000, 3))
    v *= (0.3 / np.sqrt((v * v).sum(axis=1)))[:, None]   # every norm within an ulp or two of 0.3
    exact = np.array([math.hypot(*row) for row in v.tolist()])
    assert (row_norms(v, 0.3) <= 0.3).tolist() == (exact <= 0.3).tolist()
    assert (row_norms(v, 0.3) < 0.3).tolist() == (exact < 0.3).tolist()
    naive = np.sqrt((v * v).sum(axis=1))
    assert (naive != exact).any()   # the case the helper exists for: numpy alone would decide otherwise


def test_the_fleet_view_is_read_only_rowed_by_id_and_shares_each_drones_rng(run):
    seen = {}

    def prepare(swarm):
        fleet = swarm.fleet_driver.fleet
        seen["ids"] = fleet.ids.tolist()
        seen["rng"] = all(fleet.rng(i) is a.ctx.rng for i, a in enumerate(swarm.agents))
        seen["ctx"] = [fleet.ctx(i).id for i in range(fleet.n)]
        seen["home"] = fleet.home_ned_m.tolist()
        seen["writeable"] = [fleet.pos_ned_m.flags.writeable, fleet.stage.flags.writeable,
                             fleet.home_ned_m.flags.writeable, fleet.ids.flags.writeable]

    manifest, d = run(*HOVER, prepare=prepare)
    assert manifest["status"] == "ok", manifest["reason"]
    assert seen["ids"] == seen["ctx"] == [0, 1, 2, 3]
    assert seen["home"] == [[0.0, 0.0, 0.0], [5.0, 0.0, 0.0], [10.0, 0.0, 0.0], [15.0, 0.0, 0.0]]
    assert seen["rng"] and seen["writeable"] == [False] * 4
    manifest, _ = run(*HOVER, "algo.drone._target_=tests.api.algos.WritesArrays")
    assert manifest["status"] == "failed"
    assert "exec_loop raised ValueError: assignment destination is read-only" in manifest["reason"]


def test_a_nan_row_sends_that_drone_no_setpoint_and_keeps_its_last(run):
    manifest, d = run(*HOVER, "algo.drone._target_=tests.api.algos.EveryOtherTick")
    assert manifest["status"] == "ok", manifest["reason"]
    sp0, sp1 = table(d, "drone_0", "setpoints"), table(d, "drone_1", "setpoints")
    gaps0, gaps1 = np.diff(sp0["tick"].to_numpy()), np.diff(sp1["tick"].to_numpy())
    assert set(gaps0.tolist()) == {2} and set(gaps1.tolist()) == {1}
    assert len(sp0) < 0.6 * len(sp1)
    assert (sp0["d"] == -3.0).all()


def test_reliable_tasks_reach_the_batch_on_task_in_order_once_each_like_per_drone(tmp_path):
    # 40 reliable tasks per drone under 30 % loss: acknowledgements leave during the inbox drain,
    # held until each drone's outbound half, so even the network's random draws match
    probe = ["mission=hover", "+algo.ground._target_=tests.core.algos.NumberedGround", *LOSSY, "seed=1"]
    report = check_batch_matches(["algo=hover", "algo.drone._target_=tests.core.algos.StatefulDrone"],
                                 ["algo=hover", "algo.drone._target_=tests.api.algos.OrderedTasksFleet"],
                                 workdir=tmp_path, extra=probe)
    assert report.manifests[1]["status"] == "ok", report.manifests[1]["reason"]
    ev = table(report.run_dirs[1], "drone_3", "events")
    marks = ev[(ev["kind"] == "marker") & (ev["name"] == "tasks")]["data"].tolist()
    assert [json.loads(m) for m in marks] == [{"received": 40}]


@pytest.mark.parametrize("cls, words", [
    ("WrongShape", ["fleet of 4 drones: exec_loop returned setpoints of shape (3, 3)",
                    "expected floats of shape (4, 3)"]),
    ("PartlyNaN", ["drone 2: exec_loop row 2 is not finite", "a row of NaN means no setpoint"]),
    ("NotBool", ["fleet of 4 drones: exec_complete returned an array of float64 and shape (4,)",
                 "expected a bool array of shape (4,)"]),
    ("ReturnsSetpoint", ["exec_loop returned tuple, expected FleetSetpoints or None"]),
    ("Raises", ["fleet of 4 drones: exec_complete raised KeyError: 'no such thing'"]),
    ("BadKind", ["exec_loop returned kinds int64 of shape (4,)",
                 "expected a SetpointKind or SetpointKind codes"]),
    ("BadYaw", ["exec_loop returned yaw of shape (5,) (float64), expected None or floats of shape (4,)"]),
])
def test_bad_batch_hook_output_fails_the_run_naming_hook_and_drones(run, cls, words):
    manifest, d = run(*HOVER, f"algo.drone._target_=tests.api.algos.{cls}")
    assert manifest["status"] == "failed"
    for w in words:
        assert w in manifest["reason"], manifest["reason"]
    assert json.loads((d / "run.json").read_text())["reason"] == manifest["reason"]


def test_the_algorithm_suite_checks_a_batch_algorithm_per_drone(tmp_path):
    from swarmbox.api import Stage
    from swarmbox.testing import check_algorithm

    report = check_algorithm(["algo=hover_batch"], workdir=tmp_path)
    calls = report.traces[0].calls
    for i in range(4):
        mine = [(hook, stage) for node, hook, stage in calls if node == f"drone_{i}"]
        assert mine.count(("prep_once", Stage.PREPARATION)) == 1
        assert mine.count(("exec_once", Stage.EXECUTION)) == 1
        assert mine.index(("exec_once", Stage.EXECUTION)) < mine.index(("exec_loop", Stage.EXECUTION))
        assert mine.count(("exec_loop", Stage.EXECUTION)) > 100


@pytest.mark.slow
def test_bad_batch_hook_output_fails_a_processes_run_naming_each_drone(tmp_path, monkeypatch):
    from swarmbox.testing.runs import compose, fly
    from tests.conftest import ROOT

    monkeypatch.setenv("PYTHONPATH", str(ROOT))   # the node processes import tests.api.algos
    cfg, choices = compose([*HOVER, "algo.drone._target_=tests.api.algos.WrongShape", "run.runtime=processes",
                            "run.progress=false"])
    manifest = fly(cfg, choices, tmp_path)
    assert manifest["status"] == "failed"
    for i in range(4):   # each process drives a fleet of one
        assert (f"drone_{i} failed: AlgorithmError: drone {i}: exec_loop returned setpoints of shape (0, 3)"
                in manifest["reason"]), manifest["reason"]
