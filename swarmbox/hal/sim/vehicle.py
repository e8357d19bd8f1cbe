"""One simulated vehicle's autopilot: commands, flight modes and the automatic-mode supervisor.

The numeric state lives in the fleet's arrays; this class holds the discrete state PX4's commander
would (armed, mode, RTL phase, timers) and turns commands into controller targets. Commands take
effect at the next ``step``.

A vehicle sees its fleet only through :class:`SimFleet` (what one vehicle may ask of the fleet it
flies in), so this module depends on the fleet's interface, not on
:class:`swarmbox.hal.sim.backend.SimBackend`, which builds the vehicles and implements that interface.
"""

from __future__ import annotations

import math
from typing import Any, Protocol

from swarmbox.api import FlightMode, Setpoint, SetpointKind, SetpointVerdict, Telemetry
from swarmbox.hal.safety import HeldSetpoint, SafetyLimits, check_setpoint, near_boundary, safety_event
from swarmbox.hal.sim.control import CascadedController
from swarmbox.hal.sim.params import GRAVITY_M_S2, SimParams

Vec3 = tuple[float, float, float]
_AUTO = (FlightMode.TAKEOFF, FlightMode.LAND, FlightMode.RTL)
_POSITION = SetpointKind.POSITION


class SimFleet(Protocol):
    """What a :class:`SimVehicle` asks of the fleet it flies in (one vehicle = index ``i``)."""

    @property
    def t_s(self) -> float:
        """The fleet's simulated time (s)."""
        ...

    def telemetry_of(self, i: int) -> Telemetry:
        """Vehicle ``i``'s live telemetry."""
        ...

    def estimate_ned(self, i: int) -> Vec3:
        """Vehicle ``i``'s estimated position (the one its controller flies on)."""
        ...

    def speed_m_s(self, i: int) -> float:
        """Vehicle ``i``'s true 3-D speed."""
        ...

    def on_ground(self, i: int) -> bool:
        """Whether vehicle ``i`` rests on the ground."""
        ...

    def arm_blocker(self, i: int) -> str:
        """Why vehicle ``i`` cannot arm now ("" if it can)."""
        ...

    def supervise(self, i: int) -> None:
        """Call ``supervise`` on vehicle ``i`` at every step from the next one on, until it returns False."""
        ...

    def emit(self, i: int, kind: str, name: str, data: dict[str, Any]) -> None:
        """Record a vehicle event (``kind``/``name`` as :class:`swarmbox.hal.vehicle.VehicleEvent`)."""
        ...

    def watch(self, i: int, on: bool) -> None:
        """Have vehicle ``i``'s held velocity or acceleration judged near the envelope at every step
        (``judge_held``), or no longer."""
        ...


