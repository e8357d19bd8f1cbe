"""GNSS failures the autopilot applies to itself (MAV_CMD_INJECT_FAILURE): ``gps_failure``.

Where :mod:`swarmbox.faults.gnss` writes the sim backend's GNSS inputs, this model asks the
vehicle's autopilot (``px4``, ``mavsim``: backends with ``inject_failure(i, unit, kind)``) to fail
its own receiver, so its own estimator sees the failure, as in flight. ``failure`` is a MAVLink
FAILURE_TYPE the autopilot models: mavsim answers ``off``, ``stuck`` and ``wrong`` (see
:mod:`swarmbox.hal.mavsim.failures`); an autopilot without a handler refuses, and the drone's
``fault/inject_refused`` event says why. At the end the receiver is restored (FAILURE_TYPE_OK).
In a distributed run (``run.runtime=processes``) the agent process that owns the vehicle sends it.
"""

from __future__ import annotations

from dataclasses import dataclass

from swarmbox.faults.base import Fault, FaultEnv, FaultParams

FAILURES = ("off", "stuck", "wrong")


@dataclass
class GpsFailureParams(FaultParams):
    failure: str = "wrong"     # off | stuck | wrong (MAVLink FAILURE_TYPE)


class GpsFailure(Fault):
    """The autopilot's GNSS receiver fails as ``failure`` from the onset to the end."""

    name = "gps_failure"
    Params = GpsFailureParams

    def validate(self) -> None:
        if self.p.failure not in FAILURES:
            self.fail(f"failure must be one of {', '.join(FAILURES)}, got {self.p.failure!r}")

    def check(self, env: FaultEnv) -> None:
        env.require_backend(self.name, ("inject_failure",), "an autopilot that takes MAV_CMD_INJECT_FAILURE")

    def start(self, env: FaultEnv) -> None:
        for drone in self.drones():
            env.backend.inject_failure(env.index(drone), "gps", self.p.failure)

    def stop(self, env: FaultEnv) -> None:
        for drone in self.drones():
            env.backend.inject_failure(env.index(drone), "gps", "ok")
