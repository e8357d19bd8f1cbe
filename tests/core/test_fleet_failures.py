"""A run that fails part way through a tick writes the object core's logs on the fleet core.

The object core ticks node by node and sends as it goes: when a hook raises, the ground and every
drone before the failing one have sent (and the network has routed) that tick's messages, Reports
included. The fleet core sends its drones' Reports and routes a tick's messages once, after the last
drone: on a failure it must send and route what the object core had by then
(``FleetSwarm.fail_midtick``). Every table of the failed run is compared.
"""

from __future__ import annotations

import pytest

from swarmbox.algorithms.formation import FormationDrone, FormationGround
from swarmbox.algorithms.hover import HoverFleet
from swarmbox.bench.hover import grid
from tests.conftest import table
from tests.core.test_fleet_identity import HOVER, assert_same_run

HERE = "tests.core.test_fleet_failures"
FORMATION = ["algo=formation", "network=wifi", "network.loss_prob=0.5", "seed=1"]   # drops drawn at send


class FormationDroneFailing(FormationDrone):
    """Drone 2 raises in its 60th execution tick (its inbox holds the ground's task: a whole tick)."""

    def exec_loop(self, ctx):
        if ctx.id == 2 and ctx.tick == 60:
            raise RuntimeError("drone 2 gives up")
        return super().exec_loop(ctx)


class FormationGroundFailing(FormationGround):
    """The ground raises in its 60th execution tick, after sending that tick's tasks."""

    def exec_loop(self, ctx):
        super().exec_loop(ctx)
        if ctx.tick == 60:
            raise RuntimeError("the ground gives up")


class HoverFleetFailing(HoverFleet):
    """The fleet's loop hook raises on its 50th call: no drone has reported in that tick."""

    calls = 0

    def exec_loop(self, fleet, rows):
        self.calls += 1
        if self.calls == 50:
            raise RuntimeError("the fleet gives up")
        return super().exec_loop(fleet, rows)


def _last_report_ticks(run, drones) -> dict[int, int]:
    out = {}
    for i in drones:
        rows = table(run, f"drone_{i}", "messages")
        out[i] = int(rows[(rows["kind"] == "send") & (rows["type"] == "report")]["tick"].max())
    return out


def _failing_tick_drops(run) -> int:
    """Drop rows in the failing tick (the last tick anything was sent): the network's draws then."""
    sent = table(run, "ground", "messages")
    drops = table(run, "net", "messages")
    return int((drops["tick"] == sent[sent["kind"] == "send"]["tick"].max()).sum())


def test_a_drone_failing_in_a_whole_tick_leaves_the_object_cores_logs(tmp_path):
    obj = assert_same_run(tmp_path, [*FORMATION, f"algo.drone._target_={HERE}.FormationDroneFailing"])
    assert obj["status"] == "failed" and "drone 2 gives up" in obj["reason"]
    last = _last_report_ticks(tmp_path / "object", [0, 1, 3])
    assert last[0] == last[1] == last[3] + 1   # drones before it reported in the failing tick
    assert _failing_tick_drops(tmp_path / "object") > 0


def test_the_ground_failing_after_its_tasks_leaves_the_object_cores_logs(tmp_path):
    obj = assert_same_run(tmp_path, [*FORMATION, f"algo.ground._target_={HERE}.FormationGroundFailing"])
    assert obj["status"] == "failed" and "the ground gives up" in obj["reason"]
    sent = table(tmp_path / "object", "ground", "messages")
    sent = sent[sent["kind"] == "send"]
    last = int(sent["tick"].max())
    assert (sent["tick"] == last).sum() > 1   # its tasks of the failing tick went out
    assert last > max(_last_report_ticks(tmp_path / "object", [0, 1, 2, 3]).values())
    assert _failing_tick_drops(tmp_path / "object") > 0   # its messages of that tick drawn and dropped


@pytest.mark.parametrize("n", [5, 60])
def test_a_fleet_hook_failing_leaves_the_object_cores_logs(tmp_path, n):
    obj = assert_same_run(tmp_path, [*HOVER, "seed=0", "network=wifi", "network.loss_prob=0.5",
                                     f"algo.drone._target_={HERE}.HoverFleetFailing"], grid(n))
    assert obj["status"] == "failed" and "the fleet gives up" in obj["reason"]
    assert _failing_tick_drops(tmp_path / "object") > 0   # the ground's messages of that tick