class SimVehicle:
    """A simulated PX4-like autopilot (implements :class:`swarmbox.hal.vehicle.Vehicle`).

    Modes: IDLE (on the ground, disarmed or armed and waiting), OFFBOARD (``setpoint``), TAKEOFF
    (climb at MPC_TKO_SPEED, then HOLD), HOLD (brake to a stop, then hold that point), LAND
    (descend at MPC_LAND_SPEED, disarm on the ground), RTL (climb to the return altitude, fly home,
    land, disarm). A crashed vehicle ignores every command and its telemetry is frozen.
    """

    def __init__(self, fleet: SimFleet, drone_id: int, home_ned_m: Vec3, *, ctrl: CascadedController,
                 params: SimParams, limits: SafetyLimits) -> None:
        self._fleet = fleet
        self._ctrl, self._p, self._limits = ctrl, params, limits
        self.drone_id = drone_id
        self.home_ned_m: Vec3 = home_ned_m
        self.mode = FlightMode.IDLE
        self.armed = False
        self.frozen: Telemetry | None = None   # set when the vehicle crashes
        self._arm_t_s = 0.0
        self._been_airborne = False
        self._rtl_phase = ""
        self._ground_since_s: float | None = None
        self._takeoff_d_m = 0.0
        self._braking = False
        self._last_sp: Setpoint | None = None   # the setpoint being flown in OFFBOARD
        self._last_ok: Setpoint | None = None   # ... when the safety check passed it unchanged
        self._ok_verdict = SetpointVerdict("ok")   # the verdict then
        self._noted: set[tuple[str, str]] = set()   # denials already reported in this mode
        self._held = HeldSetpoint()   # the velocity/acceleration asked for, judged again near the envelope
        self._watched = False         # ... by the fleet, from the first one in OFFBOARD on

    # ---- Vehicle protocol ---------------------------------------------------------------------
    def telemetry(self) -> Telemetry:
        return self.frozen if self.frozen is not None else self._fleet.telemetry_of(self.drone_id)

    def arm(self) -> None:
        if self._refuse("arm") or self.armed:
            return
        reason = self._fleet.arm_blocker(self.drone_id)
        if reason:
            self._deny("arm", reason)
            return
        self.armed, self._arm_t_s, self._been_airborne = True, self._fleet.t_s, False
        self._ctrl.reset_integrator(self.drone_id)
        self._ramp_takeoff(self._arm_t_s)
        self._set_mode(FlightMode.IDLE)
        self._fleet.supervise(self.drone_id)

    def disarm(self) -> None:
        if self._refuse("disarm") or not self.armed:
            return
        if not self._landed():
            self._deny("disarm", "airborne")
            return
        self._disarm("command")

    def takeoff(self, alt_m: float) -> None:
        if self._refuse("takeoff"):
            return
        try:
            alt = float(alt_m)
        except (TypeError, ValueError):
            alt = math.nan
        if not (math.isfinite(alt) and alt > 0):
            self._deny("takeoff", f"bad altitude {alt_m!r}")
            return
        n, e, _ = self._est()
        self._takeoff_d_m = self.home_ned_m[2] - min(alt, self._limits.max_alt_m)
        if self._landed():
            self._ctrl.reset_integrator(self.drone_id)
        self._ctrl.set_position(self.drone_id, (n, e, self._takeoff_d_m),
                                  vmax_up_m_s=self._p.mpc_tko_speed_m_s)
        self._set_mode(FlightMode.TAKEOFF)

    def setpoint(self, sp: Setpoint) -> SetpointVerdict:
        if sp == self._last_ok and self.frozen is None:
            # the setpoint flown since last tick, passed unchanged then; in OFFBOARD and armed (any
            # mode change forgets it). What depends on the vehicle's state: the jump limit of a
            # position, the envelope near its boundary for a velocity or an acceleration.
            self._held.fresh = True
            est = self._fleet.estimate_ned(self.drone_id)
            if sp.kind is _POSITION:
                if math.dist(sp.ned, est) <= self._limits.max_jump_m:
                    return self._ok_verdict
            elif not near_boundary(est, self._limits):
                return self._ok_verdict
        if self._refuse("setpoint"):
            return SetpointVerdict("ignored", "disarmed")
        verdict = check_setpoint(sp, self.telemetry(), self._limits)
        result = SetpointVerdict(verdict.action, verdict.reason, verdict.setpoint)
        if verdict.action != "ok":
            self._fleet.emit(self.drone_id, "safety", "setpoint_" + verdict.action,
                             safety_event(sp, verdict, self.telemetry()))
        requested, sp = sp, verdict.setpoint
        if sp is None or (self.mode is FlightMode.OFFBOARD and sp == self._last_sp):
            if sp is not None:
                self._held.asked(requested)
                if verdict.action == "ok":
                    self._last_ok, self._ok_verdict = sp, result
            return result
        self._command(sp)
        self._set_mode(FlightMode.OFFBOARD)
        self._last_sp = sp
        self._held.asked(requested)
        if sp.kind is not _POSITION and not self._watched:
            self._watched = True
            self._fleet.watch(self.drone_id, True)
        if verdict.action == "ok":
            self._last_ok, self._ok_verdict = sp, result
        return result

    def _command(self, sp: Setpoint) -> None:
        ctrl, i = self._ctrl, self.drone_id
        if sp.kind is SetpointKind.POSITION:
            ctrl.set_position(i, sp.ned)
        elif sp.kind is SetpointKind.VELOCITY:
            ctrl.set_velocity(i, sp.ned)
        else:
            ctrl.set_acceleration(i, sp.ned)
        ctrl.set_yaw_target(i, sp.yaw_rad)

    def judge_held(self) -> None:
        """Judge the velocity or acceleration flown without a new setpoint since the last step again
        on the vehicle's state (the fleet calls this near the envelope)."""
        held = self._held.stale()
        if held is None or self.mode is not FlightMode.OFFBOARD or self.frozen is not None:
            return
        verdict = check_setpoint(held, self.telemetry(), self._limits)
        if verdict.action != "ok":
            self._fleet.emit(self.drone_id, "safety", "setpoint_" + verdict.action,
                             safety_event(held, verdict, self.telemetry()))
        sp = verdict.setpoint
        if sp is not None and sp != self._last_sp:
            self._command(sp)
            self._last_sp, self._last_ok = sp, None

    def land(self) -> None:
        if self._refuse("land"):
            return
        n, e, _ = self._est()
        if self._p.land_at_stop_point:
            n, e = self._stop_point(n, e)
        self._ctrl.set_descent(self.drone_id, n, e, self._p.mpc_land_speed_m_s)
        self._set_mode(FlightMode.LAND)

    def return_to_launch(self) -> None:
        if self._refuse("rtl"):
            return
        n, e, d = self._est()
        self._set_mode(FlightMode.RTL)
        if self._landed():
            self._rtl_phase = "land"
            self._ctrl.set_descent(self.drone_id, n, e, self._p.mpc_land_speed_m_s)
            return
        self._rtl_phase = "climb"
        self._takeoff_d_m = min(d, self.home_ned_m[2] - self._p.rtl_alt_m)
        self._ctrl.set_position(self.drone_id, (n, e, self._takeoff_d_m))

    def hold(self) -> None:
        if self._refuse("hold"):
            return
        if self._landed():   # PX4 idles on the ground in Hold
            self._set_mode(FlightMode.HOLD)
            self._ctrl.set_thrust_off(self.drone_id)
            return
        self._ctrl.set_velocity(self.drone_id, (0.0, 0.0, 0.0))   # brake, then hold where stopped
        self._braking = True
        self._set_mode(FlightMode.HOLD)

    # ---- supervisor (called every step while in an automatic mode or not yet airborne) ---------
    def supervise(self, t_s: float) -> bool:
        """Advance the automatic modes; returns whether to keep supervising."""
        if not self.armed or self.frozen is not None:
            return False
        ramping = self._ramp_takeoff(t_s)
        landed = self._landed()
        if not self._been_airborne:
            if not landed:
                self._been_airborne = True
            elif t_s - self._arm_t_s >= self._p.preflight_disarm_s:
                self._disarm("no takeoff")
                return False
        if self.mode is FlightMode.TAKEOFF:
            if abs(self._est()[2] - self._takeoff_d_m) <= self._p.takeoff_acceptance_m:
                n, e, _ = self._est()
                self._ctrl.set_position(self.drone_id, (n, e, self._takeoff_d_m))
                self._set_mode(FlightMode.HOLD)
        elif self.mode is FlightMode.HOLD and self._braking:
            if self._fleet.speed_m_s(self.drone_id) < self._p.hold_brake_speed_m_s:
                self._braking = False
                self._ctrl.set_position(self.drone_id, self._est())
        elif self.mode is FlightMode.RTL and self._rtl_phase != "land":
            self._rtl_step()
        elif self.mode is FlightMode.LAND or self.mode is FlightMode.RTL:
            self._landing_step(t_s, landed)
        return self.armed and (self.mode in _AUTO or self._braking or not self._been_airborne or ramping)

    def _ramp_takeoff(self, t_s: float) -> bool:
        """PX4's smooth takeoff: the climb-rate limit stays at -g/MPC_Z_VEL_P_ACC (a descent rate that
        commands zero thrust) for COM_SPOOLUP_TIME after arming, then ramps linearly over
        MPC_TKO_RAMP_T to MPC_Z_VEL_MAX_UP (Takeoff.cpp). Returns whether the ramp is still running."""
        p, i = self._p, self.drone_id
        since = t_s - self._arm_t_s - p.com_spoolup_time_s
        if not self.armed or p.mpc_tko_ramp_t_s <= 0 or since >= p.mpc_tko_ramp_t_s:
            self._ctrl.set_takeoff_ramp(i, math.inf)
            return False
        start = -GRAVITY_M_S2 / max(p.mpc_z_vel_p_acc, 1e-6)
        frac = min(max(since / p.mpc_tko_ramp_t_s, 0.0), 1.0)
        self._ctrl.set_takeoff_ramp(i, start + frac * (p.mpc_z_vel_max_up_m_s - start))
        return True

    def _rtl_step(self) -> None:
        p, (n, e, d) = self._p, self._est()
        hn, he = self.home_ned_m[0], self.home_ned_m[1]
        if self._rtl_phase == "climb" and d <= self._takeoff_d_m + p.takeoff_acceptance_m:
            self._rtl_phase = "return"
            self._ctrl.set_position(self.drone_id, (hn, he, self._takeoff_d_m),
                                      vmax_h_m_s=p.rtl_cruise_speed_m_s)
        elif self._rtl_phase == "return" and math.hypot(n - hn, e - he) <= p.rtl_acceptance_m:
            self._rtl_phase = "land"
            self._ground_since_s = None
            self._ctrl.set_descent(self.drone_id, hn, he, p.mpc_land_speed_m_s)

    def _landing_step(self, t_s: float, landed: bool) -> None:
        if not landed:
            self._ground_since_s = None
        elif self._ground_since_s is None:
            self._ground_since_s = t_s
        elif t_s - self._ground_since_s >= self._p.land_disarm_delay_s:
            self._disarm("landed")

    # ---- helpers ------------------------------------------------------------------------------
    def crash(self, last: Telemetry) -> None:
        """Freeze telemetry at ``last`` and cut the motors for good."""
        self.frozen = last
        self._ctrl.set_thrust_off(self.drone_id)

    def _disarm(self, reason: str) -> None:
        self.armed = False
        self._ctrl.set_takeoff_ramp(self.drone_id, math.inf)
        self._ctrl.set_thrust_off(self.drone_id)
        self._set_mode(FlightMode.IDLE)
        self._fleet.emit(self.drone_id, "command", "disarmed", {"reason": reason})

    def _set_mode(self, mode: FlightMode) -> None:
        if mode is not self.mode:
            self._noted.clear()
            self._held.asked(None)
            if self._watched:
                self._watched = False
                self._fleet.watch(self.drone_id, False)
        self.mode, self._last_sp, self._last_ok, self._ground_since_s = mode, None, None, None
        self._ctrl.set_offboard_limits(self.drone_id, mode is FlightMode.OFFBOARD)
        self._braking = self._braking and mode is FlightMode.HOLD
        if mode in _AUTO or self._braking or (self.armed and not self._been_airborne):
            self._fleet.supervise(self.drone_id)

    def _refuse(self, cmd: str) -> bool:
        """Deny ``cmd`` when crashed or (except arm) disarmed; True when denied."""
        if self.frozen is not None:
            self._deny(cmd, "crashed")
            return True
        if cmd != "arm" and not self.armed:
            self._deny(cmd, "disarmed")
            return True
        return False

    def _deny(self, cmd: str, reason: str) -> None:
        """Report a refused command once per (command, reason) and flight mode."""
        if (cmd, reason) not in self._noted:
            self._noted.add((cmd, reason))
            name = "setpoint_ignored" if cmd == "setpoint" else cmd + "_denied"
            self._fleet.emit(self.drone_id, "command", name, {"reason": reason})

    def _landed(self) -> bool:
        return self._fleet.on_ground(self.drone_id)

    def _stop_point(self, n: float, e: float) -> tuple[float, float]:
        """Where the vehicle would stop from its velocity, as PX4's navigator projects it for LAND
        (``computeBrakingDistanceFromVelocity`` with accel MPC_ACC_HOR and a 0.6 s jerk delay)."""
        vn, ve, _ = self._fleet.telemetry_of(self.drone_id).vel_ned_m_s
        scale = math.hypot(vn, ve) / (2.0 * self._p.mpc_acc_hor_m_s2) + 0.6
        return n + vn * scale, e + ve * scale

    def _est(self) -> Vec3:
        return self._fleet.estimate_ned(self.drone_id)
