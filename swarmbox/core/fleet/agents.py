"""The drones of the fleet core: the object core's :class:`~swarmbox.core.agent.AgentNode`, its stage
machine and hooks unchanged, with the per-tick state in arrays of the whole fleet.

A drone's stage, stage tick, completion, liveness counters and message counter live in
:class:`FleetState` arrays; the node reads and writes them through properties, so every method of
the object core (entering a stage, a handover, the hooks' context) works as it does there. Each
tick the fleet does over the arrays what needs no hook — the superior watchdog, a landed or waiting
drone's completion, the finished test, every Report — and runs :meth:`FleetAgent.fleet_tick`
(the object core's tick minus what the arrays did) only for the drones whose hooks run, or that have
a message other than a Heartbeat confirming their stage, or whose watchdog fires.
"""

from __future__ import annotations

from collections.abc import Callable
from functools import partial
from operator import attrgetter, methodcaller
from typing import Any, NamedTuple

import numpy as np

from swarmbox.api import Telemetry
from swarmbox.core.agent import AgentNode
from swarmbox.core.fleet.setpoints import SetpointBatch, SetpointRows
from swarmbox.core.messages import make_msg_id
from swarmbox.core.stages import TERMINAL, Stage

_TELEMETRY = methodcaller("telemetry")
_ARMED, _LANDED, _LINK = attrgetter("armed"), attrgetter("landed"), attrgetter("link_ok")
_MODE = attrgetter("mode")
DATA = attrgetter("report_data")


class _Armed(NamedTuple):
    """What a loop stage's work reads of a reading (``AgentNode._stage_work``: ``tel.armed``)."""

    armed: bool


ARMED_ONLY = {True: _Armed(True), False: _Armed(False)}
_EXECUTION = Stage.EXECUTION
ICEBREAK, PREPARATION, EXECUTION, LANDING, TERMINATION, ABORT = (int(s) for s in (
    Stage.ICEBREAK, Stage.PREPARATION, Stage.EXECUTION, Stage.LANDING, Stage.TERMINATION, Stage.ABORT))


class FleetState:
    """Per-drone protocol state of the whole fleet (index ``k``: the k-th drone of the mission)."""

    def __init__(self, drone_ids: list[int]) -> None:
        n = self.n = len(drone_ids)
        self.ids = np.array(drone_ids, dtype=np.int16)
        self.stage = np.full(n, ICEBREAK, dtype=np.int64)
        self.entry_tick = np.zeros(n, dtype=np.int64)     # the tick the current stage was entered
        self.complete = np.zeros(n, dtype=bool)
        self.finished = np.zeros(n, dtype=bool)
        self.seq = np.zeros(n, dtype=np.int64)            # messages sent (the id counter)
        self.msg_id_base = np.array([make_msg_id(d, 0) for d in drone_ids], dtype=np.int64)
        self.sup_silent = np.zeros(n, dtype=np.int64)
        self.heard = np.zeros(n, dtype=bool)
        self.busy = np.zeros(n, dtype=bool)      # messages for the node's own inbox this tick
        self.sticky = np.zeros(n, dtype=bool)    # reliable tasks held or an alert in force: ticks in Python
        self.tels: list[Telemetry] = [None] * n  # type: ignore[list-item]  # this tick's readings
        self.armed = np.zeros(n, dtype=bool)     # ... as arrays
        self.landed = np.ones(n, dtype=bool)
        self.link_ok = np.ones(n, dtype=bool)
        self.modes: list[Any] = []
        self.tick_read = 0                           # readings so far
        #: every drone ticks whole, as on the object core (drones under drones, peer Heartbeats):
        #: each publishes its own Heartbeat and Report and re-sends its own tasks
        self.whole = False
        self.fetched = np.zeros(n, dtype=np.int64)   # the reading each record in ``tels`` is from

    def read(self, vehicles: list[Any], landed: np.ndarray, crashed: bool) -> None:
        """Every drone's reading at the start of its tick, as arrays (a drone's commands change only
        its own vehicle, so reading all first reads what each would have read). The telemetry
        records are fetched only for the drones that tick in Python (:meth:`fetch`); a crashed
        vehicle's frozen record is its own, so with a crash every record is fetched."""
        self.tick_read += 1
        if crashed:
            tels = self.tels = list(map(_TELEMETRY, vehicles))
            self.fetched[:] = self.tick_read
            self.armed = np.fromiter(map(_ARMED, tels), bool, self.n)
            self.landed = np.fromiter(map(_LANDED, tels), bool, self.n)
            self.link_ok = np.fromiter(map(_LINK, tels), bool, self.n)
            self.modes = list(map(_MODE, tels))
            return
        self.armed = np.fromiter(map(_ARMED, vehicles), bool, self.n)   # what the record would say
        self.landed = landed.copy()
        self.link_ok[:] = True
        self.modes = list(map(_MODE, vehicles))

    def fetch(self, many: Callable[[list[int]], list[Telemetry]], drones: np.ndarray) -> None:
        """The telemetry records of ``drones`` (this tick's reading); ``many``: the backend's records
        of a list of vehicles (``vehicles[k].telemetry()`` of each)."""
        fetched, now = self.fetched, self.tick_read
        todo = [k for k in drones.tolist() if fetched[k] != now] if len(drones) < 32 else (
            drones[fetched[drones] != now].tolist())   # a few drones: no numpy calls
        if todo:
            tels = self.tels
            for k, tel in zip(todo, many(todo), strict=True):
                tels[k] = tel
            fetched[todo] = now

    def settle(self, vehicles: list[Any]) -> None:
        """Records for the drones not fetched at the last reading, with what the arrays read then
        (armed, landed, link): what the end-of-run summary and a vehicle failure read."""
        for k in np.flatnonzero(self.fetched != self.tick_read).tolist():
            self.tels[k] = vehicles[k].telemetry()._replace(
                armed=bool(self.armed[k]), landed=bool(self.landed[k]), link_ok=bool(self.link_ok[k]))
            self.fetched[k] = self.tick_read


