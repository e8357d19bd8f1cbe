"""A compact binary encoding of the swarm messages (what a real link carries).

Little-endian, no padding, no field names: a 21-byte header (type u8, msg_id u64, t_sent_s f64,
src i16, dst i16) and a fixed body per type, vectors as three float32, stages as signed bytes, a
task's code as an unsigned LEB128 varint (one byte below 128, at most five up to 2**32-1). An
absent vector or yaw is NaN; variable parts (successors, descendants, neighbours) carry a count
or fill the frame's tail. The encoded length equals the message's ``nbytes`` for ASCII payload
strings, so the sizes the logs record are the sizes on the wire.
"""

from __future__ import annotations

import math
import operator
import struct

from swarmbox.core.messages import (
    NO_SUBJECT,
    TASK_CODE_MAX,
    DescendantState,
    Heartbeat,
    ProxAlert,
    Report,
    TaskAck,
    TaskCommand,
)

_HEADER = struct.Struct("<BQdhh")
_VEC = struct.Struct("<3f")
_HB = struct.Struct("<bB")
_REPORT = struct.Struct("<b?HH9fH")
_TASK_HEAD = struct.Struct("<I?")
_TASK_TAIL = struct.Struct("<bII4fH")   # stage, floor, incarnation, waypoint, yaw, data length
_ACK = struct.Struct("<II")   # seq, the acknowledged sender's incarnation
_COUNT = struct.Struct("<H")
_DESC = struct.Struct("<hb3f")
_NAN3 = (math.nan, math.nan, math.nan)

_TYPE_CODE = {Heartbeat: 1, Report: 2, TaskCommand: 3, TaskAck: 4, ProxAlert: 5}


class DecodeError(ValueError):
    """A frame that is not a well-formed swarm message."""


def check_task_code(code) -> int:
    """``code`` as an int if it fits the wire field, else a ValueError naming the allowed range."""
    try:
        value = operator.index(code)
    except TypeError:
        value = None
    if value is None or isinstance(code, bool) or not 0 <= value <= TASK_CODE_MAX:
        raise ValueError(f"task code must be an integer in 0..{TASK_CODE_MAX}, got {code!r}")
    return value


def _varint(value: int) -> bytes:
    out = bytearray()
    while value >= 0x80:
        out.append((value & 0x7F) | 0x80)
        value >>= 7
    out.append(value)
    return bytes(out)


def _unvarint(buf: bytes, off: int) -> tuple[int, int]:
    value = shift = 0
    for i in range(5):
        byte = buf[off + i]
        value |= (byte & 0x7F) << shift
        if not byte & 0x80:
            if value > TASK_CODE_MAX or (i and not byte):
                raise DecodeError(f"task code varint {buf[off:off + i + 1].hex()} is out of range or padded")
            return value, off + i + 1
        shift += 7
    raise DecodeError("task code varint longer than 5 bytes")


def _vec(v) -> tuple[float, float, float]:
    return _NAN3 if v is None else (v[0], v[1], v[2])


def _opt(v: tuple[float, float, float]) -> tuple[float, float, float] | None:
    return None if math.isnan(v[0]) else v


def _descs(items) -> bytes:
    return b"".join(_DESC.pack(d.drone_id, d.stage, *d.pos_ned_m) for d in items)


def _undescs(buf: bytes, off: int, n: int) -> tuple[DescendantState, ...]:
    out = []
    for _ in range(n):
        i, stage, x, y, z = _DESC.unpack_from(buf, off)
        out.append(DescendantState(i, stage, (x, y, z)))
        off += _DESC.size
    return tuple(out)


