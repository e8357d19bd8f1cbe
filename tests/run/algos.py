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


class BadSetpointDrone(DroneAlgorithm):
    """After 2 s of EXECUTION, commands what ``ctx.params['bad']`` names: nan_position | far | fast."""

    def exec_loop(self, ctx):
        n, e, _ = ctx.home_ned_m
        if ctx.stage_time_s < 2.0:
            return Setpoint.position(n, e, -2.0)
        bad = ctx.params["bad"]
        if bad == "nan_position":
            return Setpoint.position(float("nan"), e, -2.0)
        if bad == "far":
            return Setpoint.position(1e9, e, -2.0)
        return Setpoint.velocity(500.0, 0.0, 0.0)

    def exec_complete(self, ctx):
        return ctx.stage_time_s > 4.0


class TupleDrone(DroneAlgorithm):
    """exec_loop returns a tuple instead of a Setpoint."""

    def exec_loop(self, ctx):
        return (0.0, 0.0, -2.0)

    def exec_complete(self, ctx):
        return False


class HangingDrone(DroneAlgorithm):
    """Drone 1's exec_loop never returns after 1 s of EXECUTION: ``params.hang`` = sleep | spin."""

    def exec_loop(self, ctx):
        if ctx.id == 1 and ctx.stage_time_s > 1.0:
            if ctx.params.get("hang") == "sleep":
                import time
                time.sleep(1e6)
            while True:
                try:
                    pass
                except Exception:   # a hook that swallows errors must still be stopped
                    pass
        n, e, _ = ctx.home_ned_m
        return Setpoint.position(n, e, -2.0)

    def exec_complete(self, ctx):
        return False


class SlowDrone(DroneAlgorithm):
    """Every exec_loop call takes ``params.delay_s`` of wall time (a long run to interrupt)."""

    def exec_loop(self, ctx):
        import time
        time.sleep(ctx.params.get("delay_s", 0.002))
        n, e, _ = ctx.home_ned_m
        return Setpoint.position(n, e, -2.0)

    def exec_complete(self, ctx):
        return ctx.stage_time_s > ctx.params.get("hover_s", 5.0)


class OneCrashingDrone(DroneAlgorithm):
    """Drone 1 raises 1 s into EXECUTION; the others hover ``params.hover_s`` and complete."""

    def exec_loop(self, ctx):
        if ctx.id == 1 and ctx.stage_time_s > 1.0:
            raise ZeroDivisionError("deliberate failure in drone 1's exec_loop")
        n, e, _ = ctx.home_ned_m
        return Setpoint.position(n, e, -2.0)

    def exec_complete(self, ctx):
        return ctx.stage_time_s > ctx.params.get("hover_s", 5.0)


class WaitingDrone(DroneAlgorithm):
    """Holds its first exec_loop until the file ``params.flag`` exists (a run kept in flight while a
    test does something beside it; needs ``run.hook_timeout_s=null``), then hovers ``hover_s``."""

    def exec_loop(self, ctx):
        import time
        from pathlib import Path

        while not Path(ctx.params["flag"]).exists():
            time.sleep(0.05)
        n, e, _ = ctx.home_ned_m
        return Setpoint.position(n, e, -2.0)

    def exec_complete(self, ctx):
        return ctx.stage_time_s > ctx.params.get("hover_s", 5.0)
