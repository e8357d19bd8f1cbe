"""Direct tests of behaviours that used to be guarded only by chance: successor choice on
handover, the min_alive abort, the ICEBREAK head-count, proximity alerts, atomic log files."""

import json

import pyarrow.parquet as pq

from swarmbox.api import Stage
from swarmbox.record.writer import Recorder
from tests.conftest import table

HOVER = ["algo=hover", "mission=hover", "algo.params.hover_s=2"]


def handovers(run_dir, drone):
    ev = table(run_dir, f"drone_{drone}", "events")
    return [(json.loads(d)["lost"], json.loads(d)["new"]) for d in ev[ev["name"] == "handover"]["data"]]


def test_handover_walks_the_successor_list_in_order_skipping_the_silent(run):
    """Drone 2 serves under 0, which advertises successors (3, 1). 0 and 3 go silent together: 2
    tries 3 first, finds it silent too, then settles on 1, and the mission completes."""
    def remove(swarm):
        swarm.schedule(8.0, lambda s: (s.remove_agent(0), s.remove_agent(3)))

    manifest, d = run("algo=hover", "mission=hover",
                      "algo.drone._target_=tests.core.algos.TwoSuccessorsDrone", "topology=explicit",
                      "topology.superiors={0:-1,1:-1,2:0,3:-1}", prepare=remove)
    assert manifest["status"] == "ok", manifest["reason"]
    assert handovers(d, 2) == [(0, 3), (3, 1)]
    assert list(table(d, "drone_2", "stages")["stage"])[-1] == Stage.TERMINATION


def test_min_alive_aborts_the_mission_with_the_reason(run):
    manifest, d = run(*HOVER, "algo.params.hover_s=30", "run.min_alive=4",
                      prepare=lambda s: s.schedule(6.0, lambda sw: sw.remove_agent(2)))
    assert manifest["status"] == "aborted"
    assert manifest["reason"] == "only 3 of 4 drones alive (min_alive 4)"
    assert list(table(d, "ground", "stages")["stage"])[-1] == Stage.ABORT


def test_min_alive_is_not_triggered_while_enough_drones_remain(run):
    manifest, _ = run(*HOVER, "run.min_alive=3",
                      prepare=lambda s: s.schedule(6.0, lambda sw: sw.remove_agent(2)))
    assert manifest["status"] == "ok" and "lost drones [2]" in manifest["reason"]


def test_icebreak_waits_for_the_whole_swarm(run):
    """One drone never joins: the ground must not start with 3 of 4, and says so when it times out."""
    manifest, d = run(*HOVER, "run.timeouts_s.ICEBREAK=2", prepare=lambda s: s.remove_agent(1))
    assert manifest["status"] == "aborted"
    assert "ICEBREAK timed out after 2 s" in manifest["reason"]
    assert "3 of 4 drones joined" in manifest["reason"]
    assert list(table(d, "ground", "stages")["stage"]) == [Stage.ICEBREAK, Stage.ABORT]
    for i in (0, 2, 3):
        assert Stage.PREPARATION not in set(table(d, f"drone_{i}", "stages")["stage"])


def test_proximity_alerts_name_close_drones_only(run):
    """Drones 0 and 1 start 1.5 m apart (inside run.proximity_m = 2), 2 and 3 far away."""
    manifest, d = run("algo=hover", "mission=hover", "algo.drone._target_=tests.core.algos.ProximityDrone",
                      "mission.initial_positions={0:[0,0],1:[1.5,0],2:[10,0],3:[20,0]}")
    assert manifest["status"] == "ok", manifest["reason"]

    def near(i):
        ev = table(d, f"drone_{i}", "events")
        return [json.loads(x)["ids"] for x in ev[ev["name"] == "near"]["data"]]

    assert near(0) and all(ids == [1] for ids in near(0))
    assert near(1) and all(ids == [0] for ids in near(1))
    assert all(ids == [] for ids in near(2) + near(3))


def test_a_log_file_appears_only_once_complete(tmp_path):
    """Mid-run rows go to the run's spill file; per-node files are written as <table>.parquet.partial
    by close() and only then renamed, so a file under its final name is always whole."""
    rec = Recorder(tmp_path, flush_rows=1)
    log = rec.node(0)
    add = log.appender("stages")
    final = tmp_path / "logs" / "drone_0" / "stages.parquet"
    partial = final.with_name("stages.parquet.partial")
    add((0.0, 0, 1, "ICEBREAK", ""))
    rec.maybe_flush()
    assert not final.exists() and not partial.exists()
    add((1.0, 40, 2, "PREPARATION", ""))
    rec.close()
    assert final.is_file() and not partial.exists() and not (tmp_path / ".spill").exists()
    assert pq.read_table(final).column("name").to_pylist() == ["ICEBREAK", "PREPARATION"]
