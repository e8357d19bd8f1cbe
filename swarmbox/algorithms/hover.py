"""Hover: take off above home, hold for a while, land. The smallest complete algorithm."""

from dataclasses import dataclass

from swarmbox.api import DroneAlgorithm, DroneContext, Setpoint


@dataclass
class HoverParams:
    """Typed ``params`` (see ``conf/algo/hover.yaml``)."""

    altitude_m: float = 3.0
    hover_s: float = 5.0   # seconds at altitude before reporting complete


class HoverDrone(DroneAlgorithm):
    """Params: ``altitude_m`` (above home), ``hover_s`` (time at altitude before completing)."""

    Params = HoverParams

    def exec_once(self, ctx: DroneContext) -> None:
        n, e, _ = ctx.home_ned_m
        self.target = (n, e, -float(ctx.params["altitude_m"]))
        self.setpoint = Setpoint.position(*self.target)   # the same every tick
        self.hover_s = float(ctx.params["hover_s"])
        self.reached_at_s: float | None = None

    def exec_loop(self, ctx: DroneContext) -> Setpoint:
        if self.reached_at_s is None and ctx.has_reached(self.target, d_m=0.3):
            self.reached_at_s = ctx.stage_time_s
            ctx.mark("reached_altitude", altitude_m=-ctx.pos_ned_m[2])
        return self.setpoint

    def exec_complete(self, ctx: DroneContext) -> bool:
        return self.reached_at_s is not None and ctx.stage_time_s - self.reached_at_s >= self.hover_s
