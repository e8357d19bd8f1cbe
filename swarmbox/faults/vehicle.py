"""Vehicle faults: crash, motor/thrust loss, battery failsafe.

- ``crash``: the drone stops responding — its companion computer dies (the node is removed from
  the swarm and its radio falls silent) and the vehicle crashes (motors off, it falls, telemetry
  freezes). Needs the backend's ``crashed`` input. Permanent.
- ``motor_loss``: the vehicle's achievable acceleration (horizontal and upward) is scaled by
  ``accel_scale`` through the backend's ``accel_scale`` input; restored at the end.
- ``battery_failsafe``: the autopilot's low-battery failsafe — the drone leaves the mission and
  returns to launch, then lands (the agent aborts with the failsafe flag, which commands RTL).
  Uses only the ``Vehicle`` protocol, so every backend can express it. Permanent.
"""

from __future__ import annotations

from dataclasses import dataclass

from swarmbox.core.stages import TERMINAL, Stage
from swarmbox.faults.base import Fault, FaultEnv, FaultParams


@dataclass
class CrashParams(FaultParams):
    pass


@dataclass
class MotorLossParams(FaultParams):
    accel_scale: float = 0.3   # fraction of the nominal acceleration limits left, in [0, 1]


@dataclass
class BatteryFailsafeParams(FaultParams):
    pass


class Crash(Fault):
    """Node removed and vehicle crashed at the onset."""

    name = "crash"
    Params = CrashParams
    permanent = True

    def check(self, env: FaultEnv) -> None:
        env.require_backend(self.name, ("crashed",), "a crash input")

    def start(self, env: FaultEnv) -> None:
        for drone in self.drones():
            if not env.agent(drone).removed:
                env.swarm.remove_agent(drone)
            env.backend.crashed[env.index(drone)] = True


class MotorLoss(Fault):
    """Acceleration limits scaled by ``accel_scale`` during the window."""

    name = "motor_loss"
    Params = MotorLossParams

    def validate(self) -> None:
        self.require_range("accel_scale", self.p.accel_scale, 0.0, 1.0)

    def check(self, env: FaultEnv) -> None:
        env.require_backend(self.name, ("accel_scale",), "a thrust (acceleration scale) input")

    def start(self, env: FaultEnv) -> None:
        self._before = {d: float(env.backend.accel_scale[env.index(d)]) for d in self.drones()}
        for drone in self.drones():
            env.backend.accel_scale[env.index(drone)] *= self.p.accel_scale

    def stop(self, env: FaultEnv) -> None:
        for drone, scale in self._before.items():
            env.backend.accel_scale[env.index(drone)] = scale


class BatteryFailsafe(Fault):
    """Forced return-to-launch and landing, as a low-battery failsafe does."""

    name = "battery_failsafe"
    Params = BatteryFailsafeParams
    permanent = True

    def start(self, env: FaultEnv) -> None:
        for drone in self.drones():
            agent = env.agent(drone)
            if agent.removed or agent.stage in TERMINAL:
                continue
            agent.event("failsafe", "battery_low", drone, action="return_to_launch")
            agent.enter(Stage.ABORT, "battery failsafe: return to launch", failsafe=True)
