"""A batch algorithm (:class:`~swarmbox.api.FleetAlgorithm`) on the fleet core writes the logs of its
per-drone version on the object core, table for table.

Each case flies the per-drone algorithm (``algo=hover`` ...) on ``run.core=object`` and its batch port
(``algo=hover_batch`` ...) on ``run.core=fleet`` with the same seed and compares every Parquet table
exactly, so a permuted setpoint row, a hook called in the wrong order or a message sent in another
drone's turn (and so drawn another loss or jitter) fails it.
"""

from __future__ import annotations

import pytest

from swarmbox.bench.hover import grid
from tests.core.test_fleet_identity import assert_same_run

HOVER = ["mission=hover", "algo.params.hover_s=2"]


@pytest.mark.parametrize("seed", [0, 1, 2])
@pytest.mark.parametrize("n", [1, 5, 36])
def test_hover_batch_on_the_fleet_core_logs_equal(tmp_path, n, seed):
    manifest = assert_same_run(tmp_path, [*HOVER, f"seed={seed}"], grid(n),
                               algos=("algo=hover", "algo=hover_batch"))
    assert manifest["status"] == "ok", manifest["reason"]


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_formation_batch_on_the_fleet_core_logs_equal(tmp_path, seed):
    """The ground streams a task to every drone every tick: on_task per drone, then the fleet's hooks."""
    manifest = assert_same_run(tmp_path, [f"seed={seed}"], algos=("algo=formation", "algo=formation_batch"))
    assert manifest["status"] == "ok", manifest["reason"]


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_flocking_batch_on_the_fleet_core_logs_equal(tmp_path, seed):
    """Flocking reads every neighbour's position: the snapshot must be this tick's, for every drone."""
    manifest = assert_same_run(tmp_path, [f"seed={seed}"], algos=("algo=flocking", "algo=flocking_batch"))
    assert manifest["status"] == "ok", manifest["reason"]


@pytest.mark.parametrize("seed", [0, 1, 2])
@pytest.mark.parametrize("network", [
    ["network=wifi", "network.loss_prob=0.1"],                 # latency, jitter and loss
    ["network.loss_prob=0.6", "run.lost_inferior_ticks=2",     # drones lost, rejoining, aborting
     "run.lost_superior_ticks=4"],
])
def test_hover_batch_on_an_impaired_network_logs_equal(tmp_path, network, seed):
    assert_same_run(tmp_path, [*HOVER, *network, f"seed={seed}"], grid(9),
                    algos=("algo=hover", "algo=hover_batch"))


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_formation_batch_on_a_lossy_jittery_network_logs_equal(tmp_path, seed):
    """Tasks lost and reordered: each drone's acknowledgements leave in its own turn of the tick."""
    assert_same_run(tmp_path, ["network=wifi", "network.loss_prob=0.1", f"seed={seed}"],
                    algos=("algo=formation", "algo=formation_batch"))


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_acknowledgements_of_reliable_tasks_leave_in_their_drones_turn(tmp_path, seed):
    """40 reliable tasks per drone under loss and jitter, acknowledged during each drone's inbox drain
    before the fleet's hooks run: each acknowledgement must take its drone's place in the tick's send
    order (and so the network's random draws) as on the object core."""
    probe = ["algo=hover", "mission=hover", "+algo.ground._target_=tests.core.algos.NumberedGround",
             "network.loss_prob=0.3", "network.jitter_ms=20", "network.latency_ms=5", f"seed={seed}"]
    manifest = assert_same_run(tmp_path, probe, grid(4), algos=(
        "algo.drone._target_=tests.core.algos.StatefulDrone",
        "algo.drone._target_=tests.api.algos.OrderedTasksFleet"))
    assert manifest["status"] == "ok", manifest["reason"]
