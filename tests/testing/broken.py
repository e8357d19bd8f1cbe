"""Three deliberately broken algorithms: the conformance suite must reject each, saying why."""

import random

from swarmbox.api import DroneAlgorithm, Setpoint


class UnseededDrone(DroneAlgorithm):
    """Draws its altitude from the global, unseeded ``random`` instead of ``ctx.rng``."""

    def exec_once(self, ctx):
        self.alt = 2.0 + random.random()

    def exec_loop(self, ctx):
        n, e, _ = ctx.home_ned_m
        return Setpoint.position(n, e, -self.alt)

    def exec_complete(self, ctx):
        return ctx.stage_time_s > 3.0


class TupleSetpointDrone(DroneAlgorithm):
    """Returns a bare tuple from ``exec_loop`` instead of a Setpoint."""

    def exec_loop(self, ctx):
        n, e, _ = ctx.home_ned_m
        return (n, e, -2.0)

    def exec_complete(self, ctx):
        return ctx.stage_time_s > 3.0


class NeverDoneDrone(DroneAlgorithm):
    """Never reports EXECUTION complete: only the stage timeout ends the mission."""

    def exec_loop(self, ctx):
        n, e, _ = ctx.home_ned_m
        return Setpoint.position(n, e, -2.0)

    def exec_complete(self, ctx):
        return False
