"""The autopilot side of a mavsim vehicle's MAVLink link: streams, encoding and the UDP socket.

Speaks as PX4's API/offboard link does: HEARTBEAT (quadrotor, autopilot PX4, base_mode 29 + 128
when armed, PX4 custom modes), the default streams of PX4's onboard mode at their rates (in
simulation time), message intervals changed by MAV_CMD_SET_MESSAGE_INTERVAL, one-shot messages
sent on MAV_CMD_REQUEST_MESSAGE, and the UDP behaviour of PX4's link: it sends to its remote port
until someone talks to it, then answers that first address for good.
"""

from __future__ import annotations

import math
import socket
from collections.abc import Callable
from typing import NamedTuple

from pymavlink.dialects.v20 import common as mavlink

from swarmbox.hal.mavlink.codec import MSG, PREARM_CHECK_BIT
from swarmbox.hal.mavlink.frames import GeoFrame, deg_e7
from swarmbox.hal.mavlink.signing import keep_current, signing_timestamp
from swarmbox.hal.mavlink.statustext import split

Vec3 = tuple[float, float, float]
BASE_MODE = (mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED | mavlink.MAV_MODE_FLAG_STABILIZE_ENABLED
             | mavlink.MAV_MODE_FLAG_GUIDED_ENABLED | mavlink.MAV_MODE_FLAG_AUTO_ENABLED)   # 29
SENSORS = (mavlink.MAV_SYS_STATUS_SENSOR_3D_GYRO | mavlink.MAV_SYS_STATUS_SENSOR_3D_ACCEL
           | mavlink.MAV_SYS_STATUS_SENSOR_3D_MAG | mavlink.MAV_SYS_STATUS_SENSOR_ABSOLUTE_PRESSURE
           | mavlink.MAV_SYS_STATUS_SENSOR_GPS)
#: message -> default rate (Hz, simulation time) on PX4's onboard link; 0: only on request
DEFAULT_RATES_HZ = {"HEARTBEAT": 1.0, "SYS_STATUS": 5.0, "EXTENDED_SYS_STATE": 5.0,
                    "LOCAL_POSITION_NED": 30.0, "GLOBAL_POSITION_INT": 50.0, "GPS_RAW_INT": 10.0,
                    "ATTITUDE": 100.0, "VFR_HUD": 10.0, "HIL_STATE_QUATERNION": 0.0, "HOME_POSITION": 0.0,
                    "GPS_GLOBAL_ORIGIN": 0.0}
MTU_BYTES = 1400


class VehicleState(NamedTuple):
    """What the streams report at one instant (local frame: origin at home)."""

    t_s: float
    armed: bool
    custom_mode: int
    landed_state: int
    ready_to_arm: bool
    battery_frac: float
    pos_ned_m: Vec3
    vel_ned_m_s: Vec3
    yaw_rad: float
    gnss_ned_m: Vec3 | None
    gnss_time_s: float
    true_pos_ned_m: Vec3
    true_vel_ned_m_s: Vec3


class Streams:
    """Per-message intervals (simulation time); ``due`` lists the messages to send now."""

    def __init__(self, rates_hz: dict[str, float]) -> None:
        self._default = {MSG[name]: (1.0 / hz if hz > 0 else None) for name, hz in rates_hz.items()}
        self.interval_s = dict(self._default)
        self._next_s = dict.fromkeys(self._default, 0.0)

    def set_interval(self, msg_id: int, interval_us: float) -> bool:
        """MAV_CMD_SET_MESSAGE_INTERVAL: -1 stops, 0 restores the default; False if not streamable."""
        if msg_id not in self._default or msg_id == MSG["HEARTBEAT"] and interval_us < 0:
            return False
        if interval_us < 0:
            self.interval_s[msg_id] = None
        elif interval_us == 0:
            self.interval_s[msg_id] = self._default[msg_id]
        else:
            self.interval_s[msg_id] = interval_us / 1e6
        return True

    def streamable(self, msg_id: int) -> bool:
        return msg_id in self._default

    def due(self, t_s: float) -> list[int]:
        out = []
        for msg_id, interval in self.interval_s.items():
            if interval is None or t_s + 1e-9 < self._next_s[msg_id]:
                continue
            out.append(msg_id)
            nxt = self._next_s[msg_id] + interval
            self._next_s[msg_id] = nxt if nxt > t_s else t_s + interval
        return out


