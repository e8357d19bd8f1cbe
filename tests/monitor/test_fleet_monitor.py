"""The live monitor on the fleet core (``run.core=fleet``): the object core's dashboard and stream.

The fleet core keeps its ``messages`` rows in column chunks and hands a node's rows of many ticks
over at once; the monitor must still see what it sees on the object core. Each case flies one config
and seed on both cores with the monitor attached, takes the ground's snapshot at the same ticks
(``TickFeed``: the feed's own ``take``, on a tick schedule instead of the wall clock) and compares
what the dashboard shows: the snapshots' fields and the view's lines. The logs must not move.
"""

from __future__ import annotations

import json
import re
import time
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from pandas.testing import assert_frame_equal

from swarmbox.algorithms.hover import HoverDrone
from swarmbox.monitor.feed import GroundFeed, Snapshot, snapshot
from swarmbox.monitor.live import Monitor
from swarmbox.record.packed import DTYPES
from swarmbox.record.writer import Recorder
from swarmbox.run import build, checks
from tests.conftest import compose_config
from tests.core.test_fleet_identity import HOVER

HOVER5 = [*HOVER, "algo.params.hover_s=6"]
#: latency, jitter (several Reports of a drone can land in one tick) and loss
WIFI = ["network=wifi", "network.jitter_ms=30", "network.loss_prob=0.05"]
CRASH = ["fault=crash", "fault.targets=[1]", "fault.onset_s=3"]
#: the ticks snapshots are taken at: around the runner's progress calls (every 40 ticks at 40 Hz),
#: where the fleet core hands its rows over anyway, and in between
TICKS = (3, 39, 40, 41, 79, 80, 157, 200, 333, 420)


class TickFeed(GroundFeed):
    """The monitor's feed, with its snapshots taken at the ground's ``ticks`` (deterministic); each is
    drawn at once by the monitor's own frame (view, Rerun stream), as its render thread would."""

    def __init__(self, ticks: tuple[int, ...] | range, monitor: Monitor) -> None:
        super().__init__()
        self.at, self.monitor = set(ticks), monitor
        self.shown: dict[int, tuple[Snapshot, list[str]]] = {}
        self.seen: list[bytes] = []   # every ground messages chunk the feed was handed, in order

    def after_tick(self, ground) -> None:
        if ground.time.tick in self.at:
            self.take(ground, time.perf_counter())
            self.shown[ground.time.tick] = (self.latest, self.frame())

    def frame(self, final: bool = False) -> list[str]:
        self.monitor._frame(final)
        return ["".join(text for text, _ in line) for line in self.monitor.view.lines()[1:]]   # [0]: ticks/s

    def message_sink(self):
        sink, seen = super().message_sink(), self.seen

        def both(row: bytes) -> None:
            seen.append(bytes(row))
            sink(row)
        return both


def fly(run_dir: Path, core: str, overrides: list[str], ticks=TICKS, rerun: bool = False,
        ) -> tuple[TickFeed, dict]:
    """One run with the monitor attached as the runner attaches it; returns its feed and outcome."""
    cfg, _ = compose_config([*HOVER5, *overrides, f"run.core={core}"])
    mission = checks.check(cfg)
    monitor = Monitor("test", dashboard=False)
    monitor.feed = feed = TickFeed(ticks, monitor)
    if rerun:
        from swarmbox.monitor.rerun_live import RerunStream  # the replay extra

        monitor.stream = RerunStream(str(run_dir / "live.rrd"), "test")
    recorder = Recorder(run_dir)
    swarm = build.build_swarm(cfg, mission, monitor.tap(recorder))
    monitor.attach(swarm)
    try:
        outcome = swarm.run(mission.max_sim_time_s, progress=lambda s: recorder.maybe_flush())
        ended = (outcome.status, outcome.reason)
    except Exception as exc:   # noqa: BLE001 - a run that fails: the monitor still shows where it got to
        ended = f"{type(exc).__name__}: {exc}"
    finally:
        swarm.ground.observer = None
        swarm.backend.close()
        recorder.close()
    # as Monitor.stop: the final state, then the last frame
    feed.latest = snapshot(swarm.ground, time.perf_counter(), ticks_ago=1, arrivals=feed.arrivals)
    feed.shown[-1] = (feed.latest, feed.frame(final=True))
    if rerun:
        monitor.stream.close()
    return feed, {"outcome": ended, "tick": swarm.time.tick}


