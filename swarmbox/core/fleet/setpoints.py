"""The fleet's setpoints: every hooks drone's setpoint handed to the backend in one call, and the
``setpoints`` rows written as column chunks.

On the object core a drone's stage work hands its setpoint to its vehicle right after its hooks and
packs one row. Here the drones whose hooks run this tick (:meth:`FleetSwarm.run_hooks`) leave their
setpoints in a :class:`SetpointBatch`, in fleet order; after the last hook the batch goes to the
backend's ``setpoints`` (what each vehicle's ``setpoint`` does, in that order) and its rows become one
numpy chunk. Nothing in a drone's tick reads another drone's vehicle, and a vehicle's events wait in
the backend until after the step, so the vehicles see the same calls in the same order per vehicle
and every log is the object core's. A drone that ticks whole hands its setpoint over itself; its row
joins the same buffer, so each node's rows stay in time order.
"""

from __future__ import annotations

from collections.abc import Callable
from itertools import chain
from operator import attrgetter
from typing import Any

import numpy as np

from swarmbox.api import Setpoint, SetpointKind
from swarmbox.core.fleet.rows import append_by_node, take
from swarmbox.core.rows import NO_TEXT, SETPOINT_FIELDS, TEXTS

_NUMPY = {"d": "<f8", "q": "<i8", "T": "<i4"}
#: a packed ``setpoints`` row as a numpy record (the bytes ``pack_setpoint`` writes)
SETPOINT_ROW = np.dtype([(name, _NUMPY[code]) for name, code in SETPOINT_FIELDS])
_KIND_CODE = {kind: TEXTS.code(kind.name.lower()) for kind in SetpointKind}   # "position", ...
_OK = TEXTS.code("ok")
_KIND, _NED, _YAW = attrgetter("kind"), attrgetter("ned"), attrgetter("yaw_rad")


class SetpointRows:
    """Buffered ``setpoints`` rows of every drone, handed to the drones' logs by :meth:`hand_over`."""

    def __init__(self) -> None:
        #: node id -> its packed ``setpoints`` log (bytearray.extend)
        self.appenders: dict[int, Callable[[bytes], None]] = {}
        self._chunks: list[tuple[np.ndarray, np.ndarray]] = []   # (nodes, rows)
        self._single_nodes: list[int] = []
        self._single_rows: list[bytes] = []

    def one(self, node: int, row: bytes) -> None:
        """One packed row (a drone's own ``send_setpoint``): straight to its log while no chunk waits
        (no row can be ahead of it), else kept until the next chunk or hand-over."""
        if not self._chunks:
            self.appenders[node](row)
            return
        self._single_nodes.append(node)
        self._single_rows.append(row)

    def add(self, nodes: np.ndarray, rows: np.ndarray) -> None:
        """Ready rows (``SETPOINT_ROW`` records), one per node of ``nodes``."""
        self._settle()
        self._chunks.append((nodes, rows))

    def _settle(self) -> None:
        if self._single_rows:
            rows = np.frombuffer(b"".join(self._single_rows), dtype=SETPOINT_ROW)
            self._chunks.append((np.array(self._single_nodes, dtype=np.int16), rows))
            self._single_nodes, self._single_rows = [], []

    def hand_over(self) -> None:
        """Append every buffered row to its node's log, in order, and empty the buffer."""
        self._settle()
        if not self._chunks:
            return
        chunks, self._chunks = self._chunks, []
        append_by_node(chunks, self.appenders)


class SetpointBatch:
    """This tick's setpoints of the drones whose hooks ran, in fleet order, until :meth:`flush`.

    Each drone's row is kept between ticks (``_template``): a drone that returns the same Setpoint
    object as last tick (a hover, a held waypoint) costs an identity test, not a new row."""

    #: below this many hooks drones in a tick, each hands its setpoint over through its own
    #: ``send_setpoint`` (the object core's path): the batch's fixed cost, a few dozen numpy calls,
    #: is more than it saves
    SMALL = 48

    def __init__(self, backend: Any, rows: SetpointRows, node_ids: np.ndarray) -> None:
        self._backend, self.rows, self._ids = backend, rows, node_ids
        self.drones: list[int] = []        # fleet indices
        self.setpoints: list[Setpoint] = []
        self.inline = True                 # this tick: each drone hands its setpoint over itself
        self.times: list[float] = []       # ... at these clock readings (by fleet index)
        self._template = np.zeros(len(node_ids), dtype=SETPOINT_ROW)
        self._template["verdict"], self._template["reason"] = _OK, NO_TEXT
        self._last: list[Setpoint | None] = [None] * len(node_ids)   # the setpoint each row is of

    def begin(self, n: int, now: np.ndarray) -> None:
        """A tick with ``n`` drones whose hooks run (clock readings ``now``): below :attr:`SMALL`,
        each hands its setpoint over itself, as on the object core."""
        self.inline = n < self.SMALL or not hasattr(self._backend, "setpoints")
        if self.inline:
            self.times = now.tolist()

    def flush(self, now: np.ndarray, tick: int) -> None:
        """Hand the setpoints to the backend (the vehicles' ``setpoint``, in order) and write their rows."""
        ks, sps = self.drones, self.setpoints
        if not ks:
            return
        self.drones, self.setpoints = [], []
        odd = self._backend.setpoints(ks, sps)
        last = self._last
        new = [j for j, (k, sp) in enumerate(zip(ks, sps, strict=True)) if sp is not last[k]]
        if new:
            self._learn([ks[j] for j in new], [sps[j] for j in new])
        rows = take(self._template, ks)
        rows["t_s"], rows["tick"] = now[ks], tick
        for j, verdict in odd:
            rows["verdict"][j], rows["reason"][j] = TEXTS.code(verdict.action), TEXTS.code(verdict.reason)
        self.rows.add(self._ids[ks], rows)

    def _learn(self, ks: list[int], sps: list[Setpoint]) -> None:
        """The rows of drones ``ks`` for their new setpoints ``sps``."""
        m, t = len(ks), self._template
        ned = np.fromiter(chain.from_iterable(map(_NED, sps)), float, 3 * m).reshape(m, 3)
        t["kind"][ks] = list(map(_KIND_CODE.__getitem__, map(_KIND, sps)))
        t["n"][ks], t["e"][ks], t["d"][ks] = ned[:, 0], ned[:, 1], ned[:, 2]
        t["yaw_rad"][ks] = [np.nan if y is None else y for y in map(_YAW, sps)]
        for k, sp in zip(ks, sps, strict=True):
            self._last[k] = sp
