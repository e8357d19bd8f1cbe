"""GNSS faults: drift, bias, noise increase, dropout.

They act on the backend's GNSS fault inputs (see :class:`swarmbox.hal.sim.backend.SimBackend`):
``gnss_offset_ned_m`` (N, 3) is added to every fix, ``gnss_noise_scale`` (N,) multiplies the fix
noise, ``gnss_available`` (N,) False stops the fixes. A backend without these inputs cannot express
the faults and the run is refused at start-up. The faults compose: offsets add, noise scales
multiply, and a fault's end removes only its own contribution.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from swarmbox.faults.base import Fault, FaultEnv, FaultParams

_OFFSET = ("gnss_offset_ned_m",)


@dataclass
class GpsDriftParams(FaultParams):
    rate_m_s: float = 1.0   # m/s: the offset grows linearly at this rate from the onset
    direction_ned: list[float] = field(default_factory=lambda: [1.0, 0.0, 0.0])  # normalised; north


@dataclass
class GpsBiasParams(FaultParams):
    bias_ned_m: list[float] = field(default_factory=lambda: [5.0, 0.0, 0.0])   # m, constant offset


@dataclass
class GpsNoiseParams(FaultParams):
    noise_scale: float = 10.0   # multiplies the receiver's noise standard deviation


@dataclass
class GpsDropoutParams(FaultParams):
    pass


class GpsDrift(Fault):
    """A linearly growing GNSS offset: ``rate_m_s * (t - onset_s)`` along ``direction_ned``.

    The offset is updated every tick for the instant at the end of that tick's backend step (the
    moment a fix taken in the step is stamped), so a fix sees the exact ramp. At the end the
    receiver recovers: the drift's offset is removed.
    """

    name = "gps_drift"
    Params = GpsDriftParams

    def validate(self) -> None:
        p = self.p
        self.require_range("rate_m_s", p.rate_m_s, 0.0, unit="m/s")
        vec = np.array(self.vector3("direction_ned", p.direction_ned))
        norm = float(np.linalg.norm(vec))
        if norm == 0.0:
            self.fail("direction_ned must not be the zero vector")
        self.unit = vec / norm
        self.applied = np.zeros((len(self.targets), 3))

    def check(self, env: FaultEnv) -> None:
        env.require_backend(self.name, _OFFSET, "a GNSS offset input")

    def start(self, env: FaultEnv) -> None:
        self._update(env)

    def _update(self, env: FaultEnv) -> None:
        if not self.active:
            return
        elapsed_s = env.now_s() + env.tick_s - self.p.onset_s
        ramp = self.unit * (self.p.rate_m_s * max(elapsed_s, 0.0))
        offsets = env.backend.gnss_offset_ned_m
        for k, drone in enumerate(self.drones()):
            i = env.index(drone)
            offsets[i] += ramp - self.applied[k]
            self.applied[k] = ramp
        env.at(env.now_s() + env.tick_s, lambda: self._update(env))

    def stop(self, env: FaultEnv) -> None:
        offsets = env.backend.gnss_offset_ned_m
        for k, drone in enumerate(self.drones()):
            offsets[env.index(drone)] -= self.applied[k]
            self.applied[k] = 0.0


class GpsBias(Fault):
    """A constant GNSS offset ``bias_ned_m`` from the onset to the end."""

    name = "gps_bias"
    Params = GpsBiasParams

    def validate(self) -> None:
        self.bias = np.array(self.vector3("bias_ned_m", self.p.bias_ned_m))

    def check(self, env: FaultEnv) -> None:
        env.require_backend(self.name, _OFFSET, "a GNSS offset input")

    def start(self, env: FaultEnv) -> None:
        for drone in self.drones():
            env.backend.gnss_offset_ned_m[env.index(drone)] += self.bias

    def stop(self, env: FaultEnv) -> None:
        for drone in self.drones():
            env.backend.gnss_offset_ned_m[env.index(drone)] -= self.bias


class GpsNoise(Fault):
    """The receiver's noise standard deviation multiplied by ``noise_scale``."""

    name = "gps_noise"
    Params = GpsNoiseParams

    def validate(self) -> None:
        self.require_range("noise_scale", self.p.noise_scale, 0.0)

    def check(self, env: FaultEnv) -> None:
        env.require_backend(self.name, ("gnss_noise_scale",), "a GNSS noise input")

    def start(self, env: FaultEnv) -> None:
        for drone in self.drones():
            env.backend.gnss_noise_scale[env.index(drone)] *= self.p.noise_scale

    def stop(self, env: FaultEnv) -> None:
        scale = env.backend.gnss_noise_scale
        for drone in self.drones():
            i = env.index(drone)
            scale[i] = scale[i] / self.p.noise_scale if self.p.noise_scale else 1.0
            if math.isclose(scale[i], 1.0):
                scale[i] = 1.0


class GpsDropout(Fault):
    """No GNSS fixes at all (the estimator coasts on its inertial prediction).

    On an autopilot backend (``px4``, ``mavsim``: ``inject_failure(i, unit, kind)``) the autopilot
    switches its own receiver off (MAV_CMD_INJECT_FAILURE, GPS, OFF; OK at the end), so its own
    estimator loses GNSS; its answer is a ``fault/inject_*`` event of that drone.
    """

    name = "gps_dropout"
    Params = GpsDropoutParams

    def check(self, env: FaultEnv) -> None:
        self.autopilot = not hasattr(env.backend, "gnss_available") and hasattr(env.backend, "inject_failure")
        if not self.autopilot:
            env.require_backend(self.name, ("gnss_available",), "a GNSS availability input")

    def start(self, env: FaultEnv) -> None:
        for drone in self.drones():
            if self.autopilot:
                env.backend.inject_failure(env.index(drone), "gps", "off")
            else:
                env.backend.gnss_available[env.index(drone)] = False

    def stop(self, env: FaultEnv) -> None:
        for drone in self.drones():
            if self.autopilot:
                env.backend.inject_failure(env.index(drone), "gps", "ok")
            else:
                env.backend.gnss_available[env.index(drone)] = True
