"""MAVLink 2 message signing: the key and the timestamp (pymavlink signs and checks the packets).

A link with a key signs every packet it sends and accepts only packets signed with the same key, so a
process on the network that does not hold the key can neither command a vehicle nor pose as one. The
autopilot needs the same key (PX4: the ``SETUP_SIGNING`` message, or ``mavlink`` module parameters).

Timestamps follow the wall clock on both sides (:func:`keep_current`): a sender stamps each packet
with at least the current time (pymavlink alone adds one per packet, falling behind the clock), and
a receiver meets a new stream with its own current time, so it refuses a packet stamped more than a
minute before now — one recorded long ago and replayed to a freshly started link.
"""

from __future__ import annotations

import hashlib
import time
from typing import Any

SIGNING_EPOCH_S = 1420070400   # 2015-01-01: MAVLink signing timestamps count 10 µs from here
#: environment variable that hands a signing key to a child process (never its command line or a log)
KEY_ENV = "SWARMBOX_MAVLINK_KEY"


def signing_timestamp(now_s: float | None = None) -> int:
    """MAVLink 2 signing's timestamp for wall time ``now_s`` (10 µs units since 2015)."""
    return int(((time.time() if now_s is None else now_s) - SIGNING_EPOCH_S) * 1e5)


def keep_current(signing: Any, now_s: float | None = None) -> None:
    """Move a pymavlink ``MAVLinkSigning``'s timestamp up to the wall clock (never back)."""
    now = signing_timestamp(now_s)
    if signing.timestamp < now:
        signing.timestamp = now


def signing_key_of(text: str) -> bytes:
    """A 32-byte signing key from 64 hex digits, or the SHA-256 of any other passphrase
    (MAVProxy's ``signing setup`` convention)."""
    text = str(text).strip()
    if not text:
        raise ValueError("empty MAVLink signing key")
    try:
        key = bytes.fromhex(text)
    except ValueError:
        key = b""
    return key if len(key) == 32 else hashlib.sha256(text.encode()).digest()
