"""Misbehaving algorithms for failure-path tests."""

from swarmbox.api import DroneAlgorithm, Setpoint


class CrashingDrone(DroneAlgorithm):
    """Flies up, then raises inside exec_loop after 2 s of EXECUTION."""

    def exec_loop(self, ctx):
        if ctx.stage_time_s > 2.0:
            raise ZeroDivisionError("deliberate failure in exec_loop")
        n, e, _ = ctx.home_ned_m
        return Setpoint.position(n, e, -2.0)

    def exec_complete(self, ctx):
        return False


class NeverDoneDrone(DroneAlgorithm):
    """Hovers forever: the EXECUTION timeout has to end the mission."""

    def exec_loop(self, ctx):
        n, e, _ = ctx.home_ned_m
        return Setpoint.position(n, e, -2.0)

    def exec_complete(self, ctx):
        return False
