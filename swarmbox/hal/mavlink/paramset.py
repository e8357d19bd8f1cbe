"""Writing an autopilot parameter over MAVLink: PARAM_SET, confirmed by the PARAM_VALUE echo.

MAVLink's parameter protocol has no COMMAND_ACK: the autopilot answers a PARAM_SET with the
parameter's PARAM_VALUE, which carries the value it now holds. :class:`ParamSetter` re-sends until
that echo shows the requested value, up to ``retries`` times, then reports the outcome.
PX4 carries integer parameters bytewise (the int32's bits in the float field); the wire
conversions are :func:`param_to_wire` and :func:`param_from_wire`.
"""

from __future__ import annotations

import struct
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from pymavlink.dialects.v20 import common as mavlink

PARAM_INT32 = mavlink.MAV_PARAM_TYPE_INT32
PARAM_REAL32 = mavlink.MAV_PARAM_TYPE_REAL32


def param_to_wire(value: float, param_type: int) -> float:
    """The float field of PARAM_SET for ``value`` (PX4: an INT32's bits, bytewise)."""
    if param_type == PARAM_INT32:
        return float(struct.unpack("<f", struct.pack("<i", int(value)))[0])
    return float(value)


def param_from_wire(value: float, param_type: int) -> float:
    """The parameter's value from PARAM_VALUE's float field (inverse of :func:`param_to_wire`)."""
    if param_type == PARAM_INT32:
        return float(struct.unpack("<i", struct.pack("<f", value))[0])
    return float(value)


#: send(name, value, param_type) -> whether it left the socket
Send = Callable[[str, float, int], bool]
#: done(ok, detail): the echo confirmed the value (ok) or the retries ran out (detail says why)
Done = Callable[[bool, str], None]


@dataclass(slots=True)
class _Pending:
    value: float
    param_type: int
    done: Done
    tries: int = 0
    sent_s: float = -1.0
    last_seen: float | None = None


class ParamSetter:
    """PARAM_SET with confirmation, one pending write per parameter name (a newer one replaces it)."""

    def __init__(self, send: Send, timeout_s: float, retries: int) -> None:
        self._send, self.timeout_s, self.retries = send, timeout_s, retries
        self._pending: dict[str, _Pending] = {}

    def set(self, name: str, value: float, now_s: float, done: Done, param_type: int = PARAM_INT32) -> None:
        if len(name) > 16:
            raise ValueError(f"parameter name {name!r} longer than MAVLink's 16 characters")
        self._pending[name] = p = _Pending(float(value), param_type, done)
        self._transmit(name, p, now_s)

    def on_value(self, msg: Any) -> None:
        """A PARAM_VALUE (``name``, ``value``): confirms a pending write holding that value."""
        p = self._pending.get(msg.name)
        if p is None:
            return
        p.last_seen = msg.value
        if abs(msg.value - p.value) <= 1e-6 * max(1.0, abs(p.value)):
            del self._pending[msg.name]
            p.done(True, "")

    def service(self, now_s: float) -> None:
        for name, p in list(self._pending.items()):
            if now_s - p.sent_s < self.timeout_s:
                continue
            if p.tries > self.retries:
                del self._pending[name]
                seen = "no PARAM_VALUE" if p.last_seen is None else f"it holds {p.last_seen:g}"
                p.done(False, f"{name}={p.value:g} not confirmed after {p.tries} tries ({seen})")
            else:
                self._transmit(name, p, now_s)

    def _transmit(self, name: str, p: _Pending, now_s: float) -> None:
        self._send(name, p.value, p.param_type)
        p.tries += 1
        p.sent_s = now_s
