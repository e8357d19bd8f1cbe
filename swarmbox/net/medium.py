"""An in-process network on the run's clock, with per-link latency, jitter and loss.

Every message is recorded where it happens: a ``send`` row in the sender's log (one per
destination; a published Heartbeat gets one row for all its subscribers, ``dst`` =
:data:`~swarmbox.core.messages.BROADCAST` and the destinations listed in ``reason``), a ``recv``
row in the receiver's log stamped with the receiver's clock at the *arrival* instant (so latency
below one tick is measurable), and a ``drop`` row in the ``net`` log.
A message sent during tick k is handed to its receiver at the first tick at or after its arrival,
and never earlier than tick k+1. All randomness comes from the generator given at construction.

On an ideal network (no per-link specs, no fault hooks, constant delay, no loss) a published
Heartbeat travels as one queue item for all its subscribers, and nothing is drawn at random.
"""

from __future__ import annotations

import heapq
from collections import deque
from collections.abc import Callable, Mapping
from dataclasses import dataclass

import numpy as np

from swarmbox.core.clock import NodeClock, TimeSource
from swarmbox.core.messages import BROADCAST, MESSAGE_TYPE_CODES, broadcast_dsts
from swarmbox.core.rows import DROP, NO_TEXT, RECV, SEND, TEXTS, pack_message

#: takes one packed ``messages`` row (``swarmbox.core.rows.pack_message``)
Append = Callable[[bytes], None]


_UNREACHABLE = TEXTS.code("unreachable")


@dataclass(frozen=True, slots=True)
class LinkSpec:
    latency_s: float = 0.0   # constant one-way delay
    jitter_s: float = 0.0    # extra delay, uniform in [0, jitter_s]
    loss_prob: float = 0.0   # Bernoulli drop probability

    def __post_init__(self) -> None:
        if self.latency_s < 0 or self.jitter_s < 0:
            raise ValueError(f"link latency and jitter must be >= 0, got {self}")
        if not 0.0 <= self.loss_prob <= 1.0:
            raise ValueError(f"link loss_prob must be within [0, 1], got {self.loss_prob}")

    def impair(self, rng: np.random.Generator, hooks: list[LinkHook], msg, src: int, dst: int,
               t: float) -> tuple[float, str]:
        """``(delay_s, drop_reason or "")`` of one message on this link: latency, jitter, loss, then
        every fault hook in order (the draws happen in this order, so a seed replays exactly)."""
        delay, reason = self.latency_s, ""
        if self.jitter_s:
            delay += self.jitter_s * rng.random()
        if self.loss_prob and rng.random() < self.loss_prob:
            reason = "loss"
        for hook in hooks:
            verdict = hook(msg, src, dst, t)
            if verdict is not None:
                reason = reason or verdict[0]
                delay += verdict[1]
        return delay, reason


#: A link hook (used by fault injection) sees each (message, src, dst) at send time and returns
#: None to leave it alone, or (drop_reason or "", extra_delay_s).
LinkHook = Callable[[object, int, int, float], "tuple[str, float] | None"]


class _Endpoint:
    __slots__ = ("clock", "log", "inbox", "connected")

    def __init__(self, clock: NodeClock, log: Append) -> None:
        self.clock, self.log = clock, log
        self.inbox: list = []
        self.connected = True


