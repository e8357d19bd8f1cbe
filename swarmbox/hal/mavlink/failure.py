"""Failures asked of the autopilot itself: MAV_CMD_INJECT_FAILURE, with its acknowledgement.

PX4 (with ``SYS_FAILURE_EN=1``) and mavsim can switch a sensor or a system off inside the vehicle,
so a fault acts where it would in flight: the vehicle's estimator loses its GNSS, not a value in
the bridge. A request is a :class:`FailureRequest` (unit, type, instance by name); a
:class:`FailureInjector` sends it for one vehicle through that vehicle's command tracker (ack,
bounded retry) and reports what the autopilot answered as ``fault`` events:

- ``fault/inject_accepted`` — the autopilot acknowledged it (ACCEPTED);
- ``fault/inject_refused`` — refused or never answered, with the result and the likely cause
  (DENIED: failure injection is disabled, ``SYS_FAILURE_EN=0``; UNSUPPORTED: the autopilot has no
  handler for that unit and type; no ack: nothing in the autopilot handles the unit at all).

A refused injection never aborts the drone: the fault simply did not happen, and the event says so.
The vehicle side (mavsim) decodes the same command with :meth:`FailureRequest.from_params`.

PX4 SITL with SIH, up to at least PX4 main of August 2025 (a70a558), has no handler for a GNSS
failure: the command goes to uORB and nothing answers (``failure gps off`` in PX4's own shell times
out the same way; only the Gazebo-classic bridge ``simulator_mavlink`` handled it, and SIH's
``sensor_gps_sim`` learnt it later). For such a vehicle the injector can instead write PX4's
``SIM_GPS_USED`` parameter (satellites of the simulated receiver; below 4 it reports no fix, and
EKF2 stops fusing GNSS exactly as when a receiver loses its fix): ``gnss_via_param``. The event
then says ``via: SIM_GPS_USED``.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from pymavlink.dialects.v20 import common as mavlink

from swarmbox.hal.mavlink.codec import CMD_INJECT_FAILURE
from swarmbox.hal.mavlink.link import Command
from swarmbox.hal.mavlink.paramset import Done

__all__ = ["CMD_INJECT_FAILURE", "TYPES", "UNITS", "FailureInjector", "FailureRequest"]

#: failure units by name (MAVLink FAILURE_UNIT)
UNITS = {
    "gyro": mavlink.FAILURE_UNIT_SENSOR_GYRO, "accel": mavlink.FAILURE_UNIT_SENSOR_ACCEL,
    "mag": mavlink.FAILURE_UNIT_SENSOR_MAG, "baro": mavlink.FAILURE_UNIT_SENSOR_BARO,
    "gps": mavlink.FAILURE_UNIT_SENSOR_GPS, "optical_flow": mavlink.FAILURE_UNIT_SENSOR_OPTICAL_FLOW,
    "vio": mavlink.FAILURE_UNIT_SENSOR_VIO, "distance_sensor": mavlink.FAILURE_UNIT_SENSOR_DISTANCE_SENSOR,
    "airspeed": mavlink.FAILURE_UNIT_SENSOR_AIRSPEED, "battery": mavlink.FAILURE_UNIT_SYSTEM_BATTERY,
    "motor": mavlink.FAILURE_UNIT_SYSTEM_MOTOR, "servo": mavlink.FAILURE_UNIT_SYSTEM_SERVO,
    "avoidance": mavlink.FAILURE_UNIT_SYSTEM_AVOIDANCE, "rc_signal": mavlink.FAILURE_UNIT_SYSTEM_RC_SIGNAL,
    "mavlink_signal": mavlink.FAILURE_UNIT_SYSTEM_MAVLINK_SIGNAL,
}
#: failure types by name (MAVLink FAILURE_TYPE); ``ok`` ends a failure
TYPES = {
    "ok": mavlink.FAILURE_TYPE_OK, "off": mavlink.FAILURE_TYPE_OFF, "stuck": mavlink.FAILURE_TYPE_STUCK,
    "garbage": mavlink.FAILURE_TYPE_GARBAGE, "wrong": mavlink.FAILURE_TYPE_WRONG,
    "slow": mavlink.FAILURE_TYPE_SLOW, "delayed": mavlink.FAILURE_TYPE_DELAYED,
    "intermittent": mavlink.FAILURE_TYPE_INTERMITTENT,
}
_UNIT_NAMES = {v: k for k, v in UNITS.items()}
_TYPE_NAMES = {v: k for k, v in TYPES.items()}
#: why an autopilot refuses an injection, by the result the command tracker reports
CAUSES = {
    "denied": "failure injection is disabled on the autopilot (PX4: SYS_FAILURE_EN=0)",
    "unsupported": "the autopilot has no handler for this failure unit and type",
    "no ack": "nothing in the autopilot answered (PX4: no module handles this unit in this simulator)",
}

Emit = Callable[[str, str, dict[str, Any]], None]
#: set_param(name, value, done): write an autopilot parameter, ``done(ok, detail)`` when confirmed
SetParam = Callable[[str, float, Done], None]
SIM_GPS_USED = "SIM_GPS_USED"        # PX4 SIH GPS simulator: satellites used; < 4 -> no fix
SIM_GPS_USED_ON = 10                 # PX4's default
VIA_COMMAND, VIA_PARAM = "MAV_CMD_INJECT_FAILURE", SIM_GPS_USED


@dataclass(frozen=True)
class FailureRequest:
    """One failure: ``unit`` (``gps``, ``baro`` ...), ``kind`` (``off``, ``stuck`` ..., ``ok`` to end
    it) and the sensor ``instance`` (0: all instances, PX4's convention; 1 the first ...)."""

    unit: str
    kind: str
    instance: int = 0

    def __post_init__(self) -> None:
        if self.unit not in UNITS:
            raise ValueError(f"failure unit {self.unit!r} unknown (units: {', '.join(UNITS)})")
        if self.kind not in TYPES:
            raise ValueError(f"failure type {self.kind!r} unknown (types: {', '.join(TYPES)})")
        if not isinstance(self.instance, int) or not 0 <= self.instance <= 255:
            raise ValueError(f"failure instance must be an integer 0-255, not {self.instance!r}")

    @property
    def params(self) -> tuple[float, float, float]:
        """COMMAND_LONG param1-3: unit, type, instance."""
        return float(UNITS[self.unit]), float(TYPES[self.kind]), float(self.instance)

    @property
    def label(self) -> str:
        return f"{self.unit} {self.kind}" + (f" (instance {self.instance})" if self.instance else "")

    @classmethod
    def from_params(cls, params: tuple[float, ...]) -> FailureRequest:
        """The request a received COMMAND_LONG carries; ValueError for codes MAVLink does not define."""
        p = (tuple(params) + (0.0, 0.0, 0.0))[:3]
        unit, kind = _UNIT_NAMES.get(round(p[0])), _TYPE_NAMES.get(round(p[1]))
        if unit is None or kind is None:
            raise ValueError(f"INJECT_FAILURE with unit {p[0]!r} and type {p[1]!r}: not MAVLink codes")
        return cls(unit, kind, round(p[2]))

    def event_data(self) -> dict[str, Any]:
        return {"unit": self.unit, "type": self.kind, "instance": self.instance}


class FailureInjector:
    """One vehicle's failure requests, sent through its command tracker.

    ``submit(command)`` queues a :class:`~swarmbox.hal.mavlink.link.Command` on the vehicle's
    tracker; the vehicle routes the tracker's failures for ``CMD_INJECT_FAILURE`` to
    :meth:`on_failed`. ``active`` holds the failures the autopilot accepted and that were not ended.
    """

    def __init__(self, submit: Callable[[Command], None], emit: Emit, set_param: SetParam | None = None,
                 gnss_via_param: bool = False) -> None:
        self._submit, self._emit, self._set_param = submit, emit, set_param
        self.gnss_via_param = gnss_via_param and set_param is not None
        self.active: dict[tuple[str, int], str] = {}
        self.refused = 0

    def inject(self, request: FailureRequest) -> None:
        """Ask the autopilot for ``request`` (``kind="ok"`` ends a failure of that unit)."""
        if request.unit == "gps" and self.gnss_via_param and self._set_param is not None:
            if request.kind not in ("off", "ok"):
                self._refuse(request, "unsupported", f"only off and ok through {SIM_GPS_USED}", VIA_PARAM)
                return
            value = 0 if request.kind == "off" else SIM_GPS_USED_ON
            self._set_param(SIM_GPS_USED, value, lambda ok, detail: self._accepted(request, VIA_PARAM) if ok
                            else self._refuse(request, "not confirmed", detail, VIA_PARAM))
            return
        self._submit(Command(CMD_INJECT_FAILURE, request.params, on_accepted=lambda: self._accepted(request)))

    def end(self, unit: str, instance: int = 0) -> None:
        """End a failure of ``unit`` (FAILURE_TYPE_OK)."""
        self.inject(FailureRequest(unit, "ok", instance))

    def _accepted(self, request: FailureRequest, via: str = VIA_COMMAND) -> None:
        key = (request.unit, request.instance)
        if request.kind == "ok":
            self.active.pop(key, None)
        else:
            self.active[key] = request.kind
        self._emit("fault", "inject_accepted", {**request.event_data(), "via": via})

    def _refuse(self, request: FailureRequest, result: str, cause: str, via: str, tries: int = 0) -> None:
        self.refused += 1
        self._emit("fault", "inject_refused", {**request.event_data(), "result": result, "tries": tries,
                                               "cause": cause, "via": via})

    def on_failed(self, cmd: Command, result: str) -> None:
        """The tracker gave up on an injection: a ``fault/inject_refused`` event with the cause."""
        try:
            request = FailureRequest.from_params(cmd.params)
        except ValueError:
            return
        self._refuse(request, result, CAUSES.get(result, "the autopilot refused it"), VIA_COMMAND, cmd.tries)
