"""The ``state`` rows of a whole simulated fleet, one columnar block per tick.

An agent used to log its own state row: a 20-field tuple per drone and tick, built from its
telemetry tuples and converted back to columns by the log writer. When the backend can export its
fleet arrays (``state_into``), :class:`FleetStateLog` writes the same rows for every agent that
ticked as one block of numpy columns instead: the numbers come straight from the backend's arrays
into the recorder's column buffers,
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
from swarmbox.record.blocks import StateBlocks

_TELEMETRY, _STAGE = attrgetter("telemetry"), attrgetter("stage_code")
_ARMED, _MODE = attrgetter("armed"), attrgetter("mode")


class FleetArrays(Protocol):
    """A backend that can export its fleet state (:meth:`SimBackend.state_into`)."""

    def state_into(self, values: np.ndarray, landed: np.ndarray, index: np.ndarray | None = None) -> None: ...


class StateSink(Protocol):
    def state_block(self, nodes: np.ndarray, columns: list[Any]) -> None: ...


class FleetStateLog:
    """Called by the tick loop after every agent ticked, before the backend steps.

    With a sink that exposes its column buffers (``state_blocks``, a
    :class:`~swarmbox.record.blocks.StateBlocks`) a tick's rows are written straight into them, one
    numpy call per column; otherwise they go to ``state_block`` as one block of columns.
    """

    def __init__(self, agents: Sequence[Any], backend: FleetArrays, sink: StateSink,
                 every_ticks: int) -> None:
        self.agents, self.backend, self.sink = list(agents), backend, sink
        self.every = every_ticks
        self._blocks: StateBlocks | None = getattr(sink, "state_blocks", None)
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
        blocks = self._blocks
        if blocks is None:
            blocks = StateBlocks(n)
        a, b = blocks.reserve(n)
        cols = blocks.columns
        blocks.nodes[a:b] = self._nodes
        # attribute reads through map/attrgetter: the loops run in C
        tels = list(map(_TELEMETRY, live))
        readings(self._clocks, self._time.t_s, out=cols[0][a:b])
        cols[1][a:b] = tick
        cols[2][a:b] = list(map(_STAGE, live))
        cols[3][a:b] = list(map(_ARMED, tels))
        cols[5][a:b] = list(map(MODE_TEXT.__getitem__, map(_MODE, tels)))
        self.backend.state_into(blocks.values[:, a:b], cols[4][a:b], self._index)
        blocks.commit(b)
        if self._blocks is None:
            self.sink.state_block(blocks.nodes[a:b], [c[a:b] for c in cols])


class FleetCoreStateLog(FleetStateLog):
    """The same rows for a run on the fleet core (``swarmbox.core.fleet``): the stage, armed flag and
    mode come from the fleet's arrays and this tick's readings instead of each agent."""

    def __init__(self, swarm: Any, sink: StateSink, every_ticks: int) -> None:
        self.fleet = swarm.fleet
        super().__init__(swarm.agents, swarm.backend, sink, every_ticks)

    def refresh(self) -> None:
        super().refresh()
        live = [k for k, a in enumerate(self.agents) if not a.removed]   # a crash removes one
        self._rows = None if len(live) == len(self.agents) else np.array(live, dtype=np.int64)

    def __call__(self, tick: int) -> None:
        if tick % self.every:
            return
        f, rows = self.fleet, self._rows
        n = len(self._live)
        if not n:
            return
        blocks = self._blocks if self._blocks is not None else StateBlocks(n)
        a, b = blocks.reserve(n)
        cols = blocks.columns
        blocks.nodes[a:b] = self._nodes
        readings(self._clocks, self._time.t_s, out=cols[0][a:b])
        cols[1][a:b] = tick
        modes = f.modes if rows is None else [f.modes[k] for k in rows.tolist()]
        cols[2][a:b] = f.stage if rows is None else f.stage[rows]
        cols[3][a:b] = f.armed if rows is None else f.armed[rows]
        cols[5][a:b] = list(map(MODE_TEXT.__getitem__, modes))
        self.backend.state_into(blocks.values[:, a:b], cols[4][a:b], self._index)
        blocks.commit(b)
        if self._blocks is None:
            self.sink.state_block(blocks.nodes[a:b], [c[a:b] for c in cols])
