"""What the live monitor reads, taken on the tick thread and handed over whole.

The ground node calls :meth:`GroundFeed.after_tick` at the end of every tick. Almost always that is
one clock read and a comparison; a few times a second it copies what the ground already holds —
stage, the latest Report of every inferior (immutable, shared, not copied), its Report counters,
the alerted proximity pairs — into an immutable :class:`Snapshot` and swaps it in. The render thread
only ever reads the latest snapshot and the event queue, so it never touches live node state and the
tick loop never waits for it.

Events reach the monitor through :class:`TappedRecorder`: the event rows the nodes of this process
log anyway (the ground's own, and the drones' when they run here) are also put on a queue. The
ground's ``recv`` rows of Reports are read too (a few bytes of each, on the tick thread), so the
dashboard's link latency is the analyzer's: the row's receive time - send time of the latest Report.

A packed table's appender gets one row (the object core) or a chunk of whole rows, a node's rows of
many ticks at once (the fleet core, :mod:`swarmbox.core.fleet.rows`, keeps them in column chunks and
hands them over in time order, each row once). The sinks read every row of a chunk, in order. A swarm
that buffers rows so (``hand_over_rows``) hands them over before each snapshot, so a snapshot sees
every row logged up to its tick, as on the object core; that moves no row of any node's log.
"""

from __future__ import annotations

import struct
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from swarmbox.core.messages import GROUND_ID, MESSAGE_TYPE_CODES, DescendantState, Report
from swarmbox.core.rows import MESSAGE_FIELDS, RECV
from swarmbox.record.packed import DTYPES

#: Event kinds worth a line on the dashboard (``progress`` and ``command`` are too chatty).
SHOWN_KINDS = frozenset({"marker", "safety", "collision", "fault", "topology", "failsafe", "error",
                         "proximity", "link", "estimator"})


def _fields(*names: str) -> struct.Struct:
    """Reads the named columns of a packed ``messages`` row (:mod:`swarmbox.core.rows`) in one call,
    in place; the others are skipped as padding."""
    layout = "<"
    for name, code in MESSAGE_FIELDS:
        code = "i" if code == "T" else code
        layout += code if name in names else f"{struct.calcsize('<' + code)}x"
    return struct.Struct(layout.rstrip("0123456789x") or "<")


_KIND_TYPE_SRC = _fields("kind", "type", "src")
_T_SENT = _fields("t_s", "t_sent_s")
_REPORT = MESSAGE_TYPE_CODES[Report]
_MESSAGE = DTYPES["messages"]


@dataclass(frozen=True, slots=True)
class DroneRow:
    """One direct inferior as the ground knows it."""

    drone_id: int
    alive: bool
    silent_ticks: int
    received: int           # Reports received so far
    report: Report          # the latest one
    latency_s: float | None = None   # its receive - send time (the ground's recv row), if known


@dataclass(frozen=True, slots=True)
class Snapshot:
    wall_s: float           # perf_counter at the snapshot
    t_s: float              # ground clock
    tick: int
    tick_s: float
    stage: str
    stage_time_s: float
    reason: str
    swarm_size: int
    drones: tuple[DroneRow, ...]
    forwarded: tuple[DescendantState, ...]   # drones seen only through their superior's Report
    prox: tuple[tuple[tuple[int, int], float], ...]
    alive: int


class GroundFeed:
    """The ground observer: snapshots at ``rate_hz`` (wall clock) and an event queue."""

    def __init__(self, rate_hz: float = 4.0, max_events: int = 2000) -> None:
        self.period_s = 1.0 / rate_hz
        self.latest: Snapshot | None = None
        self.events: deque[tuple[int, tuple]] = deque(maxlen=max_events)
        self.snapshot_cost_s = 0.0     # tick-thread time spent taking snapshots
        self.snapshots = 0
        self.arrivals: dict[int, bytes] = {}   # drone -> the ground's recv row of its latest Report
        #: hands the swarm's buffered rows to the logs (and so to the sinks) before a snapshot
        self.hand_over: Callable[[], None] | None = None
        self._next = 0.0

    def after_tick(self, ground: Any) -> None:
        now = time.perf_counter()
        if now < self._next:
            return
        self._next = now + self.period_s
        self.take(ground, now)

    def take(self, ground: Any, wall_s: float) -> None:
        """Take a snapshot of ``ground`` now, after every row buffered so far reached the sinks."""
        if self.hand_over is not None:
            self.hand_over()
        self.latest = snapshot(ground, wall_s, arrivals=self.arrivals)
        self.snapshots += 1
        self.snapshot_cost_s += time.perf_counter() - wall_s

    def event_sink(self, node_id: int) -> Callable[[tuple], None]:
        push = self.events.append

        def sink(row: tuple) -> None:
            if row[2] in SHOWN_KINDS and row[3] != "stats":   # link/stats: periodic counters
                push((node_id, row))
        return sink

    def message_sink(self) -> Callable[[bytes], None]:
        """Keeps the ground's latest ``recv`` row of each drone's Report (packed; read when needed)."""
        arrivals, read, size = self.arrivals, _KIND_TYPE_SRC.unpack_from, _MESSAGE.itemsize

        def sink(row: bytes) -> None:
            if len(row) != size:   # a chunk of rows
                latest_reports(row, arrivals)
                return
            kind, mtype, src = read(row)
            if kind == RECV and mtype == _REPORT:
                arrivals[src] = row
        return sink

    def stage_sink(self, node_id: int) -> Callable[[tuple], None]:
        push = self.events.append

        def sink(row: tuple) -> None:   # (t_s, tick, stage, name, reason)
            push((node_id, (row[0], row[1], "stage", row[3], node_id, row[4])))
        return sink


