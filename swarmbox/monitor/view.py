"""The dashboard: turns successive snapshots and event rows into the lines of the screen.

Per drone, over the last ``window_s`` seconds of ground time:

- link latency: mean, over the snapshots, of the latest Report's receive time - send time, the
  analyzer's definition (docs/analysis.md) on the nodes' own clocks: the receive time is the
  ground's ``recv`` row, the instant the network delivered it, not the tick the ground read it at
  (an ideal network shows 0 ms);
- link loss: 1 - Reports received / ground ticks elapsed (a drone sends one Report per tick);
- GNSS - estimate: the latest discrepancy the drone reported (sent with each new GNSS fix).

Drones are *alive* while their Reports arrive, *LOST* once the ground declared them lost, and
*waiting* before their first Report.

One clock: an event is shown once the snapshot's ground clock has reached its time (or after two
new snapshots, for a node whose clock runs ahead), so the header never trails the events under it. Events
that repeat (the same node, kind, name and subject, e.g. a marker every second) share one line with
their count and latest values. Numbers are rounded to what the eye can use, never ``-0.0``.
"""

from __future__ import annotations

import itertools
import json
import math
from collections import OrderedDict, deque
from dataclasses import dataclass, field

from swarmbox.core.stages import Stage
from swarmbox.monitor.feed import Snapshot
from swarmbox.monitor.screen import Line
from swarmbox.record.schema import NO_SUBJECT


@dataclass
class _History:
    latency: deque = field(default_factory=deque)    # (t_s, latency_s)
    counts: deque = field(default_factory=deque)     # (t_s, tick, received)
    disc_m: float | None = None


@dataclass
class _Shown:
    """One line of the event pane: an event and how often it repeated."""

    first_t_s: float
    t_s: float
    node: str
    text: str
    count: int = 1

    def line(self) -> str:
        again = f"   (x{self.count} since {_num(self.first_t_s, 0, 2)})" if self.count > 1 else ""
        return f"{_num(self.t_s, 8, 2)}  {self.node:<8} {self.text}{again}".replace("\n", " ")


#: Event kinds whose every row is news (never folded into an earlier line).
_EPISODES = frozenset({"stage", "proximity"})
_unique = itertools.count()


def _node(node_id: int) -> str:
    return "ground" if node_id == -1 else f"drone {node_id}"


