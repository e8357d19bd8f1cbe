"""PX4's commander and navigator, reduced to what an offboard swarm uses, over one simulated vehicle.

The dynamics, estimator and automatic modes are the ``sim`` backend's
(:class:`~swarmbox.hal.sim.vehicle.SimVehicle` on a one-vehicle
:class:`~swarmbox.hal.sim.backend.SimBackend` whose home is the local origin); this class adds what a
MAVLink client sees of PX4: the navigation state (``custom_mode``), command results
(ACCEPTED / TEMPORARILY_REJECTED / DENIED / UNSUPPORTED), arming checks, the offboard signal and
its loss failsafe, the landed state and STATUSTEXT lines.

PX4 behaviours kept: OFFBOARD can only be entered while setpoints stream; arming is refused until
the estimator is ready, and in LAND/RTL; a takeoff goes at least to MIS_TAKEOFF_ALT and ends in
Hold; after landing the vehicle disarms itself; the loss timeouts scale with the speed factor, as
PX4's rcS does.
"""

from __future__ import annotations

import math
from collections.abc import Callable

from swarmbox.api import FlightMode, Setpoint, Telemetry
from swarmbox.hal.mavlink.codec import (
    CMD_ARM_DISARM,
    CMD_INJECT_FAILURE,
    CMD_LAND,
    CMD_RTL,
    CMD_SET_MODE,
    CMD_TAKEOFF,
    COMMAND_NAMES,
    CUSTOM_MODE_FLAG,
    LANDED_IN_AIR,
    LANDED_LANDING,
    LANDED_ON_GROUND,
    LANDED_TAKEOFF,
    MODE_HOLD,
    MODE_LAND,
    MODE_OFFBOARD,
    MODE_POSCTL,
    MODE_RTL,
    MODE_TAKEOFF,
    RESULT_ACCEPTED,
    RESULT_DENIED,
    RESULT_TEMPORARILY_REJECTED,
    RESULT_UNSUPPORTED,
    mode_name,
    px4_mode,
)
from swarmbox.hal.mavsim.failures import VehicleFailures
from swarmbox.hal.sim.backend import SimBackend

SEVERITY_CRITICAL, SEVERITY_WARNING, SEVERITY_INFO = 2, 4, 6
MIS_TAKEOFF_ALT_M = 2.5
FORCE_DISARM = 21196.0
_LOSS_ACTIONS = ("hold", "land", "rtl")