def latest_reports(chunk: bytes, arrivals: dict[int, bytes]) -> None:
    """The ground's packed ``messages`` rows in ``chunk``: each drone's last ``recv`` row of a Report
    goes to ``arrivals`` (an earlier one in the same chunk is already stale)."""
    rows = np.frombuffer(chunk, dtype=_MESSAGE)
    hit = np.flatnonzero((rows["kind"] == RECV) & (rows["type"] == _REPORT))
    if not len(hit):
        return
    src = rows["src"][hit]
    _, from_end = np.unique(src[::-1], return_index=True)   # the first from the end: the last
    size = _MESSAGE.itemsize
    for i in hit[len(hit) - 1 - from_end].tolist():
        arrivals[int(rows["src"][i])] = bytes(chunk[i * size:(i + 1) * size])


def snapshot(ground: Any, wall_s: float, ticks_ago: int = 0, arrivals: dict[int, bytes] | None = None,
             ) -> Snapshot:
    """The ground's state; ``ticks_ago`` = 1 when taken after the loop has already advanced time;
    ``arrivals``: the feed's recv rows, for each latest Report's latency."""
    rows, direct = [], set()
    for drone_id, inf in list(ground.inferiors.items()):
        rows.append(DroneRow(drone_id, inf.alive, inf.silent_ticks, inf.received, inf.report,
                             _latency(inf.report, arrivals.get(drone_id)) if arrivals else None))
        direct.add(drone_id)
    forwarded = tuple(d for r in rows if r.alive for d in r.report.descendants if d.drone_id not in direct)
    _, alive = ground.head_count()
    return Snapshot(wall_s, ground.clock.now() - ticks_ago * ground.tick_s, ground.time.tick - ticks_ago,
                    ground.tick_s, ground.stage.name,
                    ground.stage_tick * ground.tick_s, ground.reason, ground.mission.swarm_size,
                    tuple(rows), forwarded, tuple(ground.prox_pairs.items()), alive)


def _latency(report: Report, recv_row: bytes | None) -> float | None:
    """Receive - send time of ``report`` if ``recv_row`` is its arrival (both on the nodes' clocks)."""
    if recv_row is None:
        return None
    t_recv, t_sent = _T_SENT.unpack_from(recv_row)
    return t_recv - t_sent if t_sent == report.t_sent_s else None


class _TappedLog:
    """A node's log whose ``events`` rows (and the ground's ``stages``) also go to the monitor."""

    def __init__(self, log: Any, sinks: dict[str, Callable[[tuple], None]]) -> None:
        self._log, self._sinks = log, sinks

    def appender(self, table: str) -> Callable[[tuple], None]:
        append = self._log.appender(table)
        sink = self._sinks.get(table)
        if sink is None:
            return append

        def both(row: tuple) -> None:
            append(row)
            sink(row)
        return both

    def __getattr__(self, name: str) -> Any:
        return getattr(self._log, name)


class TappedRecorder:
    """Wraps the run's recorder so every node's event rows are also queued for the monitor."""

    def __init__(self, recorder: Any, feed: GroundFeed) -> None:
        self._recorder, self._feed = recorder, feed
        self._logs: dict[int, _TappedLog] = {}

    def node(self, node_id: int) -> _TappedLog:
        if node_id not in self._logs:
            sinks = {"events": self._feed.event_sink(node_id)}
            if node_id == GROUND_ID:
                sinks["stages"] = self._feed.stage_sink(node_id)
                sinks["messages"] = self._feed.message_sink()
            self._logs[node_id] = _TappedLog(self._recorder.node(node_id), sinks)
        return self._logs[node_id]

    def __getattr__(self, name: str) -> Any:
        return getattr(self._recorder, name)
