"""The live monitor on the fleet core (``run.core=fleet``): the object core's dashboard and stream.

The fleet core keeps its ``messages`` rows in column chunks and hands a node's rows of many ticks
over at once; the monitor must still see what it sees on the object core. Each case flies one config
and seed on both cores with the monitor attached, takes the ground's snapshot at the same ticks
(``TickFeed``: the feed's own ``take``, on a tick schedule instead of the wall clock) and compares
what the dashboard shows: the snapshots' fields and the view's lines. The logs must not move.
"""

from __future__ import annotations

import re
import time
from pathlib import Path

from swarmbox.monitor.feed import GroundFeed, Snapshot, snapshot
from swarmbox.monitor.live import Monitor
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
        from swarmbox.monitor.rerun_live import RerunStream   # the replay extra

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
               r.report.stage, r.report.pos_ned_m, r.report.vel_ned_m_s, r.report.data)
              for r in snap.drones]
    return {"t_s": snap.t_s, "tick": snap.tick, "stage": snap.stage, "stage_time_s": snap.stage_time_s,
            "reason": snap.reason, "swarm_size": snap.swarm_size, "alive": snap.alive, "prox": snap.prox,
            "forwarded": snap.forwarded, "drones": drones}


def assert_same_dashboard(tmp_path: Path, overrides: list[str], ticks=TICKS) -> tuple[TickFeed, TickFeed]:
    obj, o = fly(tmp_path / "object", "object", overrides, ticks)
    fleet, f = fly(tmp_path / "fleet", "fleet", overrides, ticks)
    assert o == f
    assert sorted(obj.shown) == sorted(fleet.shown) and len(obj.shown) > 2
    for tick in obj.shown:
        (snap_o, lines_o), (snap_f, lines_f) = obj.shown[tick], fleet.shown[tick]
        assert shown(snap_o) == shown(snap_f), tick
        assert without_disc(lines_o) == without_disc(lines_f), tick
    return obj, fleet


def without_disc(lines: list[str]) -> list[str]:
    """The lines without the drone rows' ``disc m`` cell: the fleet core's Reports do not carry the
    GNSS - estimate discrepancy yet (docs/monitor.md)."""
    return [line[:-8] if re.match(r"\s+\d+  ", line) else line for line in lines]


def test_the_dashboard_of_a_lossy_jittery_run_is_the_object_cores(tmp_path):
    obj, _ = assert_same_dashboard(tmp_path, WIFI)
    snaps = [snap for snap, _ in obj.shown.values()]
    # the case shows what it claims: measured latencies that vary, and lost Reports
    lat = {r.latency_s for s in snaps for r in s.drones if r.latency_s is not None}
    assert len(lat) > 3 and all(0.0 < x < 0.1 for x in lat)
    final = obj.shown[-1][0]
    assert any(r.received < final.tick - 10 for r in final.drones)