class DashboardView:
    """Keeps the per-drone history the dashboard needs and lays out its lines."""

    def __init__(self, title: str, window_s: float = 5.0, max_events: int = 8, max_rows: int = 40) -> None:
        self.title, self.window_s = title, window_s
        self.max_rows = max_rows
        self.history: dict[int, _History] = {}
        self.max_events = max_events
        self.events: OrderedDict[tuple, _Shown] = OrderedDict()   # shown, oldest first
        self._pending: deque[list] = deque()   # [t_s, key, node, text, snapshots waited], not shown yet
        self.snap: Snapshot | None = None
        self._prev: Snapshot | None = None
        self.tick_hz = 0.0

    # -- input ----------------------------------------------------------------------------------
    def update(self, snap: Snapshot, final: bool = False) -> None:
        """Take a new snapshot; shows the events its clock has reached (``final``: all of them)."""
        fresh = self.snap is not snap
        if fresh:
            for item in self._pending:   # snapshots an event has waited through
                item[4] += 1
        self._release(math.inf if final else snap.t_s)
        if not fresh:
            return
        self._prev, self.snap = self.snap, snap
        if self._prev is not None and snap.wall_s > self._prev.wall_s:
            self.tick_hz = (snap.tick - self._prev.tick) / (snap.wall_s - self._prev.wall_s)
        horizon = snap.t_s - self.window_s
        for row in snap.drones:
            h = self.history.setdefault(row.drone_id, _History())
            rep = row.report
            if row.alive and row.latency_s is not None:
                h.latency.append((snap.t_s, row.latency_s))
            h.counts.append((snap.t_s, snap.tick, row.received))
            if rep.discrepancy_ned_m is not None:
                h.disc_m = math.hypot(*rep.discrepancy_ned_m)
            while h.latency and h.latency[0][0] < horizon:
                h.latency.popleft()
            while len(h.counts) > 1 and h.counts[0][0] < horizon:
                h.counts.popleft()

    def add_event(self, node_id: int, row: tuple) -> str:
        """Queue an event row for the pane (shown by the next :meth:`update` that reaches its time);
        returns its text."""
        t_s, _, kind, name, subject, data = row[:6]
        if kind == "stage":
            text = f"stage {name}" + (f": {data}" if data else "")
        elif kind == "proximity":
            text = _proximity(name, data)
        else:
            about = "" if subject in (NO_SUBJECT, node_id) else f" ({_node(subject)})"
            text = f"{kind}/{name}{about}{_short(data)}"
        key = (next(_unique),) if kind in _EPISODES else (node_id, kind, name, subject)
        self._pending.append([t_s, key, _node(node_id), text, 0])
        return f"{_num(t_s, 8, 2)}  {_node(node_id):<8} {text}".replace("\n", " ")

    def _release(self, until_s: float) -> None:
        """Show the pending events up to ``until_s``, and those that already waited through two new
        snapshots (a node whose clock runs ahead of the ground's must not hold the pane back)."""
        while self._pending and (self._pending[0][0] <= until_s + 1e-9 or self._pending[0][4] >= 2):
            t_s, key, node, text, _ = self._pending.popleft()
            shown = self.events.pop(key, None)
            if shown is None:
                shown = _Shown(t_s, t_s, node, text)
            else:
                shown.t_s, shown.text, shown.count = t_s, text, shown.count + 1
            self.events[key] = shown   # to the bottom: the latest
            while len(self.events) > self.max_events:
                self.events.popitem(last=False)

    # -- numbers --------------------------------------------------------------------------------
    def latency_ms(self, drone_id: int) -> float | None:
        h = self.history.get(drone_id)
        if not h or not h.latency:
            return None
        return 1e3 * sum(x for _, x in h.latency) / len(h.latency)

    def loss(self, drone_id: int) -> float | None:
        h = self.history.get(drone_id)
        if not h or len(h.counts) < 2:
            return None
        (_, tick0, got0), (_, tick1, got1) = h.counts[0], h.counts[-1]
        if tick1 <= tick0:
            return None
        return min(1.0, max(0.0, 1.0 - (got1 - got0) / (tick1 - tick0)))

    # -- rendering ------------------------------------------------------------------------------
    def lines(self) -> list[Line]:
        """The screen as fixed-width lines of ``(text, style)`` spans (see :mod:`.screen`)."""
        snap = self.snap
        if snap is None:
            return [((f"{self.title}: waiting for the ground node...", "bold"),)]
        return [*self._header(snap), *self._table(snap), *self._events()]

    def _header(self, snap: Snapshot) -> list[Line]:
        lost = sum(1 for r in snap.drones if not r.alive)
        stage_style = "bold red" if snap.stage == Stage.ABORT.name else "bold green"
        in_stage = _num(snap.stage_time_s, 0, 1)
        second: Line = (("stage ", ""), (snap.stage, stage_style),
                        (f" {in_stage} s   drones {snap.alive}/{snap.swarm_size} alive", ""))
        if lost:
            second += ((f"   {lost} lost", "bold red"),)
        clock = f"   t {_num(snap.t_s, 0, 1)} s   {_num(self.tick_hz, 0, 0)} ticks/s"
        out = [((self.title, "bold"), (clock, "")), second]
        if snap.prox:
            pairs = ", ".join(f"{a}-{b} {_num(d, 0, 1)} m" for (a, b), d in snap.prox[:6])
            out.append(((f"PROXIMITY {pairs}", "bold yellow"),))
        return out

    def _table(self, snap: Snapshot) -> list[Line]:
        out: list[Line] = [((f"{'drone':>5}  {'link':<11}{'stage':<12}{'N m':>8}{'E m':>8}{'alt m':>7}"
                             f"{'m/s':>6}{'lat ms':>8}{'loss %':>8}{'disc m':>8}", "bold"),)]
        near = {d for pair, _ in snap.prox for d in pair}
        shown = 0
        # lost drones first, then those in a proximity alert: on a big swarm they must stay visible
        for row in sorted(snap.drones, key=lambda r: (r.alive, r.drone_id not in near, r.drone_id)):
            if shown >= self.max_rows:
                break
            shown += 1
            rep = row.report
            n, e, d = rep.pos_ned_m
            lat, loss = self.latency_ms(row.drone_id), self.loss(row.drone_id)
            hist = self.history.get(row.drone_id)
            link = (("alive", "green") if row.alive
                    else ("LOST " + _num(row.silent_ticks * snap.tick_s, 0, 1) + "s", "bold red"))
            out.append(((f"{row.drone_id:>5}  ", "bold yellow" if row.drone_id in near else ""),
                        (f"{link[0]:<11}", link[1]),
                        (f"{_stage(rep.stage):<12}{_num(n, 8, 1)}{_num(e, 8, 1)}{_num(-d, 7, 1)}"
                         f"{_num(math.hypot(*rep.vel_ned_m_s), 6, 1)}{_num(lat, 8, 1)}"
                         f"{_num(None if loss is None else 100 * loss, 8, 1)}"
                         f"{_num(hist.disc_m if hist else None, 8, 2)}", "")))
        for fw in snap.forwarded:
            if shown >= self.max_rows:
                break
            shown += 1
            n, e, d = fw.pos_ned_m
            out.append(((f"{fw.drone_id:>5}  ", ""), (f"{'via sup.':<11}", "cyan"),
                        (f"{_stage(fw.stage):<12}{_num(n, 8, 1)}{_num(e, 8, 1)}{_num(-d, 7, 1)}", "")))
        joined = {r.drone_id for r in snap.drones} | {f.drone_id for f in snap.forwarded}
        hidden, waiting = len(joined) - shown, snap.swarm_size - len(joined)
        notes = [f"{hidden} more not shown" if hidden > 0 else "",
                 f"{waiting} waiting" if waiting > 0 else ""]
        if any(notes):
            out.append(((", ".join(x for x in notes if x), "dim"),))
        return out

    def _events(self) -> list[Line]:
        body = [shown.line() for shown in self.events.values()] or ["(none yet)"]
        return [(("── events " + "─" * 60, "dim"),), *(((line, ""),) for line in body)]


