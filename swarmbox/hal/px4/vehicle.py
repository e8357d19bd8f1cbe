"""One PX4 autopilot seen through its MAVLink link (the :class:`~swarmbox.hal.vehicle.Vehicle` of
the ``px4`` bridge).

Commands are COMMAND_LONGs with ack and retry (:class:`~swarmbox.hal.mavlink.link.CommandTracker`);
an accepted command updates the state at once, the next HEARTBEAT confirms it. Setpoints pass the
same safety monitor as the simulator's, are converted to the vehicle's local frame and streamed as
SET_POSITION_TARGET_LOCAL_NED: a new setpoint goes out at the next service, an unchanged one is
re-sent at ``setpoint_rate_hz``. OFFBOARD is requested only after setpoints have streamed for
``offboard_lead_s`` (PX4 refuses it otherwise). If the autopilot leaves OFFBOARD on its own (a
failsafe, a pilot), the bridge does not fight it: setpoints are ignored, with an event, until the
next explicit command.

Frames: every conversion goes through the vehicle's :class:`~swarmbox.hal.mavlink.frames.VehicleFrame`
(local NED origin at its home, as PX4's EKF origin at the spawn point; GNSS and ground truth through
the mission's geodetic origin).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

from swarmbox.api import Setpoint, SetpointVerdict, Telemetry
from swarmbox.hal.mavlink.codec import (
    CMD_ARM_DISARM,
    CMD_INJECT_FAILURE,
    CMD_LAND,
    CMD_REQUEST_MESSAGE,
    CMD_RTL,
    CMD_SET_MESSAGE_INTERVAL,
    CMD_SET_MODE,
    CMD_TAKEOFF,
    CUSTOM_MODE_FLAG,
    LANDED_ON_GROUND,
    MODE_HOLD,
    MODE_LAND,
    MODE_OFFBOARD,
    MODE_RTL,
    MODE_TAKEOFF,
    CommandAckMsg,
    GcsEncoder,
    GlobalPositionMsg,
    GnssMsg,
    GroundTruthMsg,
    HeartbeatMsg,
    LandedStateMsg,
    LocalPositionMsg,
    ParamValueMsg,
    StatusTextMsg,
    SysStatusMsg,
    flight_mode,
    mode_name,
    px4_main_sub,
)
from swarmbox.hal.mavlink.failure import FailureInjector, FailureRequest
from swarmbox.hal.mavlink.frames import VehicleFrame
from swarmbox.hal.mavlink.link import Command, CommandTracker, VehicleLink
from swarmbox.hal.mavlink.paramset import ParamSetter
from swarmbox.hal.mavlink.statustext import StatusTexts
from swarmbox.hal.px4.linkreport import LinkReport
from swarmbox.hal.px4.params import LinkConfig
from swarmbox.hal.px4.streams import Streams
from swarmbox.hal.safety import HeldSetpoint, SafetyLimits, check_setpoint, safety_event

Vec3 = tuple[float, float, float]
#: emit(kind, name, data): an event of this vehicle, stamped by the backend.
Emit = Callable[[str, str, dict[str, Any]], None]
_NAN = math.nan
_ZERO3 = (0.0, 0.0, 0.0)
STATE_GRACE_S = 0.3           # a HEARTBEAT this soon after an accepted command may predate it
_NOT_CRITICAL = frozenset((CMD_SET_MESSAGE_INTERVAL, CMD_REQUEST_MESSAGE, CMD_INJECT_FAILURE))


class Px4Vehicle:
    """A PX4 autopilot over MAVLink (implements :class:`swarmbox.hal.vehicle.Vehicle`)."""

    def __init__(self, drone_id: int, link: VehicleLink, cfg: LinkConfig, frame: VehicleFrame,
                 limits: SafetyLimits, emit: Emit) -> None:
        self.drone_id, self.home_ned_m = drone_id, frame.home_ned_m
        self._link, self._cfg, self._frame, self._limits, self._emit = link, cfg, frame, limits, emit
        self._target = (link.system_id, cfg.component_id)
        self._enc = GcsEncoder(signing_key=cfg.signing_key, link_id=drone_id & 0xFF)
        self._cmds = CommandTracker(self._send_command, self._command_report, cfg.command_timeout_s,
                                    cfg.command_retries, self._command_timed_out, self._command_failed)
        self.failure = ""                          # the latest flight command the autopilot refused
        self._params = ParamSetter(lambda name, value, kind: self._link.send(self._enc.param_set(
            self._target, name, value, kind)), cfg.command_timeout_s, cfg.command_retries)
        self.failures = FailureInjector(
            lambda cmd: self._cmds.submit(cmd, self._now), emit,
            lambda name, value, done: self._params.set(name, value, self._now, done),
            gnss_via_param=cfg.gnss_failure == "sim_param")
        self._on_regain: Command | None = None      # the last command lost with the link
        self._now = 0.0
        self.connected = self.link_lost = False
        self._hb_s = self._gcs_hb_s = self._state_set_s = -math.inf
        self._armed, self._mode, self._landed_state, self._ready = False, MODE_HOLD, 0, False
        self._battery, self._yaw, self._pos_s = _NAN, 0.0, 0.0
        self._local: Vec3 | None = None
        self._vel: Vec3 = _ZERO3
        self._gnss: Vec3 | None = None
        self._true: Vec3 | None = None
        self._gnss_seq, self._gnss_usec = 0, -1
        self._home_alt_m: float | None = None
        self._tel: Telemetry | None = None
        self._sp: Setpoint | None = None          # streamed setpoint, vehicle-local frame
        self._sp_new, self._sp_sent_s, self._offboard_try_s = False, -math.inf, -math.inf
        self._held = HeldSetpoint()                # the velocity/acceleration asked for, judged again
        self._stream_since_s: float | None = None
        self._blocked = ""                         # why setpoints are not followed (autopilot's choice)
        self._noted: set[tuple[str, str]] = set()
        self._streams = Streams(cfg, link.decoder, self._submit)
        self._checks_s, self._odd_acks = 0.0, set()
        self._texts = StatusTexts(self._emit)
        self._link_report = LinkReport(link, emit, cfg.stats_every_s)
        self.clock_pairs: list[tuple[float, float]] = []   # (vehicle boot s, our clock - boot) minima
        self._handlers: dict[type, Callable[[Any], None]] = {
            LocalPositionMsg: self._on_local, GlobalPositionMsg: self._on_global, GnssMsg: self._on_gnss,
            SysStatusMsg: self._on_sys_status, LandedStateMsg: self._on_landed, CommandAckMsg: self._on_ack,
            StatusTextMsg: self._on_statustext, GroundTruthMsg: self._on_truth,
            ParamValueMsg: self._params.on_value}

    @property
    def system_id(self) -> int:
        return self._link.system_id

    @property
    def has_position(self) -> bool:
        return self.connected and self._local is not None

    # ---- Vehicle protocol ---------------------------------------------------------------------
    def telemetry(self) -> Telemetry:
        return self._tel if self._tel is not None else self._build_telemetry()

    def arm(self) -> None:
        if self._armed:
            return
        self._blocked = ""
        self._submit(CMD_ARM_DISARM, (1.0,), lambda: self._set_armed(True))

    def disarm(self) -> None:
        if self._armed:
            self._submit(CMD_ARM_DISARM, (0.0,), lambda: self._set_armed(False))

    def takeoff(self, alt_m: float) -> None:
        if not (isinstance(alt_m, int | float) and math.isfinite(alt_m) and alt_m > 0):
            self._deny("takeoff", f"bad altitude {alt_m!r}")
            return
        self._stop_offboard()
        home_amsl = self._frame.home_alt_m if self._home_alt_m is None else self._home_alt_m
        amsl = home_amsl + min(float(alt_m), self._limits.max_alt_m)
        self._submit(CMD_TAKEOFF, (_NAN, 0.0, 0.0, _NAN, _NAN, _NAN, amsl),
                     lambda: self._set_mode(MODE_TAKEOFF))

    def setpoint(self, sp: Setpoint) -> SetpointVerdict:
        verdict = check_setpoint(sp, self.telemetry(), self._limits)
        if verdict.action != "ok":
            self._emit("safety", "setpoint_" + verdict.action, safety_event(sp, verdict, self.telemetry()))
        safe = verdict.setpoint
        result = SetpointVerdict(verdict.action, verdict.reason, safe)
        if safe is None:
            return result
        if not self._armed or self.link_lost or self._blocked:
            reason = "disarmed" if not self._armed else ("link lost" if self.link_lost else self._blocked)
            self._deny("setpoint", reason)
            return SetpointVerdict("ignored", reason)
        self._held.asked(sp)
        self._fly(safe)
        if self._stream_since_s is None:
            self._stream_since_s = self._now
        return result

    def _fly(self, safe: Setpoint) -> None:
        local = self._frame.setpoint_to_local(safe)
        if local != self._sp:
            self._sp, self._sp_new = local, True

    def _judge_held(self) -> None:
        """A velocity or acceleration no longer sent is still streamed: keep it inside the envelope."""
        held = self._held.stale()
        if held is None or self._sp is None:
            return
        verdict = check_setpoint(held, self.telemetry(), self._limits)
        if verdict.action != "ok":
            self._emit("safety", "setpoint_" + verdict.action, safety_event(held, verdict, self.telemetry()))
        if verdict.setpoint is not None:
            self._fly(verdict.setpoint)

    def land(self) -> None:
        self._stop_offboard()
        self._submit(CMD_LAND, (0.0, 0.0, 0.0, _NAN, _NAN, _NAN, _NAN), lambda: self._set_mode(MODE_LAND))

    def return_to_launch(self) -> None:
        self._stop_offboard()
        self._submit(CMD_RTL, (), lambda: self._set_mode(MODE_RTL))

    def hold(self) -> None:
        self._stop_offboard()
        main, sub = px4_main_sub(MODE_HOLD)
        self._submit(CMD_SET_MODE, (CUSTOM_MODE_FLAG, main, sub), lambda: self._set_mode(MODE_HOLD))

    def inject_failure(self, unit: str, kind: str, instance: int = 0) -> None:
        """Ask the autopilot to fail ``unit`` (``kind="ok"`` ends it): MAV_CMD_INJECT_FAILURE."""
        self.failures.inject(FailureRequest(unit, kind, instance))

    # ---- servicing (called by the backend every step) -----------------------------------------
    def service(self, now_s: float) -> None:
        """Read the link, run the watchdog, stream setpoints, retry commands."""
        self._now = now_s
        handlers = self._handlers
        for comp, value in self._link.poll():
            if type(value) is HeartbeatMsg:
                self._on_heartbeat(comp, value)
            else:
                handler = handlers.get(type(value))
                if handler is not None:
                    handler(value)
        if now_s - self._gcs_hb_s >= 1.0 / self._cfg.heartbeat_rate_hz:
            self._gcs_hb_s = now_s
            self._link.send(self._enc.heartbeat())
        if not self.connected:
            if now_s - self._checks_s >= 1.0:   # why not: packets from other system ids?
                self._checks_s = now_s
                self._link_report(now_s, connected=False)
            return
        if not self.link_lost and now_s - self._hb_s > self._cfg.link_timeout_s:
            self._lose_link()
        self._judge_held()
        self._stream()
        self._cmds.service(now_s)
        self._params.service(now_s)
        if now_s - self._checks_s >= 1.0:
            self._checks_s = now_s
            self._texts.service(now_s)
            self._streams.silence_unrequested(now_s)
            self._link_report(now_s, connected=True)

    def _stream(self) -> None:
        sp, now = self._sp, self._now
        if sp is None or self.link_lost:
            return
        if self._sp_new or now - self._sp_sent_s >= 1.0 / self._cfg.setpoint_rate_hz:
            self._link.send(self._enc.setpoint(self._target, int(now * 1e3), sp))
            self._sp_sent_s, self._sp_new = now, False
        if (self._mode != MODE_OFFBOARD and self._armed and self._stream_since_s is not None
                and now - self._stream_since_s >= self._cfg.offboard_lead_s
                and now - self._offboard_try_s >= 1.0 and not self._cmds.busy(CMD_SET_MODE)):
            self._offboard_try_s = now
            main, sub = px4_main_sub(MODE_OFFBOARD)
            self._submit(CMD_SET_MODE, (CUSTOM_MODE_FLAG, main, sub), lambda: self._set_mode(MODE_OFFBOARD))

    # ---- incoming -----------------------------------------------------------------------------
    def _on_heartbeat(self, comp: int, hb: HeartbeatMsg) -> None:
        if comp != self._target[1] or not hb.autopilot:
            return
        if not self.connected:
            self.connected = True
            self._emit("link", "connected", {"system_id": self.system_id, "mode": mode_name(hb.custom_mode)})
            self._streams.configure()
        elif self.link_lost:
            self.link_lost = False
            self._emit("link", "regained", {"silent_s": round(self._now - self._hb_s, 3)})
            self._streams.configure()
            if self._on_regain is not None:   # e.g. the failsafe's return-to-launch: send it now
                cmd, self._on_regain = self._on_regain, None
                self._submit(cmd.command, cmd.params, cmd.on_accepted)
        self._hb_s = self._now
        self._tel = None
        if self._now - self._state_set_s < STATE_GRACE_S:
            return   # may have been sent before the command we just saw accepted
        if hb.armed != self._armed:
            self._set_armed(hb.armed)
        if hb.custom_mode != self._mode:
            if self._sp is not None and self._mode == MODE_OFFBOARD:
                self._took_over(mode_name(hb.custom_mode))
            self._set_mode(hb.custom_mode, confirmed=True)

    def _on_local(self, m: LocalPositionMsg) -> None:
        self._local, self._vel, self._pos_s, self._tel = m.pos_ned_m, m.vel_ned_m_s, self._now, None
        offset = self._now - m.time_boot_s
        pairs = self.clock_pairs
        if pairs and int(pairs[-1][0]) == int(m.time_boot_s):
            if offset < pairs[-1][1]:
                pairs[-1] = (m.time_boot_s, offset)
        else:
            pairs.append((m.time_boot_s, offset))

    def _on_global(self, m: GlobalPositionMsg) -> None:
        if m.yaw_rad is not None:
            self._yaw = m.yaw_rad
        self._home_alt_m = m.alt_m - m.rel_alt_m
        self._tel = None

    def _on_gnss(self, m: GnssMsg) -> None:
        if m.fix_type >= 3 and m.time_usec != self._gnss_usec:
            self._gnss_usec = m.time_usec
            self._gnss = self._frame.geodetic_to_mission(m.lat_deg, m.lon_deg, m.alt_m)
            self._gnss_seq += 1
            self._tel = None

    def _on_sys_status(self, m: SysStatusMsg) -> None:
        self._ready, self._battery, self._tel = m.ready_to_arm, m.battery_frac, None

    def _on_landed(self, m: LandedStateMsg) -> None:
        self._landed_state, self._tel = m.landed_state, None

    def _on_ack(self, m: CommandAckMsg) -> None:
        if m.target_system in (0, self._enc.system_id):
            self._cmds.on_ack(m, self._now)

    def _on_statustext(self, m: StatusTextMsg) -> None:
        self._texts.on_chunk(m.severity, m.text, m.line_id, m.chunk_seq, self._now)

    def _took_over(self, mode: str) -> None:
        """The autopilot left OFFBOARD on its own (failsafe, pilot): the drone aborts, and the reason names
        the autopilot's alert if one came just before (PX4 says "Failsafe activated")."""
        self._stop_offboard()
        self._blocked = f"autopilot switched to {mode}"
        self._emit("command", "offboard_lost", {"mode": mode})
        alert = self._texts.recent_alert(self._now)
        self.failure = f"autopilot took over: left OFFBOARD for {mode}" + (f" ({alert})" if alert else "")
        self._emit("failure", "autopilot_took_over", {"mode": mode, "alert": alert, "reason": self.failure})

    def _on_truth(self, m: GroundTruthMsg) -> None:
        self._true, self._tel = self._frame.geodetic_to_mission(m.lat_deg, m.lon_deg, m.alt_m), None

    # ---- helpers ------------------------------------------------------------------------------
    def _build_telemetry(self) -> Telemetry:
        pos = self.home_ned_m if self._local is None else self._frame.to_mission(self._local)
        landed = self._landed_state == LANDED_ON_GROUND if self._landed_state else not self._armed
        self._tel = Telemetry(self._pos_s, pos, self._vel, self._yaw, self._gnss, self._gnss_seq, self._armed,
                              landed, flight_mode(self._mode, self._armed, landed), self._battery,
                              self._ready and not self.link_lost, self._true, link_ok=not self.link_lost)
        return self._tel

    def _submit(self, command: int, params: tuple[float, ...], on_accepted: Callable[[], None] | None = None,
                quiet: bool = False) -> None:
        if not quiet and command != CMD_SET_MESSAGE_INTERVAL:
            self._on_regain = None    # a newer intent replaces one lost with the link
        self._cmds.submit(Command(command, params, quiet, on_accepted), self._now)

    def _command_timed_out(self, cmd: Command) -> None:
        if self.link_lost and not cmd.quiet and cmd.command != CMD_SET_MESSAGE_INTERVAL:
            self._on_regain = cmd

    def _command_failed(self, cmd: Command, result: str) -> None:
        """A flight command refused to the end of its retries: a ``failure`` event (the drone aborts).
        Not a disarm refused in the air, nor a command lost with the link (resent when it returns)."""
        if (cmd.command in _NOT_CRITICAL or (cmd.command == CMD_ARM_DISARM and cmd.params[:1] == (0.0,))
                or (self.link_lost and result == "no ack")):
            if cmd.command == CMD_INJECT_FAILURE:
                self.failures.on_failed(cmd, result)
            return
        self.failure = f"autopilot refused {cmd.name} ({result} after {cmd.tries} tries)"
        self._emit("failure", "command_failed", {"command": cmd.name, "result": result, "tries": cmd.tries,
                                                 "reason": self.failure})

    def _send_command(self, command: int, params: tuple[float, ...], confirmation: int) -> bool:
        return self._link.send(self._enc.command(self._target, command, params, confirmation))

    def _command_report(self, name: str, data: dict[str, Any]) -> None:
        if name != "unexpected_ack":
            self._emit("command", name, data)
        elif data["command"] not in self._odd_acks:
            self._odd_acks.add(data["command"])
            self._emit("link", name, data)

    def _set_mode(self, mode: int, confirmed: bool = False) -> None:
        if mode != self._mode:
            self._noted.clear()
        self._mode, self._tel = mode, None
        if not confirmed:
            self._state_set_s = self._now

    def _set_armed(self, armed: bool) -> None:
        self._armed, self._tel = armed, None
        self._noted.clear()
        self._state_set_s = self._now
        if not armed:
            self._stop_offboard()

    def _stop_offboard(self) -> None:
        self._sp, self._stream_since_s, self._blocked = None, None, ""
        self._held.asked(None)

    def _deny(self, cmd: str, reason: str) -> None:
        if (cmd, reason) not in self._noted:
            self._noted.add((cmd, reason))
            name = "setpoint_ignored" if cmd == "setpoint" else cmd + "_denied"
            self._emit("command", name, {"reason": reason})

    def _lose_link(self) -> None:
        self.link_lost, self._tel = True, None
        self._emit("link", "lost", {"silent_s": round(self._now - self._hb_s, 3),
                                    "mode": mode_name(self._mode), "armed": self._armed})
