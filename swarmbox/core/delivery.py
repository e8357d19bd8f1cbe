"""Reliable task commands: exactly once and in send order, per sender, under any loss or reordering.

Sender side (:class:`Outbox`): each reliable command to a receiver gets the next number (1, 2, ...)
and is re-sent every ``retry_ticks`` until acknowledged, at most ``max_retries`` times; every copy
carries ``floor``, the lowest number still in flight, so the receiver learns when a gap was
abandoned (retries exhausted, or the receiver was declared lost) instead of waiting for it forever.

Receiver side (:class:`Window`): acknowledges every copy, drops duplicates, holds a command that
arrived ahead of a missing one, and releases held commands in number order once the gap fills (or
falls below the sender's floor, or has stayed open longer than the sender keeps retrying: the
sender gave it up, and may have nothing left in flight to carry the news). A command is also held
until the receiver has entered the stage the sender was in when it sent it, so no hook sees a
stage's tasks before that stage's ``*_once``.
"""

from __future__ import annotations

from swarmbox.api.types import Stage
from swarmbox.core.messages import TaskCommand

_ABORT = int(Stage.ABORT)


class _Pending:
    __slots__ = ("cmd", "next_tick", "retries")

    def __init__(self, cmd: TaskCommand, next_tick: int) -> None:
        self.cmd, self.next_tick, self.retries = cmd, next_tick, 0


class Outbox:
    """Numbers, remembers and re-sends one node's reliable commands until acknowledged."""

    def __init__(self, retry_ticks: int, max_retries: int) -> None:
        self.retry_ticks, self.max_retries = retry_ticks, max_retries
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

    def acked(self, src: int, seq: int) -> None:
        inflight = self.pending.get(src)
        if inflight is not None:
            inflight.pop(seq, None)

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

    def forget(self, dst: int) -> None:
        """Stop re-sending to ``dst`` (declared lost); the next copy's floor skips the gap."""
        self.pending.pop(dst, None)

    @property
    def busy(self) -> bool:
        return any(self.pending.values())


class _Sender:
    __slots__ = ("next", "floor", "held", "since")

    def __init__(self) -> None:
        self.next, self.floor = 1, 1
        self.held: dict[int, TaskCommand] = {}
        self.since: dict[int, int] = {}       # number -> tick it arrived


class Window:
    """One receiver's per-sender window over reliable commands.

    ``give_up_ticks``: how long a gap may stay open before the receiver concludes the sender
    abandoned it (longer than the sender's whole retry schedule).
    """

    def __init__(self, give_up_ticks: int) -> None:
        self.give_up_ticks = give_up_ticks
        self._senders: dict[int, _Sender] = {}

    def accept(self, cmd: TaskCommand, tick: int) -> bool:
        """Take a received copy; False when it is a duplicate (already delivered or held)."""
        s = self._senders.get(cmd.src)
        if s is None:
            s = self._senders[cmd.src] = _Sender()
        if cmd.floor > s.floor:
            s.floor = cmd.floor
        if cmd.seq < s.next or cmd.seq in s.held:
            return False
        s.held[cmd.seq] = cmd
        s.since[cmd.seq] = tick
        return True

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
            elif s.next < s.floor:   # the sender gave this one up
                s.next = min([s.floor, *held])
            elif held and tick - min(s.since.values()) > self.give_up_ticks:
                s.next = min(held)   # ... and said so in no copy that got through
            else:
                break
        return out

    def holding(self) -> list[int]:
        """Senders with commands held back."""
        return [src for src, s in self._senders.items() if s.held]
