"""MAVLink 2 message signing: the key and the timestamp (pymavlink signs and checks the packets).

A link with a key signs every packet it sends and accepts only packets signed with the same key, so a
process on the network that does not hold the key can neither command a vehicle nor pose as one. The
autopilot needs the same key (PX4: the ``SETUP_SIGNING`` message, or ``mavlink`` module parameters).
"""

from __future__ import annotations

import hashlib
import time

SIGNING_EPOCH_S = 1420070400   # 2015-01-01: MAVLink signing timestamps count 10 µs from here
#: environment variable that hands a signing key to a child process (never its command line or a log)
KEY_ENV = "SWARMBOX_MAVLINK_KEY"


def signing_timestamp(now_s: float | None = None) -> int:
    """MAVLink 2 signing's timestamp for wall time ``now_s`` (10 µs units since 2015)."""
    return int(((time.time() if now_s is None else now_s) - SIGNING_EPOCH_S) * 1e5)


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