def shown(snap: Snapshot) -> dict:
    """What the dashboard and the stream read of a snapshot (the wall clock and the Report's own
    message id are not shown)."""
    drones = [(r.drone_id, r.alive, r.silent_ticks, r.received, r.latency_s, r.report.t_sent_s,
               r.report.stage, r.report.pos_ned_m, r.report.vel_ned_m_s, r.report.discrepancy_ned_m,
               r.report.data)
              for r in snap.drones]
    return {"t_s": snap.t_s, "tick": snap.tick, "stage": snap.stage, "stage_time_s": snap.stage_time_s,
            "reason": snap.reason, "swarm_size": snap.swarm_size, "alive": snap.alive, "prox": snap.prox,
            "forwarded": snap.forwarded, "drones": drones}


def assert_same_dashboard(tmp_path: Path, overrides: list[str], ticks=TICKS,
                          ) -> tuple[TickFeed, TickFeed, dict]:
    """Both cores fly ``overrides``; returns their feeds and the (common) outcome."""
    obj, o = fly(tmp_path / "object", "object", overrides, ticks)
    fleet, f = fly(tmp_path / "fleet", "fleet", overrides, ticks)
    assert o == f
    assert sorted(obj.shown) == sorted(fleet.shown) and len(obj.shown) > 2
    for tick in obj.shown:
        (snap_o, lines_o), (snap_f, lines_f) = obj.shown[tick], fleet.shown[tick]
        assert shown(snap_o) == shown(snap_f), tick
        assert lines_o == lines_f, tick
    return obj, fleet, o


def test_the_dashboard_of_a_lossy_jittery_run_is_the_object_cores(tmp_path):
    obj, _, _ = assert_same_dashboard(tmp_path, WIFI)
    snaps = [snap for snap, _ in obj.shown.values()]
    # the case shows what it claims: measured latencies that vary, and lost Reports
    lat = {r.latency_s for s in snaps for r in s.drones if r.latency_s is not None}
    assert len(lat) > 3 and all(0.0 < x < 0.1 for x in lat)
    disc = [r.report.discrepancy_ned_m for s in snaps for r in s.drones]   # new GNSS fixes: some
    assert any(d is None for d in disc) and any(d is not None for d in disc)
    final = obj.shown[-1][0]
    assert any(r.received < final.tick - 10 for r in final.drones)


def test_the_ground_rows_reach_the_monitor_in_order_and_once_across_hand_overs(tmp_path):
    """Snapshots just before, at and after the runner's progress calls (where the fleet core hands
    its rows over anyway): the feed is handed the ground's rows of both cores, byte for byte."""
    obj, fleet, _ = assert_same_dashboard(tmp_path, WIFI)
    assert len(fleet.seen) < len(obj.seen)   # the fleet core's came in chunks
    assert b"".join(fleet.seen) == b"".join(obj.seen)
    logged = pd.read_parquet(tmp_path / "fleet" / "logs" / "ground" / "messages.parquet")
    rows = np.frombuffer(b"".join(fleet.seen), dtype=DTYPES["messages"])
    assert len(rows) == len(logged) and (rows["t_s"] == logged["t_s"].to_numpy()).all()


def test_a_monitor_coarser_than_the_tick_reads_each_drones_latest_report(tmp_path):
    """One snapshot every 17 ticks (run.monitor_hz far below the tick rate): each hand-over holds
    several Reports of a drone; the one the ground holds is the last."""
    obj, fleet, _ = assert_same_dashboard(tmp_path, WIFI, ticks=range(0, 2000, 17))
    assert b"".join(fleet.seen) == b"".join(obj.seen)


def test_a_drone_that_crashes_leaves_the_dashboard_as_on_the_object_core(tmp_path):
    obj, _, _ = assert_same_dashboard(tmp_path, [*WIFI, *CRASH])
    final, lines = obj.shown[-1]
    assert [r.drone_id for r in final.drones if not r.alive] == [1]   # the case crashed drone 1
    assert any(re.match(r"\s+1  LOST", line) for line in lines)


class FailsAtThreeSeconds(HoverDrone):
    """Drone 2's hook raises 3 s into the execution: the run fails."""

    def exec_loop(self, ctx):
        if ctx.id == 2 and ctx.stage_time_s > 3.0:
            raise ValueError("drone 2 fails on purpose")
        return super().exec_loop(ctx)