def _array_property(name: str, cast: type) -> property:
    def get(self: FleetAgent) -> Any:
        return cast(getattr(self._fleet, name)[self._k])

    def put(self: FleetAgent, value: Any) -> None:
        getattr(self._fleet, name)[self._k] = value

    return property(get, put)


class FleetAgent(AgentNode):
    """An AgentNode whose per-tick state lives in the fleet's arrays (see the module's notes)."""

    def __init__(self, node_id: int, *, fleet: FleetState, k: int, **kw: Any) -> None:
        self._fleet, self._k = fleet, k
        super().__init__(node_id, **kw)
        fleet.entry_tick[k] = 0   # the first tick counts 0, as the object core's first increment makes it

    stage_code = _array_property("stage", int)
    complete = _array_property("complete", bool)
    finished = _array_property("finished", bool)
    _seq = _array_property("seq", int)
    _sup_silent = _array_property("sup_silent", int)
    _heard_superior = _array_property("heard", bool)

    @property
    def stage_tick(self) -> int:
        return self.time.tick - int(self._fleet.entry_tick[self._k])

    @stage_tick.setter
    def stage_tick(self, value: int) -> None:
        self._fleet.entry_tick[self._k] = self.time.tick - value

    @property
    def telemetry(self) -> Telemetry:
        return self._fleet.tels[self._k]

    @telemetry.setter
    def telemetry(self, value: Telemetry) -> None:
        self._fleet.tels[self._k] = value

    def fleet_tick(self) -> None:
        """AgentNode.tick without what the fleet does over its arrays: the stage tick (derived),
        the telemetry reading (done for all), the Report (sent with all) and the state row."""
        self.fleet_inbound()
        self.fleet_outbound()

    def fleet_inbound(self) -> None:
        """The inbound half of :meth:`fleet_tick` (link check, inbox, superior watchdog): a batch
        algorithm's drones all run it before the fleet's loop hooks."""
        tel = self.telemetry
        self._own = None
        if not tel.link_ok and self.stage not in TERMINAL:
            self.event("failsafe", "vehicle_link_lost", self.node_id, action="return_to_launch")
            self.enter(Stage.ABORT, "link to the autopilot lost", failsafe=True)
        if self.inbox or self._window_busy or self.proximity:
            self._drain_inbox()
        if self._heard_superior and self.stage not in TERMINAL:   # the superior watchdog
            self._sup_silent += 1
            if self._sup_silent > self._lost_superior_ticks:
                self._hand_over("silent")
        if self.inferiors:   # a superior drone (only when the fleet ticks whole)
            self.age_inferiors()

    def fleet_outbound(self) -> None:
        """The outbound half of :meth:`fleet_tick`: stage work (hooks, setpoint) and completion."""
        tel = self.telemetry
        now = self.clock.now()
        self.complete = self._stage_work(tel, now)
        if self._fleet.whole:   # its own Heartbeat and Report (none sent in the fleet's batch)
            self._publish(tel, now)
            if self.outbox.pending:
                self.retry_tasks()
        if self.stage in TERMINAL and (not tel.armed or self.stage_timed_out()):
            self.finished = True
        # held reliable tasks or a proximity alert in force: the inbox is drained every tick
        self._fleet.sticky[self._k] = bool(self._window_busy or self.proximity)

    def buffer_setpoints(self, rows: SetpointRows) -> Callable[[bytes], None]:
        """Write this drone's ``setpoints`` rows into the fleet's buffer ``rows`` (which hands them to
        its log in order); returns the log's own appender."""
        own, self._log_setpoint = self._log_setpoint, partial(rows.one, self.node_id)
        return own

    def fleet_loop(self, tel: Any, batch: SetpointBatch) -> bool:
        """The tick of a drone in a loop stage with nothing in its inbox and its watchdog quiet (the
        fleet counted it): AgentNode._stage_work with its setpoint left in ``batch``, handed over
        after the last drone's hooks (in a tick of few such drones, at once); returns ``complete``.
        ``tel``: its telemetry record, or for a batch algorithm's drone (whose loop work reads of it
        only whether the vehicle is armed) ``ARMED_ONLY[armed]``. The progress event may come before
        the setpoint here: it goes to the node's log now, the vehicle's events from the setpoint
        after the step, as on the object core."""
        self._own = None
        stage = self.stage
        complete, sp = self._loop_hooks(stage, tel)
        if sp is not None:
            if batch.inline:   # a few drones this tick: its setpoint now, as on the object core
                self.send_setpoint(sp, batch.times[self._k])
            else:
                batch.drones.append(self._k)
                batch.setpoints.append(sp)
        if stage is _EXECUTION and complete != self._exec_done:
            self._note_exec(complete)
        return complete
