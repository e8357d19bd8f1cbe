"""The dashboard: turns successive snapshots and event rows into a rich renderable.

Per drone, over the last ``window_s`` seconds of ground time:

- link latency: mean of (arrival - send time) of the latest Report at each snapshot; the arrival is
  known to the tick (the ground reads its inbox once per tick), so values are tick-quantised;
- link loss: 1 - Reports received / ground ticks elapsed (a drone sends one Report per tick);
- GNSS - estimate: the latest discrepancy the drone reported (sent with each new GNSS fix).

Drones are *alive* while their Reports arrive, *LOST* once the ground declared them lost, and
*waiting* before their first Report.
"""

from __future__ import annotations

import json
import math
from collections import deque
from dataclasses import dataclass, field

from rich.console import Group
from rich.panel import Panel
from rich.table import Table
from rich.text import Text

from swarmbox.core.stages import Stage
from swarmbox.monitor.feed import Snapshot
from swarmbox.record.schema import NO_SUBJECT


@dataclass
class _History:
    latency: deque = field(default_factory=deque)    # (t_s, latency_s)
    counts: deque = field(default_factory=deque)     # (t_s, tick, received)
    disc_m: float | None = None


def _node(node_id: int) -> str:
    return "ground" if node_id == -1 else f"drone {node_id}"


