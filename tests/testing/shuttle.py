"""The worked example of docs/algorithms.md, verbatim (a test flies it through the suite)."""

from dataclasses import dataclass

from swarmbox.api import DroneAlgorithm, GroundAlgorithm, Setpoint

GOTO = 1

@dataclass
class ShuttleParams:
    altitude_m: float = 4.0
    spacing_m: float = 6.0

class ShuttleGround(GroundAlgorithm):
    Params = ShuttleParams

    def prep_once(self, ctx):                    # tick 0 of PREPARATION: every drone has joined
        for k, drone in enumerate(sorted(ctx.reports)):
            ctx.send_task(drone, code=GOTO, waypoint_ned_m=(ctx.params["spacing_m"] * k, 10.0,
                                                            -ctx.params["altitude_m"]))

class ShuttleDrone(DroneAlgorithm):
    Params = ShuttleParams

    def prep_once(self, ctx):                    # always runs before the first on_task
        self.targets = []

    def on_task(self, ctx, task):                # reliable: once each, in send order
        if task.code == GOTO:
            self.targets.append(task.waypoint_ned_m)

    def prep_complete(self, ctx):                # hold PREPARATION until the assignment arrived
        return bool(self.targets) and ctx.state.ready_to_arm

    def exec_loop(self, ctx):
        return Setpoint.position(*self.targets[-1])

    def exec_complete(self, ctx):
        return ctx.has_reached(self.targets[-1])
