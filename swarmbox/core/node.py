"""What the ground node and the agent nodes share: stages, messaging, inferior bookkeeping,
reliable task commands, markers and logging."""

from __future__ import annotations

import json
import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from functools import partial
from types import MappingProxyType
from typing import Any, Protocol

import numpy as np

from swarmbox.api.types import DescendantState, InferiorReport, MissionInfo, Stage
from swarmbox.core.clock import NodeClock, TimeSource
from swarmbox.core.delivery import Outbox
from swarmbox.core.messages import NO_SUBJECT, Report, TaskAck, TaskCommand, make_msg_id
from swarmbox.core.ports import Transport
from swarmbox.core.stages import check_transition

Row = tuple
_ABORT = int(Stage.ABORT)
#: Stage by code, for building views without an enum call per message.
STAGE_OF = {int(s): s for s in Stage}
#: InferiorReport(*fields) without the Python-level NamedTuple constructor (one per Report received).
new_inferior_report = partial(tuple.__new__, InferiorReport)
_new_descendant = partial(tuple.__new__, DescendantState)


class NodeLog(Protocol):
    """Where a node writes its rows (see ``swarmbox.record.schema`` for the columns): a row tuple, or
    for the packed tables (``messages``, ``setpoints``) a row packed by :mod:`swarmbox.core.rows`."""

    def appender(self, table: str) -> Callable[[Row | bytes], None]: ...


@dataclass(frozen=True, slots=True)
class CoreTiming:
    """Protocol timings and limits, in ticks unless the name says otherwise."""

    tick_s: float = 0.025
    lost_inferior_ticks: int = 20
    lost_superior_ticks: int = 40
    task_retry_ticks: int = 8
    task_max_retries: int = 40
    arm_retry_ticks: int = 20
    proximity_m: float = 2.0
    proximity_window_s: float = 0.0   # look-ahead of the proximity alerts (0: current distance only)
    min_alive: int = 1
    state_every_ticks: int = 1
    timeouts_s: Mapping[str, float] = field(default_factory=lambda: {
        "ICEBREAK": 60.0, "PREPARATION": 60.0, "EXECUTION": 900.0, "LANDING": 120.0,
        "TERMINATION": 10.0, "ABORT": 120.0})


class AlgorithmError(RuntimeError):
    """A user hook raised; the message names the node and the hook."""


class _Inferior:
    __slots__ = ("report", "silent_ticks", "alive", "received")

    def __init__(self, report: Report) -> None:
        self.report, self.silent_ticks, self.alive = report, 0, True
        self.received = 1   # Reports received: the live monitor's loss estimate


