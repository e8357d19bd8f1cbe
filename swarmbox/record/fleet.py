"""The ``state`` rows of a whole simulated fleet, one columnar block per tick.

An agent used to log its own state row: a 20-field tuple per drone and tick, built from its
telemetry tuples and converted back to columns by the log writer. When the backend can export its
fleet arrays (``state_columns``), :class:`FleetStateLog` writes the same rows for every agent that
ticked as one block of numpy columns instead: the numbers come straight from the backend's arrays,
and only what lives on the agent (its clock reading, stage, armed flag and mode as of its tick's
telemetry) is gathered per agent. The rows' values and meaning are the same as an agent's own.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, Protocol

import numpy as np

from swarmbox.api import FlightMode

_MODE_TEXT = {m: m.value for m in FlightMode}


class FleetArrays(Protocol):
    """A backend that can export its fleet state (:meth:`SimBackend.state_columns`)."""

    def state_columns(self, index: np.ndarray) -> list[np.ndarray]: ...


class StateSink(Protocol):
    def state_block(self, nodes: np.ndarray, columns: list[Any]) -> None: ...


class FleetStateLog:
    """Called by the tick loop after every agent ticked, before the backend steps."""

    def __init__(self, agents: Sequence[Any], backend: FleetArrays, sink: StateSink, every_ticks: int) -> None:
        self.agents, self.backend, self.sink = list(agents), backend, sink
        self.every = every_ticks
        for agent in self.agents:
            agent.own_state_rows = False   # this log writes them
        self.refresh()

    def refresh(self) -> None:
        """Take note of removed agents (the tick loop calls this when it removes one)."""
        self._live = [a for a in self.agents if not a.removed]
        self._nodes = np.array([a.node_id for a in self._live], dtype=np.int16)
        self._index = np.array([a.vehicle.drone_id for a in self._live], dtype=np.int64)

    def __call__(self, tick: int) -> None:
        if tick % self.every:
            return
        live = self._live
        n = len(live)
        if not n:
            return
        tels = [a.telemetry for a in live]
        t_s = np.fromiter([a.clock.now() for a in live], dtype=np.float64, count=n)
        stage = np.fromiter([a.stage for a in live], dtype=np.int8, count=n)
        armed = np.fromiter([tel.armed for tel in tels], dtype=bool, count=n)
        mode = [_MODE_TEXT[tel.mode] for tel in tels]
        nums = self.backend.state_columns(self._index)
        landed = nums.pop()
        self.sink.state_block(self._nodes, [t_s, np.full(n, tick, dtype=np.int64), stage, armed, landed,
                                            mode, *nums])
