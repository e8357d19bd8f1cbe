"""The swarm network over Eclipse Zenoh: one peer session per node process, no broker.

Each node listens on its own TCP locator and connects to every other node's; multicast scouting is
off, so a session only ever meets the nodes of its own mission. Key expressions are
``swarmbox/<mission>/to/<dst>`` for messages to one node and ``swarmbox/<mission>/hb/<src>`` for
Heartbeats (a subscriber declares interest in a publisher by subscribing to that key).

Frames are the compact encoding of :mod:`swarmbox.net.codec`, signed by :mod:`swarmbox.net.auth`.
The network fault models act at the receiver, once per (message, destination), exactly as in
:class:`~swarmbox.net.medium.SimMedium`: the configured link latency/jitter/loss and any fault hook
(burst loss, partition, link cut) delay or drop a message before the node sees it. A frame is
signed for the key expression it is published on, and a message addressed to another node is
refused (``misdirected``): a frame captured on its way to one node cannot be replayed to another.
Rows logged:
``send`` (sender, one per known destination), ``recv`` (receiver, stamped at arrival on its clock)
and ``drop`` (receiver; fault drops and every rejected frame with its reason).
"""

from __future__ import annotations

import heapq
import json
import time as wall
from collections import deque
from collections.abc import Callable, Mapping

import numpy as np
import zenoh

from swarmbox.core.clock import NodeClock, TimeSource
from swarmbox.core.messages import MESSAGE_TYPE_CODES, NO_SUBJECT, Heartbeat
from swarmbox.core.rows import DROP, NO_TEXT, RECV, SEND, TEXTS, pack_message
from swarmbox.net.auth import AuthSpec, Rejected, Signer, Verifier
from swarmbox.net.codec import DecodeError, decode, encode
from swarmbox.net.medium import LinkHook, LinkSpec

Append = Callable[[bytes], None]   # one packed ``messages`` row
_REJECTED = TEXTS.code("rejected")


def session_config(listen: str, peers: list[str]) -> zenoh.Config:
    """A peer-mode session on explicit TCP locators, without multicast scouting."""
    conf = zenoh.Config()
    conf.insert_json5("mode", '"peer"')
    conf.insert_json5("listen/endpoints", json.dumps([listen]))
    conf.insert_json5("connect/endpoints", json.dumps(peers))
    conf.insert_json5("scouting/multicast/enabled", "false")
    return conf


