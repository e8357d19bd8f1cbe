"""The safety monitor's interventions, counted per drone for the run's record.

Refused or clamped setpoints are events in each drone's log; a run that finished ``ok`` while the
monitor refused its algorithm's setpoints should say so in ``run.json`` too, naming the drones.
The tally taps the backend's ``drain_events`` (called once per tick), so the core is unchanged.
"""

from __future__ import annotations

from typing import Any


class SafetyTally:
    def __init__(self, backend: Any) -> None:
        self.counts: dict[str, dict[int, int]] = {}
        self.first: dict[str, str] = {}
        drain = backend.drain_events

        def counted() -> Any:
            events = drain()
            for ev in events:
                if ev.kind == "safety":
                    per = self.counts.setdefault(ev.name, {})
                    per[ev.drone_id] = per.get(ev.drone_id, 0) + 1
                    self.first.setdefault(ev.name, str(ev.data.get("reason", "")))
            return events

        backend.drain_events = counted

    def record(self) -> dict[str, dict[str, int]]:
        return {name: {str(d): n for d, n in sorted(per.items())}
                for name, per in sorted(self.counts.items())}

    def summary(self) -> str:
        """E.g. ``safety: drones [0, 1] setpoint_refused 80 times (first: non-finite setpoint)``."""
        parts = []
        for name, per in sorted(self.counts.items()):
            ids = sorted(per)
            who = f"drone {ids[0]}" if len(ids) == 1 else f"drones {ids}"
            parts.append(f"safety: {who} {name} {sum(per.values())} times (first: {self.first[name]})")
        return "; ".join(parts)
