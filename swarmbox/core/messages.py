"""Swarm messages: Heartbeat, Report, TaskCommand (+ TaskAck) and ProxAlert.

Fields follow the reference implementation; every message also carries a run-unique ``msg_id``, the
sender's local clock time ``t_sent_s`` and can tell its encoded size (``nbytes``), so the recorder and
the analyzer can follow each message across the network. Messages are immutable ``NamedTuple``s: they
are built tens of thousands of times per simulated minute and must stay cheap.
"""

from __future__ import annotations

from typing import NamedTuple

from swarmbox.api.types import DescendantState
from swarmbox.core.rows import TEXTS

GROUND_ID = -1
#: Pseudo-node id under which the simulated network records drops.
NET_ID = -2
#: The ``subject`` of an event that is about no node in particular.
NO_SUBJECT = -3
#: The ``dst`` of the one ``send`` row logged for a Heartbeat published to its subscribers; the row's
#: ``reason`` lists the destinations (see :func:`broadcast_dsts`).
BROADCAST = -4

# Encoded sizes (bytes) of a compact binary encoding: header = msg_id u64, t_sent f64, src i16,
# dst i16, type u8.
_HEADER = 21
_VEC3 = 12  # three float32
# a Report's size without its data and descendants: header, stage, complete, two counts, position,
# velocity, discrepancy, data length (folded here: Report.nbytes is asked once per drone and tick)
_REPORT_FIXED = _HEADER + 1 + 1 + 2 + 2 + 3 * _VEC3 + 2
_DESCENDANT_BYTES = 2 + 1 + _VEC3   # id, stage, position


#: Task codes travel as an unsigned LEB128 varint: one byte below 128 (every shipped algorithm's
#: codes), up to five bytes for the largest code.
TASK_CODE_MAX = 2**32 - 1


def task_code_nbytes(code: int) -> int:
    """Wire bytes of a task code (1 below 128, 2 below 16384, ...)."""
    return 1 if code < 0x80 else (code.bit_length() + 6) // 7


def broadcast_dsts(dsts: tuple[int, ...] | list[int]) -> str:
    """The ``reason`` text of a broadcast ``send`` row: its destination ids, comma-separated."""
    return ",".join(map(str, dsts))


#: Bits of a message id: the sender's counter below :data:`SEQ_BITS`, then the low eight bits of the
#: sender's incarnation, then the sender id (+2) from bit 40.
SEQ_BITS = 32
INCARNATION_MAX = 2**32 - 1


def make_msg_id(src: int, seq: int, incarnation: int = 0) -> int:
    """A run-unique message id from the sender id, its incarnation and its message counter.

    The incarnation (a node's boot count) keeps a restarted node's ids apart from those of its
    earlier processes; ids repeat only after 256 restarts of one node within one run. Incarnation 0
    (every node of a single-process run) gives ``((src + 2) << 40) | seq``.
    """
    return ((src + 2) << 40) | ((incarnation & 0xFF) << SEQ_BITS) | seq


class Heartbeat(NamedTuple):
    """Superior -> its inferiors (and any subscribed peer), every tick.

    ``stage`` is the command for the inferiors; ``successors`` is the ordered list of fallback
    superiors for the sender's inferiors should the sender fall silent.
    """

    msg_id: int
    t_sent_s: float
    src: int
    stage: int
    successors: tuple[int, ...]
    pos_ned_m: tuple[float, float, float]
    vel_ned_m_s: tuple[float, float, float]

    @property
    def nbytes(self) -> int:
        return _HEADER + 1 + 1 + 2 * len(self.successors) + 2 * _VEC3


class Report(NamedTuple):
    """Inferior -> its superior, every tick: progress, head-count, own state, mission payload."""

    msg_id: int
    t_sent_s: float
    src: int
    dst: int
    stage: int
    complete: bool
    total_count: int
    total_alive: int
    pos_ned_m: tuple[float, float, float]
    vel_ned_m_s: tuple[float, float, float]
    discrepancy_ned_m: tuple[float, float, float] | None
    data: str
    descendants: tuple[DescendantState, ...]

    @property
    def nbytes(self) -> int:
        return _REPORT_FIXED + len(self.data) + len(self.descendants) * _DESCENDANT_BYTES


class TaskCommand(NamedTuple):
    """A superior's command to one inferior. Its meaning (``code``, ``data``) belongs to the algorithm.

    ``reliable`` commands are numbered per (sender incarnation, receiver) from 1, acknowledged by a
    :class:`TaskAck` once delivered and re-sent until acknowledged; ``floor`` is the lowest number the
    sender still tries to deliver (lower ones are acknowledged or abandoned), so the receiver's window
    can skip an abandoned gap. ``stage`` is the sender's stage at send time: the receiver hands the
    command to its algorithm only once it is in that stage too. ``incarnation`` is the sender's boot
    count: a restarted sender numbers from 1 again under a higher one. Best-effort commands carry
    their own counter.
    """

    msg_id: int
    t_sent_s: float
    src: int
    dst: int
    seq: int
    reliable: bool
    code: int
    waypoint_ned_m: tuple[float, float, float] | None
    yaw_rad: float | None
    data: str
    stage: int = 0
    floor: int = 0
    incarnation: int = 0

    @property
    def nbytes(self) -> int:
        return _HEADER + 4 + 1 + task_code_nbytes(self.code) + _VEC3 + 4 + 2 + len(self.data) + 1 + 4 + 4


class TaskAck(NamedTuple):
    """Says the reliable TaskCommand ``seq`` of ``dst`` (the original sender) in its ``incarnation``
    reached the receiver's algorithm; sent only once it did."""

    msg_id: int
    t_sent_s: float
    src: int
    dst: int
    seq: int
    incarnation: int = 0

    @property
    def nbytes(self) -> int:
        return _HEADER + 4 + 4


class ProxAlert(NamedTuple):
    """Ground -> a drone that has others within the proximity radius: their ids and positions."""

    msg_id: int
    t_sent_s: float
    src: int
    dst: int
    neighbours: tuple[DescendantState, ...]

    @property
    def nbytes(self) -> int:
        return _HEADER + 2 + len(self.neighbours) * (2 + 1 + _VEC3)


Message = Heartbeat | Report | TaskCommand | TaskAck | ProxAlert

MESSAGE_TYPES: dict[type, str] = {
    Heartbeat: "heartbeat",
    Report: "report",
    TaskCommand: "task",
    TaskAck: "ack",
    ProxAlert: "prox",
}
#: Each message type's code in the log's text table (``swarmbox.core.rows``).
MESSAGE_TYPE_CODES: dict[type, int] = {cls: TEXTS.code(name) for cls, name in MESSAGE_TYPES.items()}
