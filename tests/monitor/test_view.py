"""The dashboard's lines, from real feeds: a formation flown on the simulator with the monitor's feed
attached, read as the render thread reads it.

What the lines must show: the link latency the analyzer computes (0 ms on an ideal network), one
line per repeated marker with its count, rounded numbers, no ``-0.0``, and no event later than the
header's clock.
"""

from __future__ import annotations

import re

import pandas as pd
import pytest

from swarmbox.analysis.load import node_id
from swarmbox.analysis.network import message_flow
from swarmbox.analysis.unify import T
from swarmbox.monitor.feed import GroundFeed, TappedRecorder
from swarmbox.monitor.view import DashboardView
from swarmbox.record.writer import Recorder
from swarmbox.run import build, checks
from tests.conftest import compose_config

FORMATION = ("algo=formation", "mission=formation", "mission.max_sim_time_s=40")


class Frames:
    """The monitor thread's job, done every few ticks on the tick thread (deterministic): queued
    events into the view, the feed's latest snapshot, the lines."""

    def __init__(self, feed: GroundFeed, view: DashboardView, every_ticks: int) -> None:
        self.feed, self.view, self.every = feed, view, every_ticks
        self.trailing: list[tuple[float, float]] = []   # (header clock, an event shown later than it)
        self.ticks = 0

    def __call__(self, _swarm) -> None:
        self.ticks += 1
        if self.ticks % self.every == 0:
            self.frame()

    def frame(self, final: bool = False) -> list[str]:
        while self.feed.events:
            self.view.add_event(*self.feed.events.popleft())
        if self.feed.latest is None:
            return []
        self.view.update(self.feed.latest, final)
        if not final:
            clock = self.view.snap.t_s
            self.trailing += [(clock, e.t_s) for e in self.view.events.values() if e.t_s > clock + 1e-9]
        return ["".join(text for text, _ in line) for line in self.view.lines()]


def fly(tmp_path, *overrides: str, rate_hz: float = 20.0) -> tuple[Frames, list[str], pd.DataFrame]:
    """One run with a feed on its ground; returns the frames, the last screen and the message flow."""
    cfg, _ = compose_config([*FORMATION, *overrides])
    mission = checks.check(cfg)
    feed = GroundFeed(rate_hz)
    recorder = Recorder(tmp_path)
    swarm = build.build_swarm(cfg, mission, TappedRecorder(recorder, feed))
    swarm.ground.observer = feed
    frames = Frames(feed, DashboardView("test", max_events=40, max_rows=10), every_ticks=7)
    swarm.run(mission.max_sim_time_s, progress=frames)
    swarm.backend.close()
    recorder.close()
    screen = frames.frame(final=True)
    parts = []
    for path in (tmp_path / "logs").glob("*/messages.parquet"):   # perfect clocks: unified = as logged
        part = pd.read_parquet(path)
        parts.append(part.assign(node=node_id(path.parent.name), **{T: part["t_s"]}))
    return frames, screen, message_flow(pd.concat(parts, ignore_index=True), 1.0 / cfg.run.tick_hz)


def latency_column(screen: list[str]) -> dict[int, str]:
    """drone -> its ``lat ms`` cell, from the table's rows."""
    header = next(line for line in screen if "lat ms" in line)
    end = header.index("lat ms") + len("lat ms")
    return {int(m.group(1)): line[end - 8:end].strip() for line in screen
            if (m := re.match(r"\s+(\d+)  alive", line))}


def report_latency_ms(flow: pd.DataFrame) -> set[float]:
    reports = flow[(flow["type"] == "report") & (flow["dst"] == -1) & flow["delivered"]]
    return set(reports["latency_ms"].round(6))


@pytest.mark.parametrize("overrides, ms", [((), 0.0), (("network.latency_ms=10",), 10.0)])
def test_link_latency_is_the_analyzers(tmp_path, overrides, ms):
    """The ground reads its inbox once a tick (25 ms here): the dashboard must not add that tick."""
    _, screen, flow = fly(tmp_path, *overrides)
    assert report_latency_ms(flow) == {ms}                  # what the analyzer says
    assert latency_column(screen) == {i: f"{ms:.1f}" for i in range(4)}


def test_repeated_markers_share_a_line_with_their_count_and_rounded_values(tmp_path):
    frames, screen, _ = fly(tmp_path)
    events = screen[screen.index(next(x for x in screen if x.startswith("── events"))) + 1:]
    marks = [x for x in events if "marker/formation_error" in x]
    assert len(marks) == 4                                  # one line per drone (a marker a second each)
    for line in marks:
        count = int(re.search(r"\(x(\d+) since", line).group(1))
        assert count >= 5                                   # one a second of the formation flown
        value = re.search(r"error_m=(\S+)", line).group(1)
        assert len(value.replace(".", "").lstrip("0")) <= 3, line   # 3 significant digits, not 16
    assert [x for x in events if "stage" in x]              # stage changes are each their own line
    assert not any("-0.0" in x for x in screen)
    assert frames.trailing == []                            # no event shown later than the header's clock


def test_the_header_clock_leads_events_even_with_a_stale_snapshot(tmp_path):
    """A snapshot every 5 s of wall time: the first stays the latest while the whole flight logs its
    events; they wait for the ground clock instead of running ahead of it."""
    frames, screen, _ = fly(tmp_path, rate_hz=0.2)
    assert frames.trailing == []
    assert any("marker/formation_error" in x for x in screen)   # the final frame shows them all
