"""Hover: take off above home, hold for a while, land. The smallest complete algorithm.

:class:`HoverDrone` is the per-drone version; :class:`HoverFleet` the same algorithm written over the
whole fleet at once (the batch API, ``swarmbox.api.fleet``).
"""

from dataclasses import dataclass

import numpy as np

from swarmbox.api import (
    DroneAlgorithm,
    DroneContext,
    Fleet,
    FleetAlgorithm,
    FleetSetpoints,
    Setpoint,
    row_norms,
)


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


class HoverFleet(FleetAlgorithm):
    """:class:`HoverDrone` over the whole fleet at once (``algo=hover_batch``): the same logs."""

    Params = HoverParams

    def setup(self, fleet: Fleet) -> None:
        target = fleet.home_ned_m.copy()
        target[:, 2] = -float(fleet.params["altitude_m"])
        self.target, self.hover_s = target, float(fleet.params["hover_s"])
        self.reached_at_s = np.full(fleet.n, np.nan)   # NaN: not at altitude yet
        self.setpoints = FleetSetpoints.position(target)   # the same every tick

    def exec_once(self, fleet: Fleet, rows: np.ndarray) -> None:
        self.reached_at_s[rows] = np.nan

    def exec_loop(self, fleet: Fleet, rows: np.ndarray) -> FleetSetpoints:
        waiting = rows[np.isnan(self.reached_at_s[rows])]
        if waiting.size:   # ctx.has_reached(target, d_m=0.3): within 0.3 m and slower than 0.7 m/s
            pos = fleet.pos_ned_m[waiting]
            near = row_norms(pos - self.target[waiting], 0.3) <= 0.3
            slow = row_norms(fleet.vel_ned_m_s[waiting], 0.7) <= 0.7
            for i in waiting[near & slow].tolist():
                self.reached_at_s[i] = fleet.stage_time_s[i]
                fleet.ctx(i).mark("reached_altitude", altitude_m=-float(fleet.pos_ned_m[i, 2]))
        return self.setpoints

    def exec_complete(self, fleet: Fleet, rows: np.ndarray) -> np.ndarray:
        with np.errstate(invalid="ignore"):   # NaN (not reached) compares False
            return fleet.stage_time_s - self.reached_at_s >= self.hover_s
