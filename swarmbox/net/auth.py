"""Authenticated frames: HMAC-SHA256 over every swarm message, with replay protection.

A frame is ``magic "SB" | version u8 | mission tag (4 B) | sender i16 | counter u64 | wall time f64 |
message | tag (16 B)``, the tag being the first 128 bits of HMAC-SHA256 under the mission key over
the Zenoh key expression the frame is published on (not sent: both ends know it) and everything
before the tag. The message inside names its destination, so a frame is bound to where it was
sent: replayed to another node's key it does not verify, and a receiver also refuses a message
addressed to another node (:mod:`swarmbox.net.zenoh_medium`). The receiver drops, and names the
reason of, a frame that is

* ``unsigned``: no envelope, or too short to hold one;
* ``wrong_mission``: signed for another mission (another tag);
* ``forged``: its tag does not verify (wrong key, altered, or received on another key expression
  than it was signed for), or the sender inside the message is not the one signed;
* ``stale``: its wall time is further than ``max_age_s`` from the receiver's, in either direction;
* ``replayed``: its counter was already seen from that sender, or is older than the window.

The counter starts at the sender's wall clock in microseconds, so a restarted node continues above
everything it sent before and is not mistaken for a replay. The key itself is never logged.

Trust model: one key per mission, shared by every node. It keeps out whoever does not hold it; it
does not tell the nodes apart — any node holding the key can sign as any other.
"""

from __future__ import annotations

import hashlib
import hmac
import struct
import time
from dataclasses import dataclass

MAGIC = b"SB"
VERSION = 2   # 2: the tag covers the key expression
TAG_BYTES = 16
_ENV = struct.Struct("<2sB4shQd")
KEY_ENV = "SWARMBOX_NET_KEY"


class Rejected(Exception):
    """A frame that must not reach a node; ``reason`` is one of the names in the module doc."""

    def __init__(self, reason: str, sender: int | None = None) -> None:
        super().__init__(reason)
        self.reason, self.sender = reason, sender


def mission_tag(mission_id: str) -> bytes:
    return hashlib.sha256(mission_id.encode()).digest()[:4]


@dataclass(frozen=True, slots=True)
class AuthSpec:
    key: bytes                  # the per-mission secret (>= 16 bytes)
    mission_id: str             # frames of any other mission are dropped
    max_age_s: float = 2.0      # wall-clock bound between sender and receiver
    window: int = 1024          # counters remembered per sender

    def __post_init__(self) -> None:
        if len(self.key) < 16:
            raise ValueError("the network key must be at least 16 bytes long")
        if self.max_age_s <= 0 or self.window < 1:
            raise ValueError(f"need max_age_s > 0 and window >= 1, got {self.max_age_s}, {self.window}")

    def __repr__(self) -> str:   # never show the key
        return f"AuthSpec(mission_id={self.mission_id!r}, max_age_s={self.max_age_s}, window={self.window})"


class Signer:
    """Wraps a node's outgoing messages."""

    def __init__(self, spec: AuthSpec, sender: int, wall=time.time) -> None:
        self._key, self._tag, self._sender, self._wall = spec.key, mission_tag(spec.mission_id), sender, wall
        self._counter = int(wall() * 1e6)

    def sign(self, payload: bytes, key_expr: str = "") -> bytes:
        """The frame of ``payload``, to be published on ``key_expr`` (and only there)."""
        self._counter += 1
        head = _ENV.pack(MAGIC, VERSION, self._tag, self._sender, self._counter, self._wall())
        body = head + payload
        return body + _mac(self._key, key_expr, body)


def _mac(key: bytes, key_expr: str, body: bytes) -> bytes:
    """The tag over the key expression (length-prefixed, so no two (key, body) splits collide) and body."""
    where = key_expr.encode()
    return hmac.new(key, len(where).to_bytes(2, "little") + where + body, hashlib.sha256).digest()[:TAG_BYTES]


class _Window:
    __slots__ = ("top", "seen")

    def __init__(self) -> None:
        self.top, self.seen = -1, 0


class Verifier:
    """Checks incoming frames; keeps one sliding counter window per sender."""

    def __init__(self, spec: AuthSpec, wall=time.time) -> None:
        self._spec, self._tag, self._wall = spec, mission_tag(spec.mission_id), wall
        self._windows: dict[int, _Window] = {}

    def open(self, frame: bytes, key_expr: str = "") -> tuple[int, bytes]:
        """(sender, message bytes) of a valid frame received on ``key_expr``; raises :class:`Rejected`
        otherwise."""
        if len(frame) < _ENV.size + TAG_BYTES or frame[:2] != MAGIC or frame[2] != VERSION:
            raise Rejected("unsigned")
        _, _, tag, sender, counter, t_wall = _ENV.unpack_from(frame, 0)
        if tag != self._tag:
            raise Rejected("wrong_mission", sender)
        body, mac = frame[:-TAG_BYTES], frame[-TAG_BYTES:]
        if not hmac.compare_digest(mac, _mac(self._spec.key, key_expr, body)):
            raise Rejected("forged", sender)
        if abs(self._wall() - t_wall) > self._spec.max_age_s:   # two-sided: a future date is no better
            raise Rejected("stale", sender)
        self._accept(sender, counter)
        return sender, body[_ENV.size:]

    def _accept(self, sender: int, counter: int) -> None:
        w = self._windows.setdefault(sender, _Window())
        size = self._spec.window
        if counter > w.top:
            shift = counter - w.top
            w.seen = ((w.seen << shift) | 1) & ((1 << size) - 1) if shift < size else 1
            w.top = counter
            return
        back = w.top - counter
        if back >= size or (w.seen >> back) & 1:
            raise Rejected("replayed", sender)
        w.seen |= 1 << back


OVERHEAD_BYTES = _ENV.size + TAG_BYTES
