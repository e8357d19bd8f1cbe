"""The fleet core (``run.core=fleet``) writes the object core's logs under every command topology.

Drones commanding drones (``chain``, ``tree``, ``leader_follower``, an explicit or a mission's own
superiors map), peer Heartbeats (``topology.peers=all``) and look-ahead proximity alerts
(``run.proximity_window_s`` > 0): each case flies one config and seed through both cores and
compares every Parquet table exactly (``assert_same_run``). The lossy cases assert that drones
really were lost and handed over, the proximity cases that predicted episodes really opened, so
none can pass on a run where the path under test never ran.
"""

from __future__ import annotations

import json
from pathlib import Path

import pandas as pd
import pytest

from swarmbox.bench.hover import grid
from tests.core.test_fleet_identity import HOVER, assert_same_run

#: every topology preset in which a drone's superior is a drone (swarmbox/conf/topology)
PRESETS = {
    "chain": ["topology=chain"],
    "tree": ["topology=tree"],
    "leader_follower": ["topology=leader_follower"],
    # four drones (the formation mission's): one under the ground, the others two levels deep
    "explicit": ["topology=explicit", "topology.superiors={0: -1, 1: 0, 2: 0, 3: 1}"],
}
#: CPU-heavy identity checks, left out of the default run; CI runs them on their own (-m seeds)
_HEAVY = (pytest.mark.slow, pytest.mark.seeds)
HOMES = {preset: grid(4 if preset == "explicit" else 6) for preset in PRESETS}


def _events(run_dir: Path) -> pd.DataFrame:
    """Every node's events of a run, with the node's name."""
    files = sorted(run_dir.glob("logs/*/events.parquet"))
    return pd.concat([pd.read_parquet(p).assign(node=p.parent.name) for p in files], ignore_index=True)


@pytest.mark.parametrize("seed", [0, 1, 2])
@pytest.mark.parametrize("preset", list(PRESETS))
def test_hover_under_every_drone_topology_logs_equal(tmp_path, preset, seed):
    """Reports and Heartbeats between drones: superiors age their inferiors, relay their
    descendants in their own Reports and announce successors in their Heartbeats."""
    manifest = assert_same_run(tmp_path, [*HOVER, *PRESETS[preset], "network=wifi", f"seed={seed}"],
                               HOMES[preset])
    assert manifest["status"] == "ok", manifest["reason"]
    joined = _events(tmp_path / "fleet").query("name == 'inferior_joined'")
    assert joined["node"].str.startswith("drone_").any()   # a drone commanded a drone


@pytest.mark.parametrize("seed", [0, *(pytest.param(s, marks=_HEAVY) for s in (1, 2))])
@pytest.mark.parametrize("preset", list(PRESETS))
def test_formation_under_every_drone_topology_logs_equal(tmp_path, preset, seed):
    """Formation: the ground's task stream beside drone-to-drone Reports and Heartbeats."""
    manifest = assert_same_run(tmp_path, ["algo=formation", *PRESETS[preset], f"seed={seed}"])
    assert manifest["status"] == "ok", manifest["reason"]


@pytest.mark.parametrize("seed", [0, 1, 2])
@pytest.mark.parametrize("preset", ["tree", "leader_follower"])
def test_lossy_network_losses_and_handovers_logs_equal(tmp_path, preset, seed):
    """Heavy loss and short liveness limits: superior drones lose inferiors, inferiors whose
    superior falls silent hand over to its successors or abort (the failsafe)."""
    assert_same_run(tmp_path, [*HOVER, *PRESETS[preset], "network.loss_prob=0.5", "run.lost_inferior_ticks=2",
                               "run.lost_superior_ticks=4", f"seed={seed}"], grid(7))
    events = _events(tmp_path / "fleet")
    drones = events[events["node"].str.startswith("drone_")]
    assert {"inferior_lost", "handover"} <= set(drones["name"])


