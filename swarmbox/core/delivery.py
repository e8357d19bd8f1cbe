"""Reliable task commands: exactly once and in send order, per sender, under any loss or reordering,
and across restarts of either end; whatever cannot be delivered is said so, never acknowledged.

Sender side (:class:`Outbox`): each reliable command to a receiver gets the next number (1, 2, ...)
within the sender's *incarnation* (its boot count: a restarted sender numbers from 1 again under a
higher one) and is re-sent every ``retry_ticks`` until acknowledged, at most ``max_retries`` times;
every copy carries ``floor``, the lowest number still in flight, so the receiver learns when a gap was
abandoned (retries exhausted, or the receiver was declared lost) instead of waiting for it forever.
An acknowledgement counts only for the incarnation it names.

Receiver side (:class:`Window`): holds a command that arrived ahead of a missing one and releases
held commands in number order once the gap fills (or falls below the sender's floor, or has stayed
open, since the *oldest* held arrival, longer than the sender keeps retrying: the sender gave it up,
and may have nothing left in flight to carry the news). A command is also held until the receiver
has entered the stage the sender was in when it sent it, so no hook sees a stage's tasks before that
stage's ``*_once``. The receiver acknowledges a command only once its algorithm has it (and again
for a copy of one it delivered, whose acknowledgement may have been lost); a copy of a number it
skipped, or of an earlier incarnation of the sender, is never acknowledged. A command from a
higher incarnation resets that sender's window. Every skipped number and every copy refused is
noted in :attr:`Window.notes` for the node to log.
"""

from __future__ import annotations

from typing import NamedTuple

from swarmbox.api.types import Stage
from swarmbox.core.messages import TaskCommand

_ABORT = int(Stage.ABORT)

# What Window.accept found a copy to be
NEW = "new"                # held for delivery (maybe deliverable at once)
HELD = "held"              # a copy of one held already: no acknowledgement yet
DELIVERED = "delivered"    # a copy of one delivered: acknowledge it again
SKIPPED = "skipped"        # a late copy of a skipped number: never delivered, never acknowledged
STALE = "stale"            # from an earlier incarnation of the sender: ignored

#: Skipped ranges a window remembers per sender (older late copies are refused as too old to tell)
SKIPPED_RANGES = 64


class Skip(NamedTuple):
    """Numbers ``first..last`` of ``src``'s ``incarnation`` that the receiver will never deliver."""

    src: int
    incarnation: int
    first: int
    last: int
    reason: str


class _Pending:
    __slots__ = ("cmd", "next_tick", "retries")

    def __init__(self, cmd: TaskCommand, next_tick: int) -> None:
        self.cmd, self.next_tick, self.retries = cmd, next_tick, 0


class Outbox:
    """Numbers, remembers and re-sends one node's reliable commands until acknowledged."""

    def __init__(self, retry_ticks: int, max_retries: int, incarnation: int = 0) -> None:
        self.retry_ticks, self.max_retries, self.incarnation = retry_ticks, max_retries, incarnation
        self._next: dict[int, int] = {}                      # receiver -> next number
        self._stream: dict[int, int] = {}                    # receiver -> best-effort counter
        self.pending: dict[int, dict[int, _Pending]] = {}    # receiver -> number -> in flight

    def number(self, dst: int, reliable: bool) -> tuple[int, int]:
        """(seq, floor) for a new command to ``dst``."""
        if not reliable:
            seq = self._stream[dst] = self._stream.get(dst, 0) + 1
            return seq, 0
        seq = self._next[dst] = self._next.get(dst, 0) + 1
        return seq, self.floor(dst, seq)

    def floor(self, dst: int, default: int) -> int:
        inflight = self.pending.get(dst)
        return next(iter(inflight)) if inflight else default

    def track(self, cmd: TaskCommand, tick: int) -> None:
        self.pending.setdefault(cmd.dst, {})[cmd.seq] = _Pending(cmd, tick + self.retry_ticks)

    def acked(self, src: int, seq: int, incarnation: int = 0) -> bool:
        """Take an acknowledgement; False when it names another (earlier) incarnation of this sender."""
        if incarnation != self.incarnation:
            return False
        inflight = self.pending.get(src)
        if inflight is not None:
            inflight.pop(seq, None)
        return True

    def due(self, tick: int) -> tuple[list[TaskCommand], list[tuple[int, int, int]]]:
        """(commands to re-send now, (dst, seq, retries) abandoned now)."""
        resend: list[TaskCommand] = []
        abandoned: list[tuple[int, int, int]] = []
        for dst, inflight in self.pending.items():
            for seq, p in list(inflight.items()):
                if tick < p.next_tick:
                    continue
                if p.retries >= self.max_retries:
                    del inflight[seq]
                    abandoned.append((dst, seq, p.retries))
                    continue
                p.retries += 1
                p.next_tick = tick + self.retry_ticks
                resend.append(p.cmd)
        return resend, abandoned

    def forget(self, dst: int) -> list[tuple[int, int]]:
        """Stop re-sending to ``dst`` (declared lost); the next copy's floor skips the gap.

        Returns the (seq, retries) of every command dropped unacknowledged, for the caller to log.
        """
        inflight = self.pending.pop(dst, None) or {}
        return [(seq, p.retries) for seq, p in inflight.items()]

    @property
    def busy(self) -> bool:
        return any(self.pending.values())