class DashboardView:
    """Keeps the per-drone history the dashboard needs and renders it."""

    def __init__(self, title: str, window_s: float = 5.0, max_events: int = 8, max_rows: int = 40) -> None:
        self.title, self.window_s = title, window_s
        self.max_rows = max_rows
        self.history: dict[int, _History] = {}
        self.events: deque[str] = deque(maxlen=max_events)
        self.snap: Snapshot | None = None
        self._prev: Snapshot | None = None
        self.tick_hz = 0.0

    # -- input ----------------------------------------------------------------------------------
    def update(self, snap: Snapshot) -> None:
        if self.snap is snap:
            return
        self._prev, self.snap = self.snap, snap
        if self._prev is not None and snap.wall_s > self._prev.wall_s:
            self.tick_hz = (snap.tick - self._prev.tick) / (snap.wall_s - self._prev.wall_s)
        horizon = snap.t_s - self.window_s
        for row in snap.drones:
            h = self.history.setdefault(row.drone_id, _History())
            rep = row.report
            if row.alive:
                arrival = snap.t_s - max(row.silent_ticks - 1, 0) * snap.tick_s
                h.latency.append((snap.t_s, arrival - rep.t_sent_s))
            h.counts.append((snap.t_s, snap.tick, row.received))
            if rep.discrepancy_ned_m is not None:
                h.disc_m = math.hypot(*rep.discrepancy_ned_m)
            while h.latency and h.latency[0][0] < horizon:
                h.latency.popleft()
            while len(h.counts) > 1 and h.counts[0][0] < horizon:
                h.counts.popleft()

    def add_event(self, node_id: int, row: tuple) -> None:
        t_s, _, kind, name, subject, data = row[:6]
        if kind == "stage":
            text = f"stage {name}" + (f": {data}" if data else "")
        elif kind == "proximity":
            text = _proximity(name, data)
        else:
            about = "" if subject in (NO_SUBJECT, node_id) else f" ({_node(subject)})"
            text = f"{kind}/{name}{about}{_short(data)}"
        self.events.append(f"{t_s:8.2f}  {_node(node_id):<8} {text}")

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
    def render(self) -> Group:
        snap = self.snap
        if snap is None:
            return Group(Text(f"{self.title}: waiting for the ground node...", style="bold"))
        return Group(self._header(snap), self._table(snap), self._events_panel())

    def _header(self, snap: Snapshot) -> Text:
        lost = sum(1 for r in snap.drones if not r.alive)
        stage_style = "bold red" if snap.stage == Stage.ABORT.name else "bold green"
        t = Text()
        t.append(f"{self.title}  ", style="bold")
        t.append(f"t {snap.t_s:.1f} s   stage ")
        t.append(snap.stage, style=stage_style)
        t.append(f" {snap.stage_time_s:.1f} s   drones {snap.alive}/{snap.swarm_size} alive")
        if lost:
            t.append(f"   {lost} lost", style="bold red")
        t.append(f"   {self.tick_hz:4.0f} ticks/s")
        if snap.prox:
            pairs = ", ".join(f"{a}-{b} {d:.1f} m" for (a, b), d in snap.prox[:6])
            t.append(f"\nPROXIMITY {pairs}", style="bold yellow")
        return t

    def _table(self, snap: Snapshot) -> Table:
        table = Table(expand=False, pad_edge=False, box=None, header_style="bold")
        for col in ("drone", "link", "stage", "N m", "E m", "alt m", "m/s", "lat ms", "loss %", "disc m"):
            table.add_column(col, justify="right" if col not in ("link", "stage") else "left", no_wrap=True)
        near = {d for pair, _ in snap.prox for d in pair}
        shown = 0
        for row in sorted(snap.drones, key=lambda r: r.drone_id):
            if shown >= self.max_rows:
                break
            shown += 1
            rep = row.report
            link = Text("alive", style="green") if row.alive else Text(
                f"LOST {row.silent_ticks * snap.tick_s:.1f}s", style="bold red")
            n, e, d = rep.pos_ned_m
            lat, loss = self.latency_ms(row.drone_id), self.loss(row.drone_id)
            disc = self.history[row.drone_id].disc_m if row.drone_id in self.history else None
            ident = Text(str(row.drone_id), style="bold yellow" if row.drone_id in near else "")
            table.add_row(ident, link, _stage(rep.stage), f"{n:7.1f}", f"{e:7.1f}", f"{-d + 0.0:5.1f}",
                          f"{math.hypot(*rep.vel_ned_m_s):4.1f}", _num(lat, "{:6.1f}"),
                          _num(None if loss is None else 100 * loss, "{:5.1f}"), _num(disc, "{:5.2f}"))
        for fw in snap.forwarded:
            if shown >= self.max_rows:
                break
            shown += 1
            n, e, d = fw.pos_ned_m
            table.add_row(str(fw.drone_id), Text("via superior", style="cyan"), _stage(fw.stage),
                          f"{n:7.1f}", f"{e:7.1f}", f"{-d + 0.0:5.1f}", "", "", "", "")
        joined = {r.drone_id for r in snap.drones} | {f.drone_id for f in snap.forwarded}
        hidden = len(joined) - shown
        waiting = snap.swarm_size - len(joined)
        if hidden > 0 or waiting > 0:
            note = ", ".join(x for x in (f"{hidden} more not shown" if hidden > 0 else "",
                                         f"{waiting} waiting" if waiting > 0 else "") if x)
            table.caption = note
        return table

    def _events_panel(self) -> Panel:
        body = "\n".join(self.events) if self.events else "(none yet)"
        return Panel(Text(body), title="events", title_align="left", expand=True)


def _stage(code: int) -> str:
    try:
        return Stage(code).name
    except ValueError:
        return str(code)


def _num(value: float | None, fmt: str) -> str:
    return "-" if value is None or not math.isfinite(value) else fmt.format(value)


def _proximity(name: str, data: str) -> str:
    try:
        f = json.loads(data)
        a, b = f["pair"]
    except (ValueError, KeyError, TypeError):
        return f"proximity/{name}"
    if name == "prox_start":
        how = "predicted" if f.get("predicted") else "closer than the limit"
        return f"PROXIMITY {a}-{b} {f.get('distance_m', float('nan')):.1f} m ({how})"
    return (f"proximity {a}-{b} over: closest {f.get('min_distance_m', float('nan')):.1f} m, "
            f"{f.get('duration_s', float('nan')):.1f} s")


def _short(data: str, limit: int = 70) -> str:
    try:
        fields = json.loads(data) if data else {}
    except ValueError:
        return f" {data[:limit]}"
    if not fields:
        return ""
    text = " " + " ".join(f"{k}={v}" for k, v in fields.items())
    return text if len(text) <= limit else text[: limit - 1] + "…"
