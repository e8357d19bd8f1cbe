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
from operator import attrgetter
from typing import Any, Protocol

import numpy as np

from swarmbox.core.agent import MODE_TEXT
from swarmbox.core.clock import readings

_TELEMETRY, _STAGE = attrgetter("telemetry"), attrgetter("stage")
_ARMED, _MODE = attrgetter("armed"), attrgetter("mode")


class FleetArrays(Protocol):
    """A backend that can export its fleet state (:meth:`SimBackend.state_columns`)."""

    def state_columns(self, index: np.ndarray | None = None) -> list[np.ndarray]: ...


class StateSink(Protocol):
    def state_block(self, nodes: np.ndarray, columns: list[Any]) -> None: ...


class FleetStateLog:
    """Called by the tick loop after every agent ticked, before the backend steps."""

    def __init__(self, agents: Sequence[Any], backend: FleetArrays, sink: StateSink,
                 every_ticks: int) -> None:
        self.agents, self.backend, self.sink = list(agents), backend, sink
        self.every = every_ticks
        for agent in self.agents:
            agent.own_state_rows = False   # this log writes them
        self.refresh()

    def refresh(self) -> None:
        """Take note of removed agents (the tick loop calls this when it removes one)."""
        self._live = [a for a in self.agents if not a.removed]
        self._nodes = np.array([a.node_id for a in self._live], dtype=np.int16)
        index = np.array([a.vehicle.drone_id for a in self._live], dtype=np.int64)
        # the whole fleet in vehicle order (the usual case): no fancy indexing
        self._index = None if np.array_equal(index, np.arange(len(self.agents))) else index
        self._clocks = [a.clock for a in self._live]
        self._time = self._live[0].time if self._live else None

    def __call__(self, tick: int) -> None:
        if tick % self.every:
            return
        live = self._live
        n = len(live)
        if not n:
            return
        # attribute reads through map/attrgetter: the loops run in C
        tels = list(map(_TELEMETRY, live))
        t_s = readings(self._clocks, self._time.t_s)
        stage = np.fromiter(map(int, map(_STAGE, live)), dtype=np.int8, count=n)
        armed = np.fromiter(map(_ARMED, tels), dtype=bool, count=n)
        mode = np.array(list(map(MODE_TEXT.__getitem__, map(_MODE, tels))), dtype=object)
        nums = self.backend.state_columns(self._index)
        landed = nums.pop()
        self.sink.state_block(self._nodes, [t_s, np.full(n, tick, dtype=np.int64), stage, armed, landed,
                                            mode, *nums])
