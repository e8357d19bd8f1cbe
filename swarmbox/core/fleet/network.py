"""The fleet's simulated network: every message of a tick routed as one batch of arrays.

The same network as :class:`swarmbox.net.medium.SimMedium` (constant latency, uniform jitter,
Bernoulli loss, all from the run's ``network`` generator), computed over arrays: the periodic
traffic (a Heartbeat published to every subscriber, every drone's Report) travels as array rows,
other messages (tasks, acknowledgements, proximity alerts) as the message objects, side by side.

Why the results are the object core's, number for number:

- *Draws.* SimMedium draws, per message and destination, one uniform for the jitter (if any) and
  one for the loss (if any), at send time, in send order. Every message takes the same number of
  draws whatever happens to it, so a tick's draws are one ``rng.random(k * M)`` call over its M
  messages put in send order: the ground's first (its Heartbeat to each subscriber in subscription
  order, then whatever its hooks send), then each drone's in fleet order (what its hooks sent, then
  its Report). ``Generator.random(n)`` yields the stream of ``n`` scalar calls.
- *Delivery order.* SimMedium hands over a message at the first tick at or after its arrival, in
  send order on a constant-delay network (a FIFO) and by ``(arrival, send tick, send order)`` with
  jitter (a heap). The pending rows are kept sorted that way, so a tick's deliveries are a prefix.
- *Rows.* A send row when sent (a Heartbeat: one row for all subscribers), a drop row in the
  network's log when lost, a receive row stamped with the receiver's clock at the arrival instant;
  per node in the order they happen, which is all the per-node log files keep.

Per-link specs (``network.links``), fault hooks (``hooks``, as on SimMedium) and disconnected nodes
(a crashed drone's) take the per-message path of :mod:`swarmbox.core.fleet.impair` for the ticks
they are there; without them nothing is called per message.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from swarmbox.core.clock import NodeClock, TimeSource
from swarmbox.core.fleet import impair
from swarmbox.core.fleet.rows import MESSAGE_ROW, MessageRows, concat, take
from swarmbox.core.messages import BROADCAST, MESSAGE_TYPE_CODES, NET_ID, Heartbeat, Report, broadcast_dsts
from swarmbox.core.rows import DROP, NO_TEXT, RECV, SEND, TEXTS

HEARTBEAT, REPORT = MESSAGE_TYPE_CODES[Heartbeat], MESSAGE_TYPE_CODES[Report]
_LOSS = TEXTS.code("loss")
#: a message in flight, as one record (``obj``: its object's key, -1 for a batch Report; ``dsti``,
#: ``srci``: node indices; the rest of a Report's fields after ``stage``, its ``data`` text as the
#: key of a kept object, -1 for "", ``disc`` its GNSS discrepancy, NaN for None). No object field:
#: records with one copy several times slower.
ITEM = np.dtype([("arrival", "f8"), ("tick", "i8"), ("order", "i8"), ("src", "i2"), ("srci", "i4"),
                 ("dst", "i2"), ("dsti", "i4"), ("msg_id", "i8"), ("mtype", "i4"), ("nbytes", "i4"),
                 ("t_sent", "f8"), ("obj", "i8"), ("stage", "i8"), ("complete", "?"), ("alive", "i4"),
                 ("pos", "f8", (3,)), ("vel", "f8", (3,)), ("data", "i8"), ("disc", "f8", (3,))])


def join(parts: list[np.ndarray]) -> np.ndarray:
    """The records of ``parts`` in order."""
    return parts[0] if len(parts) == 1 else concat(parts)


def empty(n: int, **values: Any) -> np.ndarray:
    """Records for ``n`` messages, zero but for ``values`` (arrays, sequences or scalars)."""
    seg = np.zeros(n, dtype=ITEM)
    seg["data"], seg["disc"] = -1, np.nan
    for name, value in values.items():
        seg[name] = value
    return seg


class FleetNetwork:
    """Routes every message of the fleet core; node index 0 is the ground, ``k + 1`` drone ``k``."""

    def __init__(self, time: TimeSource, rng: np.random.Generator, node_ids: list[int],
                 clocks: list[NodeClock], rows: MessageRows, *, latency_s: float = 0.0,
                 jitter_s: float = 0.0, loss_prob: float = 0.0,
                 links: dict[tuple[int, int], impair.Link] | None = None) -> None:
        self._time, self._rng, self.rows = time, rng, rows
        self.ids = np.array(node_ids, dtype=np.int16)
        self._index = {node: k for k, node in enumerate(node_ids)}
        self._clocks = clocks
        self.refresh_clocks()
        self.latency_s, self.jitter_s, self.loss_prob = latency_s, jitter_s, loss_prob
        self._draws = (jitter_s > 0) + (loss_prob > 0)   # uniforms per message (none: ideal network)
        self._subscribers: dict[int, list[int]] = {}
        self._fans: dict[int, tuple[np.ndarray, int]] = {}   # publisher -> see _fan
        self._objects: dict[int, list] = {}   # key -> [message, destinations still to hand over]
        self._next_obj = 0
        self._routed = 0                      # messages routed so far (the heap's tie-break)
        self._out: list[np.ndarray] = []      # this tick's messages, in segments
        self._out_keys: list[tuple[np.ndarray, np.ndarray]] = []
        self._singles: list[tuple] = []       # this tick's single messages, until the next segment
        self.phase = 0                        # 0: the ground's turn; k + 1: drone k's
        self._counter = 0                     # send order within a phase
        self.pending = empty(0)
        #: fault hooks (:attr:`swarmbox.net.medium.SimMedium.hooks`), per-link specs and disconnected
        #: nodes: with any of them a tick's messages are impaired one by one (:mod:`.impair`)
        self.hooks: list[impair.Hook] = []
        self.links = dict(links or {})
        self.gone = np.zeros(len(node_ids), dtype=bool)
        self.any_gone = False
        self.late = empty(0)   # see impair.split

    @property
    def time(self) -> TimeSource:
        return self._time

    @property
    def kept(self) -> dict[int, list]:
        """The message objects in flight: key -> [message, destinations still to hand over]."""
        return self._objects

    def refresh_clocks(self) -> None:
        """Read the nodes' clock lines again (at the start, and when a clock fault skews one)."""
        self._scale = np.array([c._scale for c in self._clocks])
        self._offset = np.array([c._offset_s for c in self._clocks])

    def disconnect(self, node_id: int) -> None:
        """The node goes silent (SimMedium.disconnect): nothing it sends leaves, nothing reaches it."""
        self.gone[self._index[node_id]] = True
        self.any_gone = True

    # -- the Transport protocol (the object nodes' calls) ---------------------------------------
    def subscribe(self, subscriber: int, publisher: int) -> None:
        subs = self._subscribers.setdefault(publisher, [])
        if subscriber not in subs:
            subs.append(subscriber)
            self._fans.pop(publisher, None)

    def unsubscribe(self, subscriber: int, publisher: int) -> None:
        subs = self._subscribers.get(publisher, [])
        if subscriber in subs:
            subs.remove(subscriber)
            self._fans.pop(publisher, None)

    def has_subscribers(self, publisher: int) -> bool:
        return bool(self._subscribers.get(publisher))

    def send(self, msg: Any, dst: int) -> None:
        """One message to one node: its send row now, its routing with the tick's batch."""
        mtype, nbytes, sent, src = MESSAGE_TYPE_CODES[type(msg)], msg.nbytes, msg.t_sent_s, msg.src
        if self.any_gone and self.gone[self._index[src]]:
            return
        self.rows.one(src, (sent, self._time.tick, SEND, msg.msg_id, mtype, src, dst, nbytes, sent, NO_TEXT))
        key = self._keep(msg, 1)
        self._singles.append((self.phase, self._counter, src, self._index[src], dst, self._index[dst],
                              msg.msg_id, mtype, nbytes, sent, key))
        self._counter += 1

    def publish(self, msg: Any) -> None:
        """A Heartbeat to every subscriber of its sender: one ``send`` row for all of them."""
        src = msg.src
        fan = self._fans.get(src)
        if fan is None:
            fan = self._fan(src)
        template, text = fan
        n = len(template)
        if not n or (self.any_gone and self.gone[self._index[src]]):
            return
        mtype, nbytes, sent = MESSAGE_TYPE_CODES[type(msg)], msg.nbytes, msg.t_sent_s
        self.rows.one(src, (sent, self._time.tick, SEND, msg.msg_id, mtype, src, BROADCAST, nbytes, sent,
                            text))
        seg = template.copy()
        seg["msg_id"], seg["mtype"], seg["nbytes"], seg["t_sent"] = msg.msg_id, mtype, nbytes, sent
        seg["obj"], seg["stage"] = self._keep(msg, n), msg.stage if mtype == HEARTBEAT else -1
        self._settle()
        self._out.append(seg)
        self._out_keys.append((np.full(n, self.phase), self._counter + np.arange(n)))
        self._counter += n

    def _fan(self, src: int) -> tuple[np.ndarray, int]:
        """A publisher's subscribers as records to copy, and the text code of their list (kept until
        a subscription changes)."""
        dsts = self._subscribers.get(src, [])
        template = empty(len(dsts), src=src, srci=self._index[src], dst=dsts,
                         dsti=[self._index[d] for d in dsts])
        fan = self._fans[src] = (template, TEXTS.code(broadcast_dsts(dsts)) if dsts else NO_TEXT)
        return fan

    def _keep(self, msg: Any, n: int) -> int:
        key = self._next_obj
        self._objects[key] = [msg, n]
        self._next_obj += 1
        return key

    def _settle(self) -> None:
        """The single messages sent so far, as one segment (before the next segment)."""
        singles = self._singles
        if not singles:
            return
        phase, counter, src, srci, dst, dsti, msg_id, mtype, nbytes, sent, obj = zip(*singles, strict=True)
        seg = empty(len(singles), src=src, srci=srci, dst=dst, dsti=dsti, msg_id=msg_id, mtype=mtype,
                    nbytes=nbytes, t_sent=sent, obj=obj, stage=-1)
        self._out.append(seg)
        self._out_keys.append((np.array(phase, dtype=np.int64), np.array(counter, dtype=np.int64)))
        self._singles = []

    # -- batches ---------------------------------------------------------------------------------
    def reports(self, src: list[int], dst: list[int]) -> tuple[np.ndarray, np.ndarray]:
        """Records and send rows for one Report from each of ``src`` to its ``dst``, with every field
        that stays the same from tick to tick (:meth:`send_reports` fills in the rest)."""
        n = len(src)
        seg = empty(n, src=src, srci=[self._index[s] for s in src], dst=dst,
                    dsti=[self._index[d] for d in dst], mtype=REPORT, obj=-1)
        rows = np.zeros(n, dtype=MESSAGE_ROW)
        rows["kind"], rows["type"], rows["src"], rows["dst"], rows["reason"] = SEND, REPORT, src, dst, NO_TEXT
        return seg, rows

    def send_reports(self, seg: np.ndarray, rows: np.ndarray, data: list[str]) -> None:
        """Every drone's Report of this tick (``seg``: their records, ``rows`` their send rows, drones
        in fleet order; ``data``: their texts); each goes out after whatever its drone's hooks sent."""
        for k in [k for k, text in enumerate(data) if text]:   # usually none
            seg["data"][k] = self._keep(data[k], 1)
        self._settle()
        rows["t_s"] = rows["t_sent_s"] = seg["t_sent"]
        rows["tick"], rows["msg_id"], rows["nbytes"] = self._time.tick, seg["msg_id"], seg["nbytes"]
        self.rows.add(seg["src"], rows)
        self._out.append(seg)
        self._out_keys.append((seg["srci"].astype(np.int64), np.full(len(seg), 1 << 40)))

    def route(self) -> None:
        """Impair this tick's messages in send order: drop rows for the lost, the rest in flight."""
        self._settle()
        if not self._out:
            return
        segs, keys = self._out, self._out_keys
        self._out, self._out_keys, self._counter = [], [], 0
        out = join(segs)
        if len(segs) > 1:
            phase, order = np.concatenate([k[0] for k in keys]), np.concatenate([k[1] for k in keys])
            ahead = (phase[1:] < phase[:-1]) | ((phase[1:] == phase[:-1]) & (order[1:] < order[:-1]))
            if ahead.any():   # something sent by a drone's hooks: put it before that drone's Report
                out = take(out, np.lexsort((order, phase)))
        m = len(out)
        t, tick = self._time.t_s, self._time.tick
        out["tick"][:] = tick
        out["order"] = self._routed + np.arange(m)
        self._routed += m
        if self.hooks or self.links or self.any_gone:   # message by message, as SimMedium._route
            delay, reason = impair.each(self, self._rng, out, t)
            lost = reason != NO_TEXT
            out["arrival"] = t + delay
            if lost.any():
                self._drop(out, lost, t, reason[lost])
                out, delay = take(out, ~lost), delay[~lost]
            self._enqueue(*impair.split(self, out, delay))
            return
        delay = np.full(m, self.latency_s)
        lost = np.zeros(m, dtype=bool)
        if self._draws:
            u = self._rng.random(m * self._draws).reshape(m, self._draws)
            if self.jitter_s:
                delay = self.latency_s + self.jitter_s * u[:, 0]
            if self.loss_prob:
                lost = u[:, -1] < self.loss_prob
        out["arrival"] = t + delay
        if lost.any():
            self._drop(out, lost, t, _LOSS)
            out = take(out, ~lost)
        self._enqueue(out)

    def drop_rows(self, lost: np.ndarray, t: Any, reason: Any) -> None:
        """One ``drop`` row for each record of ``lost``, stamped ``t`` (its send, or for an
        unreachable node its arrival)."""
        self.rows.block(NET_ID, {"t_s": t, "tick": self._time.tick, "kind": DROP, "msg_id": lost["msg_id"],
                                 "type": lost["mtype"], "src": lost["src"], "dst": lost["dst"],
                                 "nbytes": lost["nbytes"], "t_sent_s": lost["t_sent"], "reason": reason},
                        len(lost))

    def _drop(self, out: np.ndarray, lost: np.ndarray, t: Any, reason: Any) -> None:
        self.drop_rows(take(out, lost), t, reason)
        self._forget(out["obj"][lost])
        self._forget(out["data"][lost])

    def text(self, key: int) -> str:
        """A delivered Report's data text (its key released)."""
        if key < 0:
            return ""
        text = self._objects.pop(key)[0]
        return text

    def _forget(self, keys: np.ndarray) -> None:
        """Objects handed over (or lost) for some of their destinations."""
        keys = keys[keys >= 0]
        if not len(keys):
            return
        if keys[0] == keys[-1] and (keys == keys[0]).all():   # one Heartbeat's copies
            keys, counts = keys[:1], np.array([len(keys)])
        else:
            keys, counts = np.unique(keys, return_counts=True)
        for key, count in zip(keys.tolist(), counts.tolist(), strict=True):
            entry = self._objects[key]
            entry[1] -= count
            if not entry[1]:
                del self._objects[key]

    def _enqueue(self, out: np.ndarray, late: np.ndarray | None = None) -> None:
        both = join([self.pending, out]) if len(self.pending) else out
        if self.jitter_s:   # the heap's order: arrival, then send tick, then send order
            both = take(both, np.lexsort((both["order"], both["tick"], both["arrival"])))
        self.pending = both
        if late is not None and len(late):
            both = join([self.late, late]) if len(self.late) else late
            self.late = take(both, np.lexsort((both["order"], both["tick"], both["arrival"])))

    def deliver(self) -> np.ndarray:
        """Every message that has arrived by now, in hand-over order, with its receive row logged;
        the objects among them in ``objects`` (None for a batch Report)."""
        p = self.pending
        n = int(np.searchsorted(p["arrival"], self._time.t_s + 1e-12, side="right"))
        due, self.pending = p[:n], p[n:]
        if self.any_gone or len(self.late):
            due = impair.arrived(self, due)
            n = len(due)
        if not n:
            return due
        dsti = due["dsti"]   # the receiver's clock at the arrival instant (NodeClock.at, the same arithmetic)
        local = due["arrival"] * self._scale[dsti] + self._offset[dsti]
        self.rows.block(due["dst"], {"t_s": local, "tick": self._time.tick, "kind": RECV,
                                     "msg_id": due["msg_id"], "type": due["mtype"], "src": due["src"],
                                     "dst": due["dst"], "nbytes": due["nbytes"], "t_sent_s": due["t_sent"],
                                     "reason": NO_TEXT}, n)
        return due

    def objects(self, keys: np.ndarray) -> list[Any]:
        """The message objects of delivered rows (``keys`` >= 0)."""
        objects = self._objects
        return [objects[k][0] for k in keys.tolist()]

    def release(self, keys: np.ndarray) -> None:
        """Delivered rows: their objects are kept until every destination has had its copy."""
        self._forget(keys)