class Commander:
    """The flight-mode logic of one mavsim vehicle; every time is simulation time."""

    def __init__(self, sim: SimBackend, *, home_alt_m: float, speed: float = 1.0,
                 offboard_loss_s: float = 1.0, offboard_loss_action: str = "hold",
                 refuse: frozenset[str] = frozenset()) -> None:
        if offboard_loss_action not in _LOSS_ACTIONS:
            raise ValueError(f"offboard_loss_action must be one of {_LOSS_ACTIONS}, "
                             f"got {offboard_loss_action!r}")
        self.sim, self.v = sim, sim.vehicles[0]
        self.home_alt_m = float(home_alt_m)                  # AMSL: NAV_TAKEOFF's altitude is absolute
        self.nav = MODE_HOLD
        self.texts: list[tuple[int, str]] = []       # STATUSTEXT lines to send
        self._loss_s = offboard_loss_s * speed         # PX4's rcS multiplies COM_OF_LOSS_T by the speed
        self._loss_action = offboard_loss_action
        self._refused = frozenset(refuse)   # fault injection: command names ("arm", "takeoff", ...) denied
        self._sp: Setpoint | None = None
        self._sp_s = -math.inf
        self._handlers: dict[int, Callable[[tuple[float, ...]], int]] = {
            CMD_ARM_DISARM: self._arm_disarm, CMD_SET_MODE: self._set_mode, CMD_TAKEOFF: self._takeoff,
            CMD_LAND: self._land, CMD_RTL: self._rtl, CMD_INJECT_FAILURE: self._inject_failure}
        self.failures = VehicleFailures(sim)

    @property
    def t_s(self) -> float:
        return self.sim.t_s

    @property
    def armed(self) -> bool:
        return self.v.armed

    def telemetry(self) -> Telemetry:
        return self.v.telemetry()

    # ---- inputs -------------------------------------------------------------------------------
    def on_setpoint(self, sp: Setpoint) -> None:
        """A SET_POSITION_TARGET_LOCAL_NED: the offboard signal, followed in OFFBOARD when armed."""
        self._sp, self._sp_s = sp, self.t_s
        if self.nav == MODE_OFFBOARD and self.v.armed:
            self.v.setpoint(sp)

    def on_command(self, command: int, params: tuple[float, ...]) -> int:
        """A COMMAND_LONG; returns the MAV_RESULT of its COMMAND_ACK."""
        handler = self._handlers.get(command)
        name = "arm" if command == CMD_ARM_DISARM and params[:1] == (1.0,) else COMMAND_NAMES.get(command)
        if name in self._refused:   # e.g. a pre-flight check that never passes
            self._text(SEVERITY_CRITICAL, f"{name} denied (injected)")
            return RESULT_DENIED
        return RESULT_UNSUPPORTED if handler is None else handler(params)

    def _inject_failure(self, params: tuple[float, ...]) -> int:
        result, text = self.failures.inject(params)
        self._text(SEVERITY_WARNING if result == RESULT_ACCEPTED else SEVERITY_INFO, text)
        return result

    # ---- state --------------------------------------------------------------------------------
    def offboard_signal(self) -> bool:
        return self._sp is not None and self.t_s - self._sp_s <= self._loss_s

    def ready_to_arm(self) -> bool:
        """PX4's PREARM bit: could arm now, in the current mode."""
        if self.sim.arm_blocker(0) or self.nav in (MODE_LAND, MODE_RTL):
            return False
        return self.nav != MODE_OFFBOARD or self.offboard_signal()

    def landed_state(self) -> int:
        if self.sim.on_ground(0):
            return LANDED_ON_GROUND
        if self.nav == MODE_TAKEOFF:
            return LANDED_TAKEOFF
        return LANDED_LANDING if self.nav == MODE_LAND else LANDED_IN_AIR

    # ---- time ---------------------------------------------------------------------------------
    def step(self, dt_s: float) -> None:
        """Advance the dynamics, then the automatic transitions and the failsafe."""
        self.failures.step()
        self.sim.step(dt_s)
        for ev in self.sim.drain_events():
            if ev.kind == "command" and ev.name == "disarmed":
                reason = ev.data.get("reason")
                self._text(SEVERITY_INFO, "Disarmed by landing" if reason == "landed"
                           else "Disarmed by auto preflight disarming" if reason == "no takeoff"
                           else "Disarmed by external command")
        if not self.v.armed:
            if self.nav in (MODE_TAKEOFF, MODE_LAND, MODE_RTL):
                self.nav = MODE_HOLD
            return
        if self.nav == MODE_TAKEOFF and self.v.mode is FlightMode.HOLD:
            self.nav = MODE_HOLD
        elif self.nav == MODE_OFFBOARD and not self.offboard_signal():
            self._text(SEVERITY_WARNING, f"Failsafe: offboard signal lost, activating {self._loss_action}")
            self._enter_loss_action()

    def _enter_loss_action(self) -> None:
        if self._loss_action == "land":
            self.v.land()
            self.nav = MODE_LAND
        elif self._loss_action == "rtl":
            self.v.return_to_launch()
            self.nav = MODE_RTL
        else:
            self.v.hold()
            self.nav = MODE_HOLD

    # ---- commands -----------------------------------------------------------------------------
    def _arm_disarm(self, p: tuple[float, ...]) -> int:
        if p[0] < 0.5:
            return self._disarm(p)
        if self.v.armed:
            return RESULT_ACCEPTED
        if self.nav in (MODE_LAND, MODE_RTL) or (self.nav == MODE_OFFBOARD and not self.offboard_signal()):
            self._text(SEVERITY_CRITICAL, f"Arming denied: not possible in {mode_name(self.nav)}")
            return RESULT_DENIED
        reason = self.sim.arm_blocker(0)
        if reason:
            self._text(SEVERITY_CRITICAL, f"Arming denied: {reason}")
            return RESULT_TEMPORARILY_REJECTED
        self.v.arm()
        self._text(SEVERITY_INFO, "Armed by external command")
        if self.nav == MODE_OFFBOARD and self._sp is not None:
            self.v.setpoint(self._sp)
        return RESULT_ACCEPTED

    def _disarm(self, p: tuple[float, ...]) -> int:
        if not self.v.armed:
            return RESULT_ACCEPTED
        if not self.sim.on_ground(0):
            self._text(SEVERITY_CRITICAL, "Disarming denied: not landed")
            return RESULT_DENIED
        self.v.disarm()
        self.nav = MODE_HOLD
        return RESULT_ACCEPTED

    def _set_mode(self, p: tuple[float, ...]) -> int:
        if not int(p[0]) & CUSTOM_MODE_FLAG:
            return RESULT_UNSUPPORTED
        mode = px4_mode(int(p[1]), int(p[2]))
        if mode == MODE_OFFBOARD:
            if not self.offboard_signal():
                self._text(SEVERITY_CRITICAL, "Switching to Offboard is currently not possible")
                return RESULT_TEMPORARILY_REJECTED
            self.nav = mode
            if self.v.armed and self._sp is not None:
                self.v.setpoint(self._sp)
            return RESULT_ACCEPTED
        if mode in (MODE_HOLD, MODE_POSCTL):
            if self.v.armed:
                self.v.hold()
            self.nav = mode
            return RESULT_ACCEPTED
        if mode == MODE_TAKEOFF:
            return self._takeoff((math.nan,) * 7)
        if mode == MODE_LAND:
            return self._land(p)
        return self._rtl(p) if mode == MODE_RTL else RESULT_DENIED

    def _takeoff(self, p: tuple[float, ...]) -> int:
        if not self.v.armed:
            self._text(SEVERITY_CRITICAL, "Takeoff denied: disarmed")
            return RESULT_DENIED
        rel = p[6] - self.home_alt_m if math.isfinite(p[6]) else MIS_TAKEOFF_ALT_M
        if rel < MIS_TAKEOFF_ALT_M:
            self._text(SEVERITY_WARNING, f"Using minimum takeoff altitude: {MIS_TAKEOFF_ALT_M:.2f} m")
            rel = MIS_TAKEOFF_ALT_M
        self.v.takeoff(rel)
        self.nav = MODE_TAKEOFF
        return RESULT_ACCEPTED

    def _land(self, p: tuple[float, ...]) -> int:
        if not self.v.armed:
            return RESULT_DENIED
        self.v.land()
        self.nav = MODE_LAND
        return RESULT_ACCEPTED

    def _rtl(self, p: tuple[float, ...]) -> int:
        if not self.v.armed:
            return RESULT_DENIED
        self.v.return_to_launch()
        self.nav = MODE_RTL
        return RESULT_ACCEPTED

    def _text(self, severity: int, text: str) -> None:
        self.texts.append((severity, text))