class ZenohMedium:
    """The transport of one node process (same interface as :class:`SimMedium` for that node)."""

    def __init__(self, node_id: int, *, time: TimeSource, true_of: Callable[[float], float], auth: AuthSpec,
                 listen: str, peers: list[str], rng: np.random.Generator,
                 default: LinkSpec = LinkSpec(), links: Mapping[tuple[int, int], LinkSpec] | None = None,
                 subscribers: Mapping[int, list[int]] | None = None,
                 on_reject: Callable[[str, int | None], None] | None = None) -> None:
        self.node_id, self._time, self._true_of = node_id, time, true_of
        self._rng, self._default, self._links = rng, default, dict(links or {})
        self._static_subs = {k: list(v) for k, v in (subscribers or {}).items()}
        self._prefix = f"swarmbox/{auth.mission_id}"
        self._signer, self._verifier = Signer(auth, node_id), Verifier(auth)
        self._on_reject = on_reject or (lambda reason, sender: None)
        self._arrived: deque = deque()          # (arrival wall s, key expr, frame), filled by Zenoh's threads
        self._held: list = []                   # (due true s, seq, arrival true s, msg, nbytes)
        self._held_seq = 0
        self._log: Append = lambda row: None
        self._clock: NodeClock | None = None
        self.inbox: list = []
        self.connected = True
        self.hooks: list[LinkHook] = []
        self.bytes_out = self.bytes_in = 0
        self._session = zenoh.open(session_config(listen, peers))
        self._subs: dict[int, object] = {}
        self._direct = self._session.declare_subscriber(f"{self._prefix}/to/{node_id}", self._on_sample)
        self._hb_key = f"{self._prefix}/hb/{node_id}"
        self._hb_pub = self._session.declare_publisher(self._hb_key)
        self._pubs: dict[int, object] = {}

    # -- membership (the SimMedium interface, for the one local node) ---------------------------
    def register(self, node_id: int, clock: NodeClock, log: Append) -> list:
        if node_id != self.node_id:
            raise ValueError(f"this process runs node {self.node_id}, not {node_id}")
        self._clock, self._log = clock, log
        return self.inbox

    def disconnect(self, node_id: int) -> None:
        self.connected = False

    def subscribe(self, subscriber: int, publisher: int) -> None:
        if subscriber == self.node_id and publisher not in self._subs:
            self._subs[publisher] = self._session.declare_subscriber(f"{self._prefix}/hb/{publisher}",
                                                                     self._on_sample)

    def unsubscribe(self, subscriber: int, publisher: int) -> None:
        sub = self._subs.pop(publisher, None) if subscriber == self.node_id else None
        if sub is not None:
            sub.undeclare()

    def has_subscribers(self, publisher: int) -> bool:
        if self._static_subs.get(publisher):
            return True
        return publisher == self.node_id and self._hb_pub.matching_status.matching

    def link(self, src: int, dst: int) -> LinkSpec:
        return self._links.get((src, dst), self._default)

    # -- traffic --------------------------------------------------------------------------------
    def publish(self, msg: Heartbeat) -> None:
        if not self.connected:
            return
        frame = self._signer.sign(encode(msg), self._hb_key)
        for dst in self._static_subs.get(msg.src, ()):
            self._log_send(msg, dst, len(frame))
        self._hb_pub.put(frame)
        self.bytes_out += len(frame)

    def send(self, msg, dst: int) -> None:
        if not self.connected:
            return
        key = f"{self._prefix}/to/{dst}"
        frame = self._signer.sign(encode(msg), key)
        self._log_send(msg, dst, len(frame))
        pub = self._pubs.get(dst)
        if pub is None:
            pub = self._pubs[dst] = self._session.declare_publisher(key)
        pub.put(frame)
        self.bytes_out += len(frame)

    def _log_send(self, msg, dst: int, nbytes: int) -> None:
        self._log(pack_message(self._clock.now(), self._time.tick, SEND, msg.msg_id,
                               MESSAGE_TYPE_CODES[type(msg)], msg.src, dst, nbytes, msg.t_sent_s, NO_TEXT))

    def _on_sample(self, sample) -> None:
        self._arrived.append((wall.time(), str(sample.key_expr), bytes(sample.payload.to_bytes())))

    def deliver_due(self) -> None:
        """Verify and decode what has arrived, apply the link model, hand over what is due."""
        arrived = self._arrived
        while arrived:
            t_wall, key, frame = arrived.popleft()
            self._admit(self._true_of(t_wall), key, frame)
        now = self._time.t_s + 1e-12
        while self._held and self._held[0][0] <= now:
            _, _, arrival, msg, nbytes = heapq.heappop(self._held)
            self._hand_over(arrival, msg, nbytes)

    def _admit(self, arrival: float, key: str, frame: bytes) -> None:
        self.bytes_in += len(frame)
        try:
            sender, payload = self._verifier.open(frame, key)
            msg = decode(payload)
            if msg.src != sender:
                raise Rejected("forged", sender)
            if type(msg) is not Heartbeat and msg.dst != self.node_id:   # signed, but for another node
                raise Rejected("misdirected", sender)
        except Rejected as rej:
            self._reject(arrival, rej.reason, rej.sender, len(frame))
            return
        except DecodeError:
            self._reject(arrival, "malformed", None, len(frame))
            return
        if not self.connected:
            return
        src, dst = msg.src, self.node_id
        spec = self._links.get((src, dst), self._default) if self._links else self._default
        delay, reason = spec.impair(self._rng, self.hooks, msg, src, dst, arrival)
        if reason:
            self._log(pack_message(self._clock.at(arrival), self._time.tick, DROP, msg.msg_id,
                                   MESSAGE_TYPE_CODES[type(msg)], src, dst, len(frame), msg.t_sent_s,
                                   TEXTS.code(reason)))
        elif delay <= 0:
            self._hand_over(arrival, msg, len(frame))
        else:
            self._held_seq += 1
            heapq.heappush(self._held, (arrival + delay, self._held_seq, arrival + delay, msg, len(frame)))

    def _reject(self, arrival: float, reason: str, sender: int | None, nbytes: int) -> None:
        src = NO_SUBJECT if sender is None else sender
        self._log(pack_message(self._clock.at(arrival), self._time.tick, DROP, 0, _REJECTED, src,
                               self.node_id, nbytes, float("nan"), TEXTS.code(reason)))
        self._on_reject(reason, sender)

    def _hand_over(self, arrival: float, msg, nbytes: int) -> None:
        self._log(pack_message(self._clock.at(arrival), self._time.tick, RECV, msg.msg_id,
                               MESSAGE_TYPE_CODES[type(msg)], msg.src, self.node_id, nbytes, msg.t_sent_s,
                               NO_TEXT))
        self.inbox.append(msg)

    def close(self) -> None:
        """Leave the network (the session's threads stop)."""
        self.connected = False
        try:
            self._session.close()
        except Exception:   # closing a session that lost its peers must not hide the run's outcome
            pass
