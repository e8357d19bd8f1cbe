"""hover, formation and flocking: the batch ports write exactly the per-drone versions' logs.

Every run here is under packet loss and jitter, with a drone crashing (node removed, radio silent)
and another's GNSS drifting, so that stage changes, hand-overs, lost inferiors and the network's
random draws are all part of what must match.
"""

from pathlib import Path

import pytest

from swarmbox.core.batch import FleetDriver
from swarmbox.testing import BatchMismatch, check_batch_matches
from swarmbox.testing.runs import compare_logs, compose, fly

FAULTS = ["network.loss_prob=0.1", "network.jitter_ms=20", "network.latency_ms=5",
          "fault=[crash,gps_drift]", "fault.crash.targets=[1]", "fault.crash.onset_s=6",
          "fault.gps_drift.targets=[2]", "fault.gps_drift.onset_s=5", "fault.gps_drift.rate_m_s=2"]
#: the formation, shortened: circle from 5 s of EXECUTION, one lap in ~25 s
SHORT_FORMATION = ["algo.params.start_s=5", "algo.params.angular_rate_rad_s=0.25",
                   "algo.params.complete_after_s=32"]


def test_hover_batch_writes_the_per_drone_logs(tmp_path):
    report = check_batch_matches(["algo=hover"], ["algo=hover_batch"], workdir=tmp_path, extra=FAULTS)
    assert [m["status"] for m in report.manifests] == ["ok", "ok"]


@pytest.mark.parametrize("topology", ["centralized", "tree"])
def test_formation_batch_writes_the_per_drone_logs(tmp_path, topology):
    # under a tree, drones relay the leader's waypoint from exec_loop and take over a lost superior:
    # their messages must leave in the per-drone order for the network's draws to match
    report = check_batch_matches(["algo=formation"], ["algo=formation_batch"], workdir=tmp_path,
                                 extra=[*SHORT_FORMATION, *FAULTS, f"topology={topology}"])
    assert [m["status"] for m in report.manifests] == ["ok", "ok"]


def test_flocking_batch_writes_the_per_drone_logs(tmp_path):
    report = check_batch_matches(["algo=flocking"], ["algo=flocking_batch"], workdir=tmp_path,
                                 extra=["algo.params.flock_s=15", *FAULTS])
    assert [m["status"] for m in report.manifests] == ["ok", "ok"]


def test_fleets_of_one_as_in_the_processes_runtime_write_the_per_drone_logs(tmp_path):
    report = check_batch_matches(["algo=formation"], ["algo=formation_batch"], workdir=tmp_path,
                                 extra=[*SHORT_FORMATION, *FAULTS, "topology=tree"], fleets_of_one=True)
    assert [m["status"] for m in report.manifests] == ["ok", "ok"]


def _swap_rows(swarm):
    """Give drone 0 row 1's results and drone 1 row 0's: the bug of a driver mixing up its rows."""
    driver: FleetDriver = swarm.fleet_driver
    swarm.agents[0].algorithm, swarm.agents[1].algorithm = driver.members[1], driver.members[0]


@pytest.mark.parametrize("algo", ["hover", "flocking"])
def test_rows_handed_to_the_wrong_drones_are_caught(tmp_path, algo):
    extra = ["run.progress=false", "algo.params.flock_s=5"] if algo == "flocking" else ["run.progress=false"]
    cfg, choices = compose([f"algo={algo}", *extra])
    fly(cfg, choices, tmp_path / "per_drone")
    cfg, choices = compose([f"algo={algo}_batch", *extra])
    fly(cfg, choices, tmp_path / "batch")
    fly(cfg, choices, tmp_path / "swapped", _swap_rows)
    assert compare_logs(tmp_path / "per_drone", tmp_path / "batch") == []
    differences = compare_logs(tmp_path / "per_drone", tmp_path / "swapped")
    assert any(d.startswith("drone_0/setpoints.parquet") for d in differences), differences


def test_a_mismatch_names_the_tables(tmp_path):
    with pytest.raises(BatchMismatch, match=r"drone_\d/setpoints.parquet"):
        check_batch_matches(["algo=hover"], ["algo=hover_batch", "algo.params.altitude_m=3.5"],
                            workdir=tmp_path)
    with pytest.raises(BatchMismatch, match="not a FleetAlgorithm"):
        check_batch_matches(["algo=hover"], ["algo=hover"], workdir=tmp_path / "same")


@pytest.mark.slow
def test_a_batch_algorithm_flies_in_the_processes_runtime_as_a_fleet_of_one(tmp_path):
    # one process per drone, real sockets, wall-clock pacing: each drone's FleetAlgorithm drives one
    # row; logs cannot be bit-equal to another run here (wall clock), the flight's shape can
    import pandas as pd

    cfg, choices = compose(["algo=hover_batch", "run.runtime=processes", "run.progress=false"])
    manifest = fly(cfg, choices, tmp_path)
    assert manifest["status"] == "ok", manifest["reason"]
    for i, (n, _) in enumerate([(0.0, 0), (5.0, 0), (10.0, 0), (15.0, 0)]):
        logs = tmp_path / "logs" / f"drone_{i}"
        ev = pd.read_parquet(logs / "events.parquet")
        assert (ev["name"] == "reached_altitude").sum() == 1, i
        assert (ev["name"] == "exec_complete").sum() >= 1, i
        sp = pd.read_parquet(logs / "setpoints.parquet")
        assert len(sp) > 100 and (sp["n"] == n).all() and (sp["e"] == 0.0).all() and (sp["d"] == -3.0).all()


FAULT_DIR = Path(__file__).parents[2] / "swarmbox" / "conf" / "fault"
FAULT_PRESETS = sorted(p.stem for p in FAULT_DIR.glob("*.yaml")
                       if p.stem not in ("none", "gps_failure"))   # gps_failure: PX4's failure injection


@pytest.mark.slow
@pytest.mark.parametrize("fault", FAULT_PRESETS)
@pytest.mark.parametrize("algo, extra", [("formation", ["topology=tree"]),
                                         ("flocking", ["algo.params.flock_s=40"])])
def test_batch_ports_write_the_per_drone_logs_under_every_fault_preset(tmp_path, fault, algo, extra):
    check_batch_matches([f"algo={algo}"], [f"algo={algo}_batch"], workdir=tmp_path,
                        extra=[f"fault={fault}", *extra])