class VehicleEncoder:
    """Packs the autopilot's messages; positions are converted with ``home`` (the EKF origin)."""

    def __init__(self, system_id: int, home: GeoFrame, signing_key: bytes | None = None) -> None:
        self._mav = mavlink.MAVLink(None, srcSystem=system_id, srcComponent=1)
        self._text_id = 0
        if signing_key is not None:   # MAVLink 2 signing of everything the vehicle sends
            sign = self._mav.signing
            sign.secret_key, sign.link_id, sign.sign_outgoing = signing_key, 0, True
            sign.timestamp = signing_timestamp()
        self.home = home
        self._build: dict[int, Callable[[VehicleState], object]] = {
            MSG["HEARTBEAT"]: self._heartbeat, MSG["SYS_STATUS"]: self._sys_status,
            MSG["EXTENDED_SYS_STATE"]: lambda s: self._mav.extended_sys_state_encode(0, s.landed_state),
            MSG["LOCAL_POSITION_NED"]: lambda s: self._mav.local_position_ned_encode(
                _ms(s.t_s), *s.pos_ned_m, *s.vel_ned_m_s),
            MSG["GLOBAL_POSITION_INT"]: self._global_position, MSG["GPS_RAW_INT"]: self._gps_raw,
            MSG["ATTITUDE"]: lambda s: self._mav.attitude_encode(_ms(s.t_s), 0.0, 0.0, s.yaw_rad, 0, 0, 0),
            MSG["VFR_HUD"]: self._vfr_hud, MSG["HIL_STATE_QUATERNION"]: self._hil_state,
            MSG["HOME_POSITION"]: self._home_position, MSG["GPS_GLOBAL_ORIGIN"]: self._origin,
        }

    def encode(self, msg_id: int, state: VehicleState) -> bytes:
        return self._pack(self._build[msg_id](state))

    def command_ack(self, command: int, result: int, target: tuple[int, int]) -> bytes:
        return self._pack(self._mav.command_ack_encode(command, result, 0, 0, target[0], target[1]))

    def statustext(self, severity: int, text: str) -> list[bytes]:
        """One packet, or PX4-style chunks for a line longer than 50 bytes (hal/mavlink/statustext.py)."""
        self._text_id = self._text_id % 65535 + 1
        return [self._pack(self._mav.statustext_encode(severity, chunk.encode(), line_id, seq))
                for chunk, line_id, seq in split(text, self._text_id)]

    def _pack(self, msg: object) -> bytes:
        if self._mav.signing.sign_outgoing:
            keep_current(self._mav.signing)   # stamps follow the wall clock (a restarted link checks them)
        buf = msg.pack(self._mav)  # type: ignore[attr-defined]
        self._mav.seq = (self._mav.seq + 1) % 256
        return bytes(buf)

    def _heartbeat(self, s: VehicleState) -> object:
        base = BASE_MODE | (mavlink.MAV_MODE_FLAG_SAFETY_ARMED if s.armed else 0)
        status = mavlink.MAV_STATE_ACTIVE if s.armed else mavlink.MAV_STATE_STANDBY
        return self._mav.heartbeat_encode(mavlink.MAV_TYPE_QUADROTOR, mavlink.MAV_AUTOPILOT_PX4, base,
                                          s.custom_mode, status)

    def _sys_status(self, s: VehicleState) -> object:
        present = SENSORS | PREARM_CHECK_BIT
        health = SENSORS | (PREARM_CHECK_BIT if s.ready_to_arm else 0)
        pct = int(round(100 * s.battery_frac)) if math.isfinite(s.battery_frac) else -1
        millivolts = int(15200 + 16 * max(pct, 0))
        return self._mav.sys_status_encode(present, present, health, 100, millivolts, -1, pct,
                                           0, 0, 0, 0, 0, 0)

    def _global_position(self, s: VehicleState) -> object:
        lat, lon, alt = self.home.geodetic_of(s.pos_ned_m)
        vn, ve, vd = s.vel_ned_m_s
        hdg = int(round(math.degrees(s.yaw_rad) * 100)) % 36000
        rel_mm = int(-s.pos_ned_m[2] * 1e3)
        return self._mav.global_position_int_encode(_ms(s.t_s), deg_e7(lat), deg_e7(lon), int(alt * 1e3),
                                                    rel_mm, _cm(vn), _cm(ve), _cm(vd), hdg)

    def _gps_raw(self, s: VehicleState) -> object:
        if s.gnss_ned_m is None:
            return self._mav.gps_raw_int_encode(0, mavlink.GPS_FIX_TYPE_NO_FIX, 0, 0, 0, 65535, 65535, 0,
                                                65535, 0)
        lat, lon, alt = self.home.geodetic_of(s.gnss_ned_m)
        vn, ve, _ = s.true_vel_ned_m_s
        cog = int(round(math.degrees(math.atan2(ve, vn)) * 100)) % 36000
        return self._mav.gps_raw_int_encode(int(s.gnss_time_s * 1e6), mavlink.GPS_FIX_TYPE_3D_FIX,
                                            deg_e7(lat), deg_e7(lon), int(alt * 1e3), 70, 100,
                                            _cm(math.hypot(vn, ve)), cog, 12)

    def _vfr_hud(self, s: VehicleState) -> object:
        speed = math.hypot(s.vel_ned_m_s[0], s.vel_ned_m_s[1])
        heading = int(round(math.degrees(s.yaw_rad))) % 360
        alt = self.home.alt_m - s.pos_ned_m[2]
        return self._mav.vfr_hud_encode(speed, speed, heading, 50 if s.armed else 0, alt, -s.vel_ned_m_s[2])

    def _hil_state(self, s: VehicleState) -> object:
        lat, lon, alt = self.home.geodetic_of(s.true_pos_ned_m)
        half = s.yaw_rad / 2
        vn, ve, vd = s.true_vel_ned_m_s
        return self._mav.hil_state_quaternion_encode(
            int(s.t_s * 1e6), [math.cos(half), 0.0, 0.0, math.sin(half)], 0.0, 0.0, 0.0, deg_e7(lat),
            deg_e7(lon), int(alt * 1e3), _cm(vn), _cm(ve), _cm(vd), 0, 0, 0, 0, 0)

    def _home_position(self, s: VehicleState) -> object:
        h = self.home
        return self._mav.home_position_encode(deg_e7(h.lat_deg), deg_e7(h.lon_deg), int(h.alt_m * 1e3),
                                              0.0, 0.0, 0.0, [1.0, 0.0, 0.0, 0.0], 0.0, 0.0, 0.0)

    def _origin(self, s: VehicleState) -> object:
        h = self.home
        return self._mav.gps_global_origin_encode(deg_e7(h.lat_deg), deg_e7(h.lon_deg), int(h.alt_m * 1e3))