def _stage(code: int) -> str:
    try:
        return Stage(code).name
    except ValueError:
        return str(code)


def _num(value: float | None, width: int, decimals: int) -> str:
    """``value`` right-aligned in ``width`` with ``decimals``; ``-`` when unknown; never ``-0.0``."""
    if value is None or not math.isfinite(value):
        return f"{'-':>{width}}"
    return f"{round(value, decimals) + 0.0:{width}.{decimals}f}"   # + 0.0: a rounded -0.0 becomes 0.0


def _round(value: object) -> object:
    """An event field as the pane shows it: floats to 3 significant digits (all their integer digits,
    at most 6 decimals), inside lists and dicts too."""
    if isinstance(value, float):
        if value == 0 or not math.isfinite(value):
            return value + 0.0
        decimals = min(6, max(0, 2 - math.floor(math.log10(abs(value)))))
        text = f"{round(value, decimals) + 0.0:.{decimals}f}"
        return text.rstrip("0").rstrip(".") if "." in text else text
    if isinstance(value, list):
        return "[" + ", ".join(str(_round(v)) for v in value) + "]"
    if isinstance(value, dict):
        return "{" + ", ".join(f"{k}: {_round(v)}" for k, v in value.items()) + "}"
    return value


def _proximity(name: str, data: str) -> str:
    try:
        f = json.loads(data)
        a, b = f["pair"]
    except (ValueError, KeyError, TypeError):
        return f"proximity/{name}"
    if name == "prox_start":
        how = "predicted" if f.get("predicted") else "closer than the limit"
        return f"PROXIMITY {a}-{b} {_num(f.get('distance_m'), 0, 1)} m ({how})"
    return (f"proximity {a}-{b} over: closest {_num(f.get('min_distance_m'), 0, 1)} m, "
            f"{_num(f.get('duration_s'), 0, 1)} s")


def _short(data: str, limit: int = 70) -> str:
    try:
        fields = json.loads(data) if data else {}
    except ValueError:
        return f" {data[:limit]}"
    if not fields:
        return ""
    text = " " + " ".join(f"{k}={_round(v)}" for k, v in fields.items())
    return text if len(text) <= limit else text[: limit - 1] + "…"
