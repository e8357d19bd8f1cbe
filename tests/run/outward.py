"""Algorithms that fly out of the envelope on purpose: the safety monitor has to keep them in."""

import math

from swarmbox.api import DroneAlgorithm, Setpoint


class OutwardDrone(DroneAlgorithm):
    """Commands ``params.kind`` (velocity | acceleration) ``params.vector`` (NED) every tick for
    ``params.fly_s`` seconds of EXECUTION, then reports complete. Drone ``i`` turns the horizontal
    part by ``i * params.turn_deg`` (so that drones leave in different directions, not into each other)."""

    def exec_once(self, ctx):
        n, e, d = (float(x) for x in ctx.params["vector"])
        turn = math.radians(ctx.id * float(ctx.params.get("turn_deg", 0.0)))
        c, s = math.cos(turn), math.sin(turn)
        make = Setpoint.velocity if ctx.params["kind"] == "velocity" else Setpoint.acceleration
        self.setpoint = make(c * n - s * e, s * n + c * e, d)

    def exec_loop(self, ctx):
        return self.setpoint

    def exec_complete(self, ctx):
        return ctx.stage_time_s >= float(ctx.params["fly_s"])


class OnceOutwardDrone(OutwardDrone):
    """Sends its velocity or acceleration for the first 2 s only, then returns None: the vehicle keeps
    flying it."""

    def exec_loop(self, ctx):
        return self.setpoint if ctx.stage_time_s < 2.0 else None