class SimMedium:
    """The simulated network. Nodes register, subscribe to Heartbeat publishers, send, receive."""

    def __init__(self, time: TimeSource, rng: np.random.Generator, default: LinkSpec = LinkSpec(),
                 links: Mapping[tuple[int, int], LinkSpec] | None = None,
                 drop_log: Append | None = None) -> None:
        self._time, self._rng, self._default = time, rng, default
        self._links = dict(links or {})
        self._drop_log = drop_log or (lambda row: None)
        self._nodes: dict[int, _Endpoint] = {}
        self._subscribers: dict[int, list[int]] = {}
        self._queue: list = []            # (arrival, tick, seq, dst, msg, type code, nbytes), a heap
        self._fifo: deque = deque()       # same items, for messages with the default constant delay
        self._seq = 0
        self.hooks: list[LinkHook] = []
        self._ideal = not (default.jitter_s or default.loss_prob)   # and no links or hooks: _plain()
        #: publisher -> its subscribers, the text code of their list, whether all are reachable
        self._fanout: dict[int, tuple[tuple[int, ...], int, bool]] = {}

    # -- membership -----------------------------------------------------------------------------
    def register(self, node_id: int, clock: NodeClock, log: Append) -> list:
        """Attach a node; returns its inbox (a list the node drains each tick)."""
        ep = _Endpoint(clock, log)
        self._nodes[node_id] = ep
        self._fanout.clear()
        return ep.inbox

    def disconnect(self, node_id: int) -> None:
        """The node goes silent: nothing it sends leaves, nothing reaches it (e.g. a crash)."""
        self._nodes[node_id].connected = False
        self._fanout.clear()

    def subscribe(self, subscriber: int, publisher: int) -> None:
        subs = self._subscribers.setdefault(publisher, [])
        if subscriber not in subs:
            subs.append(subscriber)
            self._fanout.pop(publisher, None)

    def unsubscribe(self, subscriber: int, publisher: int) -> None:
        subs = self._subscribers.get(publisher, [])
        if subscriber in subs:
            subs.remove(subscriber)
            self._fanout.pop(publisher, None)

    def has_subscribers(self, publisher: int) -> bool:
        return bool(self._subscribers.get(publisher))

    def link(self, src: int, dst: int) -> LinkSpec:
        return self._links.get((src, dst), self._default)

    # -- traffic --------------------------------------------------------------------------------
    def publish(self, msg) -> None:
        """Send a Heartbeat to every subscriber of its sender: one ``send`` row for all of them."""
        src = msg.src
        fan = self._fanout.get(src)
        if fan is None:
            fan = self._fan(src)
        dsts, text, reachable = fan
        if not dsts:
            return
        sender = self._nodes[src]
        if not sender.connected:
            return
        t, tick = self._time.t_s, self._time.tick
        mtype, nbytes = MESSAGE_TYPE_CODES[type(msg)], msg.nbytes
        # a message is stamped with its sender's clock as it is sent: t_sent_s is that reading
        sent = msg.t_sent_s
        sender.log(pack_message(sent, tick, SEND, msg.msg_id, mtype, src, BROADCAST, nbytes, sent, text))
        if reachable and self._plain():
            self._fifo.append((t + self._default.latency_s, tick, 0, dsts, msg, mtype, nbytes))
            return
        for dst in dsts:
            self._route(msg, src, dst, t, tick, mtype, nbytes)

    def _plain(self) -> bool:
        """Every link has the default constant delay and no loss, and no fault hook is installed (hooks
        come and go with faults, so this is asked, not stored)."""
        return self._ideal and not self._links and not self.hooks

    def _fan(self, src: int) -> tuple[tuple[int, ...], int, bool]:
        dsts = tuple(self._subscribers.get(src, ()))
        nodes = self._nodes
        reachable = all(d in nodes and nodes[d].connected for d in dsts)
        fan = self._fanout[src] = (dsts, TEXTS.code(broadcast_dsts(dsts)), reachable)
        return fan

    def send(self, msg, dst: int) -> None:
        src = msg.src
        sender = self._nodes[src]
        if not sender.connected:
            return
        t, tick = self._time.t_s, self._time.tick
        mtype, nbytes = MESSAGE_TYPE_CODES[type(msg)], msg.nbytes
        sent = msg.t_sent_s
        sender.log(pack_message(sent, tick, SEND, msg.msg_id, mtype, src, dst, nbytes, sent, NO_TEXT))
        if self._ideal and not self._links and not self.hooks:   # _plain(), inline: once per drone and tick
            receiver = self._nodes.get(dst)
            if receiver is not None and receiver.connected:   # ideal and reachable: no draw, FIFO
                self._fifo.append((t + self._default.latency_s, tick, 0, dst, msg, mtype, nbytes))
                return
        self._route(msg, src, dst, t, tick, mtype, nbytes)

    def _route(self, msg, src: int, dst: int, t: float, tick: int, mtype: int, nbytes: int) -> None:
        """Impair one (message, destination) and queue it, or log its drop."""
        if not self._plain():
            spec = self._links.get((src, dst), self._default) if self._links else self._default
            delay, reason = spec.impair(self._rng, self.hooks, msg, src, dst, t)
        else:
            delay, reason = self._default.latency_s, ""
        receiver = self._nodes.get(dst)
        if not reason and (receiver is None or not receiver.connected):
            reason = "unreachable"
        if reason:
            self._drop_log(pack_message(t, tick, DROP, msg.msg_id, mtype, src, dst, nbytes, msg.t_sent_s,
                                        TEXTS.code(reason)))
            return
        if delay == self._default.latency_s and not self._default.jitter_s:
            self._fifo.append((t + delay, tick, 0, dst, msg, mtype, nbytes))   # arrival order kept
        else:
            self._seq += 1
            heapq.heappush(self._queue, (t + delay, tick, self._seq, dst, msg, mtype, nbytes))

    def deliver_due(self) -> None:
        """Hand every message that has arrived by now (and was sent in an earlier tick) over."""
        t, tick = self._time.t_s + 1e-12, self._time.tick
        fifo, q, nodes = self._fifo, self._queue, self._nodes
        last_ep = last_arrival = local = None   # a run of messages to one node arriving at one instant
        while fifo and fifo[0][0] <= t and fifo[0][1] < tick:
            item = fifo.popleft()
            dst = item[3]
            ep = nodes[dst] if type(dst) is int else None
            if ep is not None and ep.connected:   # the common case, inline: one receiver, reachable
                arrival, _, _, _, msg, mtype, nbytes = item
                if ep is not last_ep or arrival != last_arrival:   # e.g. every Report to the ground
                    last_ep, last_arrival, local = ep, arrival, ep.clock.at(arrival)
                ep.log(pack_message(local, tick, RECV, msg.msg_id, mtype, msg.src, dst, nbytes, msg.t_sent_s,
                                    NO_TEXT))
                ep.inbox.append(msg)
            else:
                self._hand_over(item, tick)
        while q and q[0][0] <= t and q[0][1] < tick:
            self._hand_over(heapq.heappop(q), tick)

    def _hand_over(self, item: tuple, tick: int) -> None:
        arrival, _, _, dst, msg, mtype, nbytes = item
        if type(dst) is tuple:   # one Heartbeat for all its subscribers (ideal network)
            nodes, msg_id, src, t_sent_s = self._nodes, msg.msg_id, msg.src, msg.t_sent_s
            for d in dst:
                ep = nodes[d]
                if ep.connected:
                    ep.log(pack_message(ep.clock.at(arrival), tick, RECV, msg_id, mtype, src, d, nbytes,
                                        t_sent_s, NO_TEXT))
                    ep.inbox.append(msg)
                else:
                    self._drop_log(pack_message(arrival, tick, DROP, msg_id, mtype, src, d, nbytes, t_sent_s,
                                                _UNREACHABLE))
            return
        ep = self._nodes[dst]
        if not ep.connected:
            self._drop_log(pack_message(arrival, tick, DROP, msg.msg_id, mtype, msg.src, dst, nbytes,
                                        msg.t_sent_s, _UNREACHABLE))
            return
        ep.log(pack_message(ep.clock.at(arrival), tick, RECV, msg.msg_id, mtype, msg.src, dst, nbytes,
                            msg.t_sent_s, NO_TEXT))
        ep.inbox.append(msg)
