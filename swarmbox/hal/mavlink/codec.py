"""MAVLink <-> SwarmBox: the one module that knows MAVLink's messages, units and PX4's modes.

Everything that crosses a MAVLink link is converted here, in both directions:

- **framing**: a UDP datagram is split into MAVLink 1/2 packets by their headers, so packets the
  caller does not want are skipped without being decoded (a Python process decodes a few thousand
  packets a second; a PX4 instance streams about 400);
- **decoding** into small named tuples with SI units in the names (``LocalPositionMsg`` ...);
- **encoding** of what a ground station sends (:class:`GcsEncoder`): heartbeats, COMMAND_LONG and
  SET_POSITION_TARGET_LOCAL_NED with the type mask of a :class:`~swarmbox.api.Setpoint`;
- **PX4 custom modes** <-> :class:`~swarmbox.api.FlightMode` (with the message and command identifiers
  and the setpoint type masks, in :mod:`swarmbox.hal.mavlink.ids`; every name is re-exported here).

Positions and frames (geodetic, vehicle-local, mission) are :mod:`swarmbox.hal.mavlink.frames`.

The vehicle side (what an autopilot sends) is encoded by :mod:`swarmbox.hal.mavsim.link` with the
same constants.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator
from typing import Any, NamedTuple

from pymavlink.dialects.v20 import common as mavlink

from swarmbox.api import Setpoint, SetpointKind
from swarmbox.hal.mavlink.ids import *  # noqa: F403 -- re-exported: callers read every MAVLink name as codec.X
from swarmbox.hal.mavlink.ids import (
    ARMED_FLAG,
    FRAME_LOCAL_NED,
    MSG,
    PREARM_CHECK_BIT,
    setpoint_of_target,
    type_mask,
)
from swarmbox.hal.mavlink.paramset import param_from_wire, param_to_wire
from swarmbox.hal.mavlink.signing import keep_current, signing_timestamp

Vec3 = tuple[float, float, float]
MAVError = mavlink.MAVError


# ---- decoded messages (SI units) ----------------------------------------------------------------
class HeartbeatMsg(NamedTuple):
    armed: bool
    custom_mode: int
    autopilot: bool          # sent by an autopilot (not a ground station or a companion)


class LocalPositionMsg(NamedTuple):
    time_boot_s: float
    pos_ned_m: Vec3
    vel_ned_m_s: Vec3


class GlobalPositionMsg(NamedTuple):
    time_boot_s: float
    lat_deg: float
    lon_deg: float
    alt_m: float             # AMSL
    rel_alt_m: float         # above home
    yaw_rad: float | None


class GnssMsg(NamedTuple):
    time_usec: int
    fix_type: int
    lat_deg: float
    lon_deg: float
    alt_m: float


class SysStatusMsg(NamedTuple):
    ready_to_arm: bool
    battery_frac: float      # NaN: unknown


class LandedStateMsg(NamedTuple):
    landed_state: int


class CommandAckMsg(NamedTuple):
    command: int
    result: int
    target_system: int


class StatusTextMsg(NamedTuple):
    severity: int
    text: str
    line_id: int = 0         # non-zero: one chunk of a longer line (hal/mavlink/statustext.py)
    chunk_seq: int = 0


class GroundTruthMsg(NamedTuple):
    lat_deg: float
    lon_deg: float
    alt_m: float


class ParamValueMsg(NamedTuple):
    name: str
    value: float             # PX4's bytewise encoding undone: an INT32 parameter's integer value
    param_type: int


class CommandLongMsg(NamedTuple):
    target_system: int
    target_component: int
    command: int
    confirmation: int
    params: tuple[float, ...]


class SetpointTargetMsg(NamedTuple):
    target_system: int
    frame: int
    setpoint: Setpoint | None   # in the vehicle's local frame


def _heartbeat(m: Any) -> HeartbeatMsg:
    autopilot = m.autopilot != mavlink.MAV_AUTOPILOT_INVALID and m.type != mavlink.MAV_TYPE_GCS
    return HeartbeatMsg(bool(m.base_mode & ARMED_FLAG), int(m.custom_mode), autopilot)


def _local(m: Any) -> LocalPositionMsg:
    return LocalPositionMsg(m.time_boot_ms / 1e3, (m.x, m.y, m.z), (m.vx, m.vy, m.vz))


def _global(m: Any) -> GlobalPositionMsg:
    yaw = None if m.hdg == 65535 else math.remainder(math.radians(m.hdg / 100.0), 2 * math.pi)
    return GlobalPositionMsg(m.time_boot_ms / 1e3, m.lat / 1e7, m.lon / 1e7, m.alt / 1e3,
                             m.relative_alt / 1e3, yaw)


def _gnss(m: Any) -> GnssMsg:
    return GnssMsg(int(m.time_usec), int(m.fix_type), m.lat / 1e7, m.lon / 1e7, m.alt / 1e3)


def _sys_status(m: Any) -> SysStatusMsg:
    frac = m.battery_remaining / 100.0 if m.battery_remaining >= 0 else math.nan
    return SysStatusMsg(bool(m.onboard_control_sensors_health & PREARM_CHECK_BIT), frac)


def _statustext(m: Any) -> StatusTextMsg:
    text = m.text.decode("utf-8", "replace") if isinstance(m.text, bytes) else str(m.text)
    return StatusTextMsg(int(m.severity), text, int(getattr(m, "id", 0)), int(getattr(m, "chunk_seq", 0)))


def _setpoint(m: Any) -> SetpointTargetMsg:
    sp = setpoint_of_target(m.type_mask, (m.x, m.y, m.z), (m.vx, m.vy, m.vz), (m.afx, m.afy, m.afz), m.yaw)
    return SetpointTargetMsg(m.target_system, m.coordinate_frame, sp)


DECODERS: dict[int, Callable[[Any], Any]] = {
    MSG["HEARTBEAT"]: _heartbeat,
    MSG["LOCAL_POSITION_NED"]: _local,
    MSG["GLOBAL_POSITION_INT"]: _global,
    MSG["GPS_RAW_INT"]: _gnss,
    MSG["SYS_STATUS"]: _sys_status,
    MSG["EXTENDED_SYS_STATE"]: lambda m: LandedStateMsg(int(m.landed_state)),
    MSG["COMMAND_ACK"]: lambda m: CommandAckMsg(int(m.command), int(m.result), int(m.target_system)),
    MSG["STATUSTEXT"]: _statustext,
    MSG["HIL_STATE_QUATERNION"]: lambda m: GroundTruthMsg(m.lat / 1e7, m.lon / 1e7, m.alt / 1e3),
    MSG["COMMAND_LONG"]: lambda m: CommandLongMsg(
        m.target_system, m.target_component, m.command, m.confirmation,
        (m.param1, m.param2, m.param3, m.param4, m.param5, m.param6, m.param7)),
    MSG["SET_POSITION_TARGET_LOCAL_NED"]: _setpoint,
    MSG["PARAM_VALUE"]: lambda m: ParamValueMsg(str(m.param_id), param_from_wire(m.param_value, m.param_type),
                                                int(m.param_type)),
}



# ---- framing and decoding -----------------------------------------------------------------------
class Packet(NamedTuple):
    system_id: int
    component_id: int
    msg_id: int
    start: int
    end: int


def iter_packets(data: bytes) -> Iterator[Packet | int]:
    """Split a datagram into MAVLink packets by their headers (no CRC check).

    Yields a :class:`Packet` per framed packet and an ``int`` (a count of bytes) for every run of
    bytes that is not a packet: garbage, or a truncated packet at the end.
    """
    i, size = 0, len(data)
    while i < size:
        magic = data[i]
        if magic == 0xFD and i + 10 <= size:
            end = i + 12 + data[i + 1] + (13 if data[i + 2] & 1 else 0)
            msg_id = data[i + 7] | data[i + 8] << 8 | data[i + 9] << 16
            sysid, compid = data[i + 5], data[i + 6]
        elif magic == 0xFE and i + 6 <= size:
            end = i + 8 + data[i + 1]
            msg_id, sysid, compid = data[i + 5], data[i + 3], data[i + 4]
        else:
            nxt = _next_magic(data, i + 1)
            yield nxt - i
            i = nxt
            continue
        if end > size:
            yield size - i
            return
        yield Packet(sysid, compid, msg_id, i, end)
        i = end


def _next_magic(data: bytes, start: int) -> int:
    hits = [j for j in (data.find(b"\xfd", start), data.find(b"\xfe", start)) if j >= 0]
    return min(hits) if hits else len(data)


class Decoder:
    """Decodes the wanted message ids of datagrams into the named tuples above.

    Counters: ``packets`` framed, ``decoded``, ``skipped`` (not wanted, never decoded; per message
    id in ``skipped_ids``), ``garbage_bytes`` and ``bad_packets`` (framed, but the CRC or length
    was wrong, or unsigned / wrongly signed while a ``signing_key`` is set: ``signature_rejected``).
    """

    def __init__(self, wanted: set[int] | frozenset[int], signing_key: bytes | None = None) -> None:
        self.wanted = set(wanted)
        self._mav = mavlink.MAVLink(None)
        #: pymavlink's per-stream signing timestamps (None: signing off)
        self._stamps: dict[Any, int] | None = None
        if signing_key is not None:
            self._mav.signing.secret_key = signing_key   # pymavlink then rejects unsigned packets
            self._stamps = self._mav.signing.stream_timestamps
            keep_current(self._mav.signing)   # a new stream stamped > 1 min before now is refused
        self.packets = self.decoded = self.skipped = self.bad_packets = self.garbage_bytes = 0
        self.signature_rejected = 0
        self.skipped_ids: dict[int, int] = {}

    def decode(self, data: bytes) -> Iterator[tuple[Packet, Any]]:
        """Yield ``(packet, value)`` for every wanted, valid packet of ``data``."""
        wanted, mav = self.wanted, self._mav
        if self._stamps is not None:
            keep_current(mav.signing)
        for item in iter_packets(data):
            if isinstance(item, int):
                self.garbage_bytes += item
                continue
            self.packets += 1
            if item.msg_id not in wanted:
                self.skipped += 1
                self.skipped_ids[item.msg_id] = self.skipped_ids.get(item.msg_id, 0) + 1
                continue
            stamps = self._stamps
            before = dict(stamps) if stamps is not None else None
            try:
                msg = mav.decode(bytearray(data[item.start:item.end]))
                value = DECODERS[item.msg_id](msg)
            except MAVError as exc:
                self.bad_packets += 1
                if str(exc) == "Invalid signature":
                    self.signature_rejected += 1
                    if stamps is not None:
                        # pymavlink records a new stream's timestamp before it checks the signature, so
                        # one packet with a wrong key and a later timestamp would make every later packet
                        # of the real sender look like a replay: forget what a rejected packet recorded
                        stamps.clear()
                        stamps.update(before)
                continue
            except (KeyError, ValueError, TypeError, AttributeError):
                self.bad_packets += 1
                continue
            self.decoded += 1
            yield item, value


# ---- ground-station side encoding ---------------------------------------------------------------
_NAN = float("nan")


class GcsEncoder:
    """Packs what a ground station or companion computer sends to an autopilot."""

    def __init__(self, system_id: int = 255, component_id: int = 190, signing_key: bytes | None = None,
                 link_id: int = 0) -> None:
        self.system_id = system_id
        self._mav = mavlink.MAVLink(None, srcSystem=system_id, srcComponent=component_id)
        if signing_key is not None:
            sign = self._mav.signing
            sign.secret_key, sign.link_id, sign.sign_outgoing = signing_key, link_id, True
            sign.timestamp = signing_timestamp()

    def _pack(self, msg: Any) -> bytes:
        if self._mav.signing.sign_outgoing:
            keep_current(self._mav.signing)
        buf = msg.pack(self._mav)
        self._mav.seq = (self._mav.seq + 1) % 256
        return bytes(buf)

    def heartbeat(self) -> bytes:
        return self._pack(self._mav.heartbeat_encode(mavlink.MAV_TYPE_GCS, mavlink.MAV_AUTOPILOT_INVALID,
                                                     0, 0, mavlink.MAV_STATE_ACTIVE))

    def command(self, target: tuple[int, int], command: int, params: tuple[float, ...],
                confirmation: int = 0) -> bytes:
        p = (tuple(float(x) for x in params) + (0.0,) * 7)[:7]
        msg = self._mav.command_long_encode(target[0], target[1], command, confirmation & 0xFF, *p)
        return self._pack(msg)

    def param_set(self, target: tuple[int, int], name: str, value: float, param_type: int) -> bytes:
        return self._pack(self._mav.param_set_encode(target[0], target[1], name.encode(),
                                                     param_to_wire(value, param_type), param_type))

    def setpoint(self, target: tuple[int, int], time_boot_ms: int, sp: Setpoint) -> bytes:
        """SET_POSITION_TARGET_LOCAL_NED for ``sp`` (already in the vehicle's local frame)."""
        zero = (0.0, 0.0, 0.0)
        pos = sp.ned if sp.kind is SetpointKind.POSITION else zero
        vel = sp.ned if sp.kind is SetpointKind.VELOCITY else zero
        acc = sp.ned if sp.kind is SetpointKind.ACCELERATION else zero
        yaw = _NAN if sp.yaw_rad is None else sp.yaw_rad
        return self._pack(self._mav.set_position_target_local_ned_encode(
            time_boot_ms & 0xFFFFFFFF, target[0], target[1], FRAME_LOCAL_NED, type_mask(sp),
            *pos, *vel, *acc, yaw, 0.0))