def encode(msg) -> bytes:
    """The wire form of one message."""
    code = _TYPE_CODE[type(msg)]
    dst = NO_SUBJECT if code == 1 else msg.dst
    head = _HEADER.pack(code, msg.msg_id, msg.t_sent_s, msg.src, dst)
    if code == 1:
        return (head + _HB.pack(msg.stage, len(msg.successors))
                + struct.pack(f"<{len(msg.successors)}h", *msg.successors)
                + _VEC.pack(*msg.pos_ned_m) + _VEC.pack(*msg.vel_ned_m_s))
    if code == 2:
        data = msg.data.encode()
        return (head + _REPORT.pack(msg.stage, msg.complete, msg.total_count, msg.total_alive,
                                    *msg.pos_ned_m, *msg.vel_ned_m_s, *_vec(msg.discrepancy_ned_m), len(data))
                + data + _descs(msg.descendants))
    if code == 3:
        data = msg.data.encode()
        yaw = math.nan if msg.yaw_rad is None else msg.yaw_rad
        return (head + _TASK_HEAD.pack(msg.seq, msg.reliable) + _varint(check_task_code(msg.code))
                + _TASK_TAIL.pack(msg.stage, msg.floor, msg.incarnation, *_vec(msg.waypoint_ned_m), yaw,
                                  len(data)) + data)
    if code == 4:
        return head + _ACK.pack(msg.seq, msg.incarnation)
    return head + _COUNT.pack(len(msg.neighbours)) + _descs(msg.neighbours)


def decode(buf: bytes):
    """The message a frame holds; :class:`DecodeError` for anything malformed."""
    try:
        return _decode(buf)
    except (struct.error, UnicodeDecodeError, KeyError, IndexError) as exc:
        raise DecodeError(f"malformed swarm message ({len(buf)} bytes): {exc}") from None


def _decode(buf: bytes):
    code, msg_id, t_sent, src, dst = _HEADER.unpack_from(buf, 0)
    off = _HEADER.size
    if code == 1:
        stage, n = _HB.unpack_from(buf, off)
        off += _HB.size
        succ = struct.unpack_from(f"<{n}h", buf, off)
        off += 2 * n
        pos, vel = _VEC.unpack_from(buf, off), _VEC.unpack_from(buf, off + _VEC.size)
        _exact(buf, off + 2 * _VEC.size)
        return Heartbeat(msg_id, t_sent, src, stage, tuple(succ), pos, vel)
    if code == 2:
        f = _REPORT.unpack_from(buf, off)
        off += _REPORT.size
        data = buf[off:off + f[13]].decode()
        off += f[13]
        rest = len(buf) - off
        if rest % _DESC.size:
            raise DecodeError(f"report tail of {rest} bytes is not a list of descendants")
        return Report(msg_id, t_sent, src, dst, f[0], f[1], f[2], f[3], tuple(f[4:7]), tuple(f[7:10]),
                      _opt(tuple(f[10:13])), data, _undescs(buf, off, rest // _DESC.size))
    if code == 3:
        seq, reliable = _TASK_HEAD.unpack_from(buf, off)
        cmd, off = _unvarint(buf, off + _TASK_HEAD.size)
        stage, floor, inc, wn, we, wd, yaw, n = _TASK_TAIL.unpack_from(buf, off)
        off += _TASK_TAIL.size
        data = buf[off:off + n].decode()
        _exact(buf, off + n)
        return TaskCommand(msg_id, t_sent, src, dst, seq, reliable, cmd, _opt((wn, we, wd)),
                           None if math.isnan(yaw) else yaw, data, stage, floor, inc)
    if code == 4:
        seq, inc = _ACK.unpack_from(buf, off)
        _exact(buf, off + _ACK.size)
        return TaskAck(msg_id, t_sent, src, dst, seq, inc)
    if code == 5:
        (n,) = _COUNT.unpack_from(buf, off)
        off += _COUNT.size
        _exact(buf, off + n * _DESC.size)
        return ProxAlert(msg_id, t_sent, src, dst, _undescs(buf, off, n))
    raise DecodeError(f"unknown message type code {code}")


def _exact(buf: bytes, end: int) -> None:
    if len(buf) != end:
        raise DecodeError(f"frame of {len(buf)} bytes, expected {end}")
