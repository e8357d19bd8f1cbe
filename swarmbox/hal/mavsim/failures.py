"""MAV_CMD_INJECT_FAILURE inside a mavsim vehicle: the failures its simulation can model.

A vehicle answers the command as PX4 with ``SYS_FAILURE_EN=1`` does: ACCEPTED when it applies the
failure, UNSUPPORTED for a unit and type it cannot model. What each accepted failure does to the
one-vehicle :class:`~swarmbox.hal.sim.backend.SimBackend` under it:

| unit | type | effect |
|---|---|---|
| gps | off | no more fixes: the estimator coasts on its inertial prediction |
| gps | stuck | every fix repeats the last one (noise off), wherever the vehicle goes |
| gps | wrong | every fix ``WRONG_OFFSET_NED_M`` (20 m north) off the truth, a constant error |
| gps | ok | the receiver is healthy again (all of the above undone) |
| motor | off | motors cut for good: the sim backend's crash (telemetry frozen; ``ok`` cannot undo it) |
| motor | slow | thrust margin halved: the accelerations the controller can command are scaled by 0.5 |
| motor | ok | full thrust again (not after ``off``) |

A growing drift has no MAVLink failure type; PX4 cannot be asked for one either.
"""

from __future__ import annotations

from swarmbox.hal.mavlink.codec import RESULT_ACCEPTED, RESULT_DENIED, RESULT_UNSUPPORTED
from swarmbox.hal.mavlink.failure import FailureRequest
from swarmbox.hal.sim.backend import SimBackend

WRONG_OFFSET_NED_M = (20.0, 0.0, 0.0)
SLOW_MOTOR_SCALE = 0.5


class VehicleFailures:
    """The failures in force on vehicle 0 of ``sim``, and what the command answers."""

    def __init__(self, sim: SimBackend) -> None:
        self.sim = sim
        self.gps = "ok"
        self.motor = "ok"
        self._stuck_fix: tuple[float, float, float] | None = None

    def inject(self, params: tuple[float, ...]) -> tuple[int, str]:
        """Apply one INJECT_FAILURE; returns the MAV_RESULT and a STATUSTEXT line."""
        try:
            req = FailureRequest.from_params(params)
        except ValueError as exc:
            return RESULT_UNSUPPORTED, f"failure injection: {exc}"
        if req.unit == "gps" and req.kind in ("ok", "off", "stuck", "wrong"):
            self._gps(req.kind)
        elif req.unit == "motor" and req.kind in ("ok", "off", "slow"):
            if req.kind == "ok" and self.motor == "off":
                return RESULT_DENIED, "failure injection: a motor that failed off does not come back"
            self._motor(req.kind)
        else:
            return RESULT_UNSUPPORTED, f"failure injection: {req.label} not modelled by this vehicle"
        return RESULT_ACCEPTED, f"failure injected: {req.label}"

    def _gps(self, kind: str) -> None:
        sim = self.sim
        sim.gnss_available[0] = kind != "off"
        sim.gnss_noise_scale[0] = 0.0 if kind == "stuck" else 1.0
        sim.gnss_offset_ned_m[0] = WRONG_OFFSET_NED_M if kind == "wrong" else (0.0, 0.0, 0.0)
        self._stuck_fix = None
        if kind == "stuck":
            tel = sim.vehicles[0].telemetry()
            fix = tel.gnss_ned_m or tel.pos_ned_m
            self._stuck_fix = (fix[0], fix[1], fix[2])
        self.gps = kind

    def _motor(self, kind: str) -> None:
        if kind == "off":
            self.sim.crashed[0] = True
        self.sim.accel_scale[0] = SLOW_MOTOR_SCALE if kind == "slow" else 1.0
        self.motor = kind

    def step(self) -> None:
        """Before each physics step: a stuck receiver's offset follows the truth so the fix stays put."""
        if self._stuck_fix is not None:
            true = self.sim.true_pos_ned_m[0]
            self.sim.gnss_offset_ned_m[0] = (self._stuck_fix[0] - true[0], self._stuck_fix[1] - true[1],
                                             self._stuck_fix[2] - true[2])
