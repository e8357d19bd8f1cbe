"""A backend without fault inputs: it flies like ``sim`` but exposes only the Backend protocol."""

from __future__ import annotations

from typing import Any

from swarmbox.hal.sim.backend import SimBackend


class BareBackend:
    realtime = False

    def __init__(self, **kwargs: Any) -> None:
        self._sim = SimBackend(**kwargs)
        self.vehicles = self._sim.vehicles

    def step(self, dt_s: float) -> None:
        self._sim.step(dt_s)

    def drain_events(self):
        return self._sim.drain_events()

    def close(self) -> None:
        self._sim.close()