@pytest.mark.parametrize("seed", [0, 1, 2])
@pytest.mark.parametrize("topology", [[], ["topology=chain"]])
def test_peer_heartbeats_logs_equal(tmp_path, topology, seed):
    """``topology.peers=all``: every drone publishes a Heartbeat to every other drone each tick."""
    assert_same_run(tmp_path, [*HOVER, *topology, "topology.peers=all", "network=wifi", f"seed={seed}"],
                    grid(5))
    messages = pd.read_parquet(tmp_path / "fleet" / "logs" / "drone_3" / "messages.parquet")
    heard = messages.query("kind == 'recv' and type == 'heartbeat'")["src"]
    assert set(heard) >= {0, 1, 2, 4}   # the peers', beside the superior's


@pytest.mark.parametrize("seed", [0, 1, 2])
@pytest.mark.parametrize("topology", [[], ["topology=chain", "network=wifi"]])
def test_proximity_look_ahead_logs_equal(tmp_path, topology, seed):
    """Crossing drones with a 2 s look-ahead: pairs are alerted on their predicted closest approach,
    long before they are within ``proximity_m`` (the tracker's velocities need every tick's reading)."""
    manifest = assert_same_run(tmp_path, ["algo=crossing", "run.proximity_window_s=2.0", *topology,
                                          f"seed={seed}"])
    assert manifest["status"] == "ok", manifest["reason"]
    ground = _events(tmp_path / "fleet").query("node == 'ground' and name == 'prox_start'")
    assert ground["data"].str.contains('"predicted": true').any()


@pytest.mark.parametrize(("preset", "algos"), [
    ("tree", ("algo=hover", "algo=hover_batch")),
    ("chain", ("algo=formation", "algo=formation_batch")),
])
def test_batch_ports_under_drone_topologies_log_their_per_drone_versions(tmp_path, preset, algos):
    """A batch algorithm on the fleet core writes its per-drone version's object-core logs here too."""
    overrides = [*(HOVER[1:] if algos[0] == "algo=hover" else []), *PRESETS[preset], "network=wifi"]
    homes = grid(6) if algos[0] == "algo=hover" else None
    manifest = assert_same_run(tmp_path, overrides, homes, algos=algos)
    assert manifest["status"] == "ok", manifest["reason"]


@pytest.mark.slow
@pytest.mark.seeds   # CPU-heavy identity checks: CI runs them on their own
@pytest.mark.parametrize("algo", ["adaptive", "chevron"])
def test_committed_missions_with_drone_superiors_logs_equal(tmp_path, algo):
    """The shipped leader-follower missions (RQ1 adaptive, RQ5 chevron): their own superiors maps."""
    manifest = assert_same_run(tmp_path, [f"algo={algo}", f"mission={algo}"])
    assert manifest["status"] == "ok", manifest["reason"]


@pytest.mark.slow
@pytest.mark.seeds   # CPU-heavy identity checks: CI runs them on their own
def test_peer_heartbeat_mission_logs_equal(tmp_path):
    """The network mission with ``topology.peers=all``: the algorithm reads its peers' Heartbeats."""
    manifest = assert_same_run(tmp_path, ["algo=network", "mission=network", "topology.peers=all"])
    assert manifest["status"] == "ok", manifest["reason"]



@pytest.mark.parametrize("seed", [0, 1])
def test_a_ground_that_reads_every_report_logs_equal(tmp_path, seed):
    """A ground algorithm with its own ``on_report`` (each Report handed to it, tasks sent back) runs
    under the object core's ground on the fleet core: the same logs, its marks and tasks included."""
    assert_same_run(tmp_path, [*HOVER, "algo.params.hover_s=4", "network=wifi", "network.loss_prob=0.1",
                               "+algo.ground._target_=tests.core.algos.ReportWatchingGround", f"seed={seed}"],
                    grid(5))
    events = _events(tmp_path / "fleet")
    seen = events[(events["node"] == "ground") & (events["name"] == "report_seen")]
    said = [json.loads(d) for d in seen["data"]]
    assert {d["drone"] for d in said} == set(range(5)), "on_report did not see every drone"
    assert max(d["n"] for d in said) >= 100 and any(d["complete"] for d in said)
