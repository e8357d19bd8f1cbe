"""A ground node started again mid-EXECUTION, in one process and on the simulated network: the new
node (next incarnation, fresh algorithm, empty memory) adopts the swarm's stage from the Reports, and
the tasks it numbers from 1 again reach the leader's ``on_task`` — not taken for copies of the old
ground's tasks 1, 2, ... (the same path as a restarted ground process; see
tests/run/test_distributed_restarts.py for the real processes)."""

from __future__ import annotations

import json

from swarmbox.core.ground import GroundNode
from tests.conftest import table

RESTART_S = 6.0
TASKING = ["algo=hover", "mission=hover", "topology=leader_follower", "algo.params.hover_s=8",
           "algo.drone._target_=tests.run.restart_algos.TaskingDrone",
           "+algo.ground._target_=tests.run.restart_algos.TaskingGround", "network.loss_prob=0.2"]


class _SameLogs:
    """The killed ground's log appenders, for its successor (one node, one set of tables)."""

    def __init__(self, old: GroundNode) -> None:
        self._tables = {"stages": old._log_stage, "events": old._log_event}

    def appender(self, table: str):
        return self._tables[table]


def restart_ground(swarm) -> None:
    old = swarm.ground
    new = GroundNode(type(old.algorithm)(), time=old.time, clock=old.clock, net=old.net, inbox=old.inbox,
                     log=_SameLogs(old), timing=old.timing, mission=old.mission, params=old.params,
                     rng=old.rng, incarnation=old.incarnation + 1)
    new.rejoin()
    swarm.ground = new


def marks(run_dir, node, name):
    ev = table(run_dir, node, "events")
    ev = ev[(ev["kind"] == "marker") & (ev["name"] == name)]
    return [(t, json.loads(d)) for t, d in zip(ev["t_s"], ev["data"], strict=True)]


def test_restarted_ground_adopts_execution_and_its_renumbered_tasks_are_delivered(run):
    manifest, d = run(*TASKING, prepare=lambda s: s.schedule(RESTART_S, restart_ground))
    assert manifest["status"] == "ok", manifest["reason"]
    stages = table(d, "ground", "stages")
    after = stages[stages["t_s"] >= RESTART_S]
    assert list(after["name"]) == ["ICEBREAK", "PREPARATION", "EXECUTION", "LANDING", "TERMINATION"]
    assert set(after["reason"].iloc[1:3]) == {"adopted from the drones' reports after a restart"}
    assert after["t_s"].iloc[2] - RESTART_S < 0.1                       # adopted within a few ticks
    ev = table(d, "ground", "events")
    adopted = ev[ev["name"] == "stage_adopted"]
    assert json.loads(adopted["data"].iloc[0])["stage"] == "EXECUTION"
    sent = [f["data"] for t, f in marks(d, "ground", "task_sent") if t >= RESTART_S]
    got = [f for _, f in marks(d, "drone_0", "task_got") if f["src"] == -1]
    late = [f for f in got if f["data"] in set(sent)]
    undelivered = ev[(ev["name"] == "task_undelivered") & (ev["t_s"] >= RESTART_S)]
    assert len(sent) > 10 and len(undelivered) == 0
    assert sorted(f["data"] for f in late) == sorted(sent)             # each exactly once
    assert [f["seq"] for f in late] == list(range(1, len(sent) + 1))    # numbered from 1 again
    assert max(f["seq"] for f in got if f not in late) > 5             # the old ground's numbers, too