class _Sender:
    __slots__ = ("incarnation", "next", "floor", "held", "since", "skipped", "unsure_below")

    def __init__(self, incarnation: int, start: int) -> None:
        self.incarnation = incarnation
        self.next = self.floor = start
        self.held: dict[int, TaskCommand] = {}
        self.since: dict[int, int] = {}                # number -> tick it arrived
        self.skipped: list[tuple[int, int]] = []       # (first, last) ranges never delivered
        self.unsure_below = 0                          # skipped ranges below this were forgotten

    def never_delivered(self, seq: int) -> str:
        """Why ``seq`` (below ``next``) was not delivered, or "" when it was."""
        if seq < self.unsure_below:
            return "late copy older than the skipped numbers the receiver remembers"
        if any(a <= seq <= b for a, b in self.skipped):
            return "late copy of a skipped task"
        return ""


class Window:
    """One receiver's per-sender window over reliable commands.

    ``give_up_ticks``: how long a gap may stay open before the receiver concludes the sender
    abandoned it (longer than the sender's whole retry schedule).
    """

    def __init__(self, give_up_ticks: int) -> None:
        self.give_up_ticks = give_up_ticks
        self._senders: dict[int, _Sender] = {}
        #: numbers skipped and copies refused since the node last logged them
        self.notes: list[Skip] = []

    def accept(self, cmd: TaskCommand, tick: int) -> str:
        """Take a received copy; returns what it is (:data:`NEW`, :data:`HELD`, :data:`DELIVERED`,
        :data:`SKIPPED` or :data:`STALE`)."""
        s = self._senders.get(cmd.src)
        if s is None or cmd.incarnation > s.incarnation:
            if s is not None:   # the sender restarted: what its earlier process left held is dropped
                for seq in sorted(s.held):
                    self.notes.append(Skip(cmd.src, s.incarnation, seq, seq, "the sender restarted"))
            # a sender met for the first time (or anew) starts at its floor: everything lower was
            # acknowledged to, or abandoned by, the sender before this receiver heard of it
            s = self._senders[cmd.src] = _Sender(cmd.incarnation, max(cmd.floor, 1))
        elif cmd.incarnation < s.incarnation:
            self.notes.append(Skip(cmd.src, cmd.incarnation, cmd.seq, cmd.seq,
                                   "copy from an earlier incarnation of the sender"))
            return STALE
        if cmd.floor > s.floor:
            s.floor = cmd.floor
        if cmd.seq < s.next:
            why = s.never_delivered(cmd.seq)
            if why:
                self.notes.append(Skip(cmd.src, s.incarnation, cmd.seq, cmd.seq, why))
                return SKIPPED
            return DELIVERED
        if cmd.seq in s.held:
            return HELD
        s.held[cmd.seq] = cmd
        s.since[cmd.seq] = tick
        return NEW

    def release(self, src: int, stage: int, tick: int) -> list[TaskCommand]:
        """Commands from ``src`` now deliverable to a receiver in ``stage``, in number order."""
        s = self._senders.get(src)
        out: list[TaskCommand] = []
        if s is None:
            return out
        held = s.held
        while True:
            cmd = held.get(s.next)
            if cmd is not None:
                if cmd.stage > stage and stage != _ABORT:
                    break
                out.append(held.pop(s.next))
                del s.since[s.next]
                s.next += 1
            elif s.next < s.floor:   # the sender gave this one up (held ones below the floor stay)
                self._skip(src, s, min([s.floor, *held]), "the sender gave it up")
            elif held and tick - min(s.since.values()) > self.give_up_ticks:
                self._skip(src, s, min(held), "gap open longer than the sender's retry schedule")
            else:
                break
        return out

    def _skip(self, src: int, s: _Sender, to: int, reason: str) -> None:
        """Move ``s.next`` up to ``to``, noting the numbers passed over as never delivered."""
        s.skipped.append((s.next, to - 1))
        if len(s.skipped) > SKIPPED_RANGES:
            s.unsure_below = s.skipped.pop(0)[1] + 1
        self.notes.append(Skip(src, s.incarnation, s.next, to - 1, reason))
        s.next = to

    def holding(self) -> list[int]:
        """Senders with commands held back."""
        return [src for src, s in self._senders.items() if s.held]