def test_a_run_that_fails_shows_where_it_got_to_as_on_the_object_core(tmp_path):
    failing = [f"algo.drone._target_={__name__}.FailsAtThreeSeconds"]
    # the run fails in a tick without a snapshot: the last frame reads what the ground had then
    obj, fleet, ended = assert_same_dashboard(tmp_path, [*WIFI, *failing], ticks=range(0, 2000, 17))
    assert "drone 2 fails on purpose" in ended["outcome"] and ended["tick"] % 17 != 0
    assert b"".join(fleet.seen) == b"".join(obj.seen)


def _recording(path: Path) -> list[tuple]:
    """Every logged value of a Rerun recording: (entity, run time, component, value), sorted."""
    rrc = pytest.importorskip("rerun.chunk", reason="needs the replay extra (Rerun)")
    out = []
    for chunk in rrc.RrdReader(path).store().stream():
        batch = chunk.to_record_batch()
        names = [n for n in batch.schema.names if n not in ("rerun.controls.RowId", "log_time")]
        for row in batch.select(names).to_pylist():
            when = row.pop("run_time", None)
            out += [(chunk.entity_path, str(when), k, repr(v)) for k, v in sorted(row.items())
                    if k != "RecordingInfo:start_time"]
    return sorted(out)


@pytest.mark.replay
def test_the_rerun_stream_is_the_object_cores(tmp_path):
    """The same snapshots streamed to Rerun (``.rrd`` files, read back): every entity and value."""
    pytest.importorskip("rerun", reason="needs the replay extra (Rerun)")
    overrides = [*WIFI, *CRASH, "run.proximity_m=40"]
    fly(tmp_path / "object", "object", overrides, rerun=True)
    fly(tmp_path / "fleet", "fleet", overrides, rerun=True)
    obj, fleet = _recording(tmp_path / "object" / "live.rrd"), _recording(tmp_path / "fleet" / "live.rrd")
    entities = {e for e, *_ in obj}
    assert {"/world/drones/1", "/metrics/latency_ms/drone_1", "/world/proximity", "/events"} <= entities
    assert obj == fleet


def _tables(run_dir: Path) -> dict[str, pd.DataFrame]:
    files = sorted((run_dir / "logs").rglob("*.parquet"))
    return {str(p.relative_to(run_dir)): pd.read_parquet(p) for p in files}


def test_the_monitor_moves_no_row_of_the_fleet_cores_logs(run):
    """Fleet core with the monitor (snapshots a few times a tick's worth of wall time) and without,
    and the object core with it: every table equal."""
    fly_ = [*HOVER5, *WIFI, *CRASH, "run.progress=false"]
    _, watched = run(*fly_, "run.core=fleet", "run.monitor=on", "run.monitor_hz=500")
    _, plain = run(*fly_, "run.core=fleet", "run.monitor=off")
    _, reference = run(*fly_, "run.core=object", "run.monitor=on", "run.monitor_hz=500")
    manifest = json.loads((watched / "run.json").read_text())
    assert manifest["monitor"]["snapshots"] > 20 and not manifest["monitor"]["error"]
    a, b, c = _tables(watched), _tables(plain), _tables(reference)
    assert a.keys() == b.keys() == c.keys()
    for name in a:
        assert_frame_equal(a[name], b[name], check_exact=True, obj=name)
        assert_frame_equal(a[name], c[name], check_exact=True, obj=name)


@pytest.mark.replay
def test_run_rerun_streams_a_fleet_core_run(run):
    """``run.rerun`` through the runner on both cores: the same world entities and the same event
    lines (the snapshots follow the wall clock, so their times and the metrics that need two of them
    differ; every event is streamed, and the last frame is the final state)."""
    pytest.importorskip("rerun", reason="needs the replay extra (Rerun)")
    fly_ = [*HOVER5, *WIFI, *CRASH, "run.progress=false", "run.rerun=live.rrd", "run.monitor_hz=20"]
    manifest, fleet = run(*fly_, "run.core=fleet")
    _, obj = run(*fly_, "run.core=object")
    assert manifest["monitor"]["rerun_frames"] >= 1
    got, want = _recording(fleet / "live.rrd"), _recording(obj / "live.rrd")
    def world(recording: list[tuple]) -> set[str]:
        return {e for e, *_ in recording if not e.startswith("/metrics/")}

    assert "/world/drones/1" in world(want) and world(got) == world(want)
    def events(recording: list[tuple]) -> list[tuple]:
        return [(t, v) for e, t, k, v in recording if e == "/events" and k == "TextLog:text"]

    assert len(events(want)) > 5 and events(got) == events(want)
