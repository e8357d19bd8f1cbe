"""The dashboard: turns successive snapshots and event rows into the lines of the screen.

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

from swarmbox.core.stages import Stage
from swarmbox.monitor.feed import Snapshot
from swarmbox.monitor.screen import Line
from swarmbox.record.schema import NO_SUBJECT


@dataclass
class _History:
    latency: deque = field(default_factory=deque)    # (t_s, latency_s)
    counts: deque = field(default_factory=deque)     # (t_s, tick, received)
    disc_m: float | None = None


def _node(node_id: int) -> str:
    return "ground" if node_id == -1 else f"drone {node_id}"


class DashboardView:
    """Keeps the per-drone history the dashboard needs and lays out its lines."""

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

    def add_event(self, node_id: int, row: tuple) -> str:
        t_s, _, kind, name, subject, data = row[:6]
        if kind == "stage":
            text = f"stage {name}" + (f": {data}" if data else "")
        elif kind == "proximity":
            text = _proximity(name, data)
        else:
            about = "" if subject in (NO_SUBJECT, node_id) else f" ({_node(subject)})"
            text = f"{kind}/{name}{about}{_short(data)}"
        line = f"{t_s:8.2f}  {_node(node_id):<8} {text}".replace("\n", " ")
        self.events.append(line)
        return line

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
        second: Line = (("stage ", ""), (snap.stage, stage_style),
                        (f" {snap.stage_time_s:.1f} s   drones {snap.alive}/{snap.swarm_size} alive", ""))
        if lost:
            second += ((f"   {lost} lost", "bold red"),)
        out = [((self.title, "bold"), (f"   t {snap.t_s:.1f} s   {self.tick_hz:.0f} ticks/s", "")), second]
        if snap.prox:
            pairs = ", ".join(f"{a}-{b} {d:.1f} m" for (a, b), d in snap.prox[:6])
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
                    else ("LOST " + format(row.silent_ticks * snap.tick_s, ".1f") + "s", "bold red"))
            out.append(((f"{row.drone_id:>5}  ", "bold yellow" if row.drone_id in near else ""),
                        (f"{link[0]:<11}", link[1]),
                        (f"{_stage(rep.stage):<12}{n:8.1f}{e:8.1f}{-d + 0.0:7.1f}"
                         f"{math.hypot(*rep.vel_ned_m_s):6.1f}{_num(lat, '{:8.1f}')}"
                         f"{_num(None if loss is None else 100 * loss, '{:8.1f}')}"
                         f"{_num(hist.disc_m if hist else None, '{:8.2f}')}", "")))
        for fw in snap.forwarded:
            if shown >= self.max_rows:
                break
            shown += 1
            n, e, d = fw.pos_ned_m
            out.append(((f"{fw.drone_id:>5}  ", ""), (f"{'via sup.':<11}", "cyan"),
                        (f"{_stage(fw.stage):<12}{n:8.1f}{e:8.1f}{-d + 0.0:7.1f}", "")))
        joined = {r.drone_id for r in snap.drones} | {f.drone_id for f in snap.forwarded}
        hidden, waiting = len(joined) - shown, snap.swarm_size - len(joined)
        notes = [f"{hidden} more not shown" if hidden > 0 else "",
                 f"{waiting} waiting" if waiting > 0 else ""]
        if any(notes):
            out.append(((", ".join(x for x in notes if x), "dim"),))
        return out

    def _events(self) -> list[Line]:
        body = list(self.events) or ["(none yet)"]
        return [(("── events " + "─" * 60, "dim"),), *(((line, ""),) for line in body)]


def _stage(code: int) -> str:
    try:
        return Stage(code).name
    except ValueError:
        return str(code)


def _num(value: float | None, fmt: str) -> str:
    if value is None or not math.isfinite(value):
        return fmt.format(float("nan")).replace("nan", "  -")
    return fmt.format(value)


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