def _ms(t_s: float) -> int:
    return int(t_s * 1e3) & 0xFFFFFFFF


def _cm(v_m_s: float) -> int:
    return max(-32768, min(32767, int(round(v_m_s * 100))))


class AutopilotSocket:
    """PX4's UDP link: bound to ``local_port``; sends to 127.0.0.1:``remote_port`` until a packet
    arrives, then to that packet's sender for good. Outgoing packets are bundled up to the MTU.
    With ``radio_on`` False nothing is sent and everything received is dropped."""

    def __init__(self, local_port: int, remote_port: int, host: str = "127.0.0.1") -> None:
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.setblocking(False)
        self.sock.bind((host, local_port))
        self.local_port: int = self.sock.getsockname()[1]
        self.peer: tuple[str, int] = (host, remote_port)
        self.partner_known = False
        self.radio_on = True
        self._out: list[bytes] = []
        self._out_len = 0
        self.tx_bytes = self.rx_bytes = 0

    def receive(self, max_datagrams: int = 256) -> list[tuple[bytes, tuple[str, int]]]:
        out = []
        for _ in range(max_datagrams):
            try:
                data, addr = self.sock.recvfrom(65536)
            except (BlockingIOError, InterruptedError):
                break
            except (ConnectionRefusedError, ConnectionResetError):
                continue
            if self.radio_on:
                self.rx_bytes += len(data)
                out.append((data, addr))
        return out

    def adopt(self, addr: tuple[str, int]) -> None:
        """The first address that sends a valid packet becomes the partner (never changed after)."""
        if not self.partner_known:
            self.partner_known, self.peer = True, addr

    def queue(self, packet: bytes) -> None:
        if self._out_len + len(packet) > MTU_BYTES:
            self.flush()
        self._out.append(packet)
        self._out_len += len(packet)

    def flush(self) -> None:
        if not self._out:
            return
        data = b"".join(self._out)
        self._out.clear()
        self._out_len = 0
        if not self.radio_on:
            return
        try:
            self.sock.sendto(data, self.peer)
            self.tx_bytes += len(data)
        except (BlockingIOError, InterruptedError, ConnectionRefusedError):
            pass   # nobody listening yet, or the buffer is full: UDP drops, as PX4's link does

    def close(self) -> None:
        self.sock.close()