class Node:
    """Base of the ground node and the agent node."""

    def __init__(self, node_id: int, *, time: TimeSource, clock: NodeClock, net: Transport,
                 inbox: list, log: NodeLog, timing: CoreTiming, mission: MissionInfo,
                 params: Mapping[str, Any], rng: np.random.Generator, incarnation: int = 0) -> None:
        self.node_id = node_id
        #: this process's boot count for the node (0 in a single-process run): in every message id,
        #: reliable task and acknowledgement, so nothing a restarted node sends is taken for its past
        self.incarnation = incarnation
        self.time, self.clock, self.net, self.inbox = time, clock, net, inbox
        self.timing, self.tick_s = timing, timing.tick_s
        self.mission, self.params, self.rng = mission, params, rng
        self.stage = Stage.ICEBREAK
        self.stage_code = int(self.stage)   # the stage as a plain int (messages and logs carry it)
        self.stage_tick = -1          # the first tick counts 0, like every stage's entry tick
        self.finished = False
        self.inferiors: dict[int, _Inferior] = {}
        self._alive: dict[int, InferiorReport] = {}  # latest Report of each alive inferior, as a view
        self._alive_view = MappingProxyType(self._alive)
        self.regroup_until_tick = -1   # a lost inferior's own inferiors may still be handing over
        self._seq = 0
        self._msg_id_base = make_msg_id(node_id, 0, incarnation)   # | seq: one OR per message
        self.outbox = Outbox(timing.task_retry_ticks, timing.task_max_retries, incarnation)
        self._log_stage = log.appender("stages")
        self._log_event = log.appender("events")
        self._log_stage((clock.now(), time.tick, int(Stage.ICEBREAK), Stage.ICEBREAK.name, ""))

    # -- ids, logging ---------------------------------------------------------------------------
    def next_msg_id(self) -> int:
        self._seq += 1
        return self._msg_id_base | self._seq

    def event(self, kind: str, name: str, subject: int = NO_SUBJECT, **data: Any) -> None:
        self._log_event((self.clock.now(), self.time.tick, kind, name, subject,
                         json.dumps(data, sort_keys=True, default=_jsonable)))

    def mark(self, name: str, fields: Mapping[str, Any]) -> None:
        self.event("marker", str(name), self.node_id, **fields)

    # -- stages ---------------------------------------------------------------------------------
    def set_stage(self, stage: Stage, reason: str = "") -> None:
        check_transition(self.stage, stage)
        self.stage, self.stage_code, self.stage_tick = stage, int(stage), 0
        self._log_stage((self.clock.now(), self.time.tick, self.stage_code, stage.name, reason))

    def stage_timed_out(self) -> bool:
        return self.stage_tick * self.tick_s > self.timing.timeouts_s[self.stage.name]

    # -- inferiors ------------------------------------------------------------------------------
    def on_report(self, rep: Report, now: float | None = None) -> bool:
        """Store a Report; returns False (and logs) when the sender is not a known drone.

        ``now``: this node's clock reading, when the caller already has it (one per inbox drain).
        """
        src = rep.src
        inf = self.inferiors.get(src)
        if inf is None:
            if src not in self.mission.initial_positions:
                self.event("error", "unknown_drone", src, reason="report from a drone not in the mission")
                return False
            self.inferiors[src] = _Inferior(rep)
            self.event("topology", "inferior_joined", src)
        else:   # known, hence in the mission
            if not inf.alive:
                inf.alive = True
                self.event("topology", "inferior_rejoined", src)
            inf.report, inf.silent_ticks = rep, 0
            inf.received += 1
        self._alive[src] = new_inferior_report((src, STAGE_OF[rep.stage], rep.complete, rep.pos_ned_m,
                                                 rep.vel_ned_m_s, rep.data,
                                                 self.clock.now() if now is None else now))
        return True

    def age_inferiors(self) -> None:
        limit = self.timing.lost_inferior_ticks
        for drone_id, inf in self.inferiors.items():
            inf.silent_ticks += 1
            if inf.alive and inf.silent_ticks > limit:
                inf.alive = False
                del self._alive[drone_id]
                self.event("topology", "inferior_lost", drone_id, silent_ticks=inf.silent_ticks)
                if inf.report.total_count > 1:
                    # its inferiors notice only after lost_superior_ticks, then hand over to us
                    self.regroup_until_tick = self.time.tick + self.timing.lost_superior_ticks + limit
                for seq, retries in self.outbox.forget(drone_id):
                    self.event("error", "task_undelivered", drone_id, seq=seq, retries=retries,
                               incarnation=self.incarnation, reason="receiver lost")

    def alive_reports(self) -> Mapping[int, InferiorReport]:
        """Read-only view of the latest Report of each alive direct inferior."""
        return self._alive_view

    def inferiors_complete(self) -> bool:
        """Every alive direct inferior reports complete *for this node's current stage*.

        An inferior that aborted on its own (failsafe) no longer holds the others back.
        """
        stage = int(self.stage)
        return all(inf.report.complete and inf.report.stage == stage
                   for inf in self.inferiors.values() if inf.alive and inf.report.stage != _ABORT)

    def head_count(self) -> tuple[int, int]:
        """(total, alive) drones reachable through alive direct inferiors."""
        total = alive = 0
        for inf in self.inferiors.values():
            if inf.alive:
                total += inf.report.total_count
                alive += inf.report.total_alive
        return total, alive

    def descendants(self) -> tuple[DescendantState, ...]:
        out = []
        append, extend = out.append, out.extend
        for drone_id, inf in self.inferiors.items():
            if inf.alive:
                rep = inf.report
                append(_new_descendant((drone_id, rep.stage, rep.pos_ned_m)))
                if rep.descendants:
                    extend(rep.descendants)
        return tuple(out)

    # -- tasks ----------------------------------------------------------------------------------
    def send_task(self, dst: int, code: int, waypoint: tuple | None, yaw_rad: float | None,
                  data: str, reliable: bool) -> None:
        inf = self.inferiors.get(dst)
        if inf is None or not inf.alive:
            self.event("error", "task_to_unknown_inferior", dst, code=code,
                       known=sorted(self.alive_reports()))
            return
        seq, floor = self.outbox.number(dst, reliable)
        cmd = TaskCommand(self.next_msg_id(), self.clock.now(), self.node_id, dst, seq, reliable,
                          int(code), waypoint, yaw_rad, data, int(self.stage), floor, self.incarnation)
        self.net.send(cmd, dst)
        if reliable:
            self.outbox.track(cmd, self.time.tick)

    def on_ack(self, ack: TaskAck) -> None:
        self.outbox.acked(ack.src, ack.seq, ack.incarnation)   # one for an earlier process: ignored

    def retry_tasks(self) -> None:
        outbox = self.outbox
        if not outbox.busy:
            return
        resend, abandoned = outbox.due(self.time.tick)
        for dst, seq, retries in abandoned:
            self.event("error", "task_undelivered", dst, seq=seq, retries=retries,
                       incarnation=self.incarnation, reason="retries exhausted")
        for cmd in resend:
            self.net.send(cmd._replace(msg_id=self.next_msg_id(), t_sent_s=self.clock.now(),
                                       floor=outbox.floor(cmd.dst, cmd.seq)), cmd.dst)


def call_hook(node: Node, hook: str, fn: Callable, *args: Any) -> Any:
    """Run a user hook; wrap anything it raises in an AlgorithmError naming node and hook."""
    try:
        return fn(*args)
    except Exception as exc:  # the user's code may raise anything
        raise hook_error(node, hook, exc) from exc


def hook_error(node: Node, hook: str, exc: Exception) -> AlgorithmError:
    """The AlgorithmError for ``exc`` raised by ``hook`` (for hot paths that inline :func:`call_hook`)."""
    who = "ground" if node.node_id < 0 else f"drone {node.node_id}"
    return AlgorithmError(f"{who}: {hook} raised {type(exc).__name__}: {exc}")


def _jsonable(x: Any) -> Any:
    if isinstance(x, np.generic):
        return x.item()
    if isinstance(x, np.ndarray):
        return x.tolist()
    if isinstance(x, float) and not math.isfinite(x):
        return str(x)
    return str(x)
