"""Crossing: drones fly straight lines across each other's paths, for proximity alerts.

Each drone climbs above its home, waits until ``depart_s`` into EXECUTION (so that all leave
together), flies at ``speed_m_s`` to its target and holds there. Targets and altitudes come from the
mission's ``values``: ``[target_n_m, target_e_m, altitude_m]`` per drone. The ground's ProxAlerts
reach ``on_prox_alert``; the drone marks each new neighbour once (``near_miss_warning``), which is
how an avoidance algorithm would hook in.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from swarmbox.api import DescendantState, DroneAlgorithm, DroneContext, Setpoint


@dataclass
class CrossingParams:
    """Typed ``params`` (see ``conf/algo/crossing.yaml``)."""

    speed_m_s: float = 4.0   # m/s, cruise speed along the straight line
    depart_s: float = 6.0    # s into EXECUTION: every drone leaves its climb point together


class CrossingDrone(DroneAlgorithm):
    """Params: ``speed_m_s`` (cruise), ``depart_s`` (s of EXECUTION before leaving)."""

    Params = CrossingParams

    def exec_once(self, ctx: DroneContext) -> None:
        tn, te, alt = ctx.mission.values[ctx.id][:3]
        n, e, _ = ctx.home_ned_m
        self.start = (n, e, -float(alt))
        self.target = (float(tn), float(te), -float(alt))
        self.warned: set[int] = set()

    def exec_loop(self, ctx: DroneContext) -> Setpoint:
        if ctx.stage_time_s < float(ctx.params["depart_s"]):
            return Setpoint.position(*self.start)
        p = ctx.pos_ned_m
        dn, de = self.target[0] - p[0], self.target[1] - p[1]
        dist = math.hypot(dn, de)
        speed = float(ctx.params["speed_m_s"])
        if dist < speed * 1.0:   # within a second of the target: let the position loop settle it
            return Setpoint.position(*self.target)
        return Setpoint.velocity(speed * dn / dist, speed * de / dist, (self.target[2] - p[2]))

    def exec_complete(self, ctx: DroneContext) -> bool:
        return ctx.has_reached(self.target, d_m=0.5)

    def on_prox_alert(self, ctx: DroneContext, neighbours: tuple[DescendantState, ...]) -> None:
        for other in neighbours:
            if other.drone_id not in self.warned:
                self.warned.add(other.drone_id)
                ctx.mark("near_miss_warning", other=other.drone_id,
                         distance_m=round(math.dist(ctx.pos_ned_m, other.pos_ned_m), 2))
