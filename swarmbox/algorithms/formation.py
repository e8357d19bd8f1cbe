"""Formation flight (paper RQ2): a virtual leader flies a circle; every drone keeps its launch
offset from the leader's launch point, rotated with the leader's heading.

The ground computes the virtual leader's waypoint and heading every tick and streams it to its
direct inferiors; a drone that has inferiors relays it to them, so the same code flies under every
topology (centralized, leader-follower, chain, tree). Before ``start_s`` the ground sends code 0
(hold above home); during the circle code 1 (follow); afterwards the leader point is the origin.

Differences from the reference implementation: the offsets are taken relative to the leader's
launch point (the reference used raw launch coordinates, the same thing when the leader launches
at the origin), and the circle ends after exactly ``laps`` turns of 2π.

:class:`FormationDrone` is the per-drone version; :class:`FormationFleet` the same drone side written
over the whole fleet at once (the batch API); both fly under :class:`FormationGround`.
"""

import math
from dataclasses import dataclass

import numpy as np

from swarmbox.api import (
    DroneAlgorithm,
    DroneContext,
    Fleet,
    FleetAlgorithm,
    FleetSetpoints,
    GroundAlgorithm,
    GroundContext,
    Setpoint,
    Task,
    wrap_angle,
)

HOLD, FOLLOW = 0, 1


@dataclass
class FormationParams:
    """Typed ``params`` (see ``conf/algo/formation.yaml``)."""

    leader: int = 0   # whose launch point is the formation's reference
    radius_m: float = 9.0   # circle radius
    altitude_m: float = 3.0
    start_s: float = 30.0   # EXECUTION time at which the circle starts (hold before)
    angular_rate_rad_s: float = 0.13333   # 40/300 rad/s: one lap in ~47 s at ~1.2 m/s
    laps: float = 1.0
    complete_after_s: float = 50.0   # a drone is done after this long, once back within tolerance of home
    home_tolerance_m: float = 1.0   # per axis (north, east)


class FormationGround(GroundAlgorithm):
    Params = FormationParams

    def exec_loop(self, ctx: GroundContext) -> None:
        p = ctx.params
        r, alt = float(p["radius_m"]), float(p["altitude_m"])
        theta = (ctx.stage_time_s - float(p["start_s"])) * float(p["angular_rate_rad_s"])
        if theta < 0:
            code, wp, yaw = HOLD, (0.0, 0.0, -alt), 0.0
        elif theta < 2 * math.pi * float(p["laps"]):
            code, wp, yaw = FOLLOW, (r * math.sin(theta), r * math.cos(theta) - r, -alt), wrap_angle(-theta)
        else:
            code, wp, yaw = FOLLOW, (0.0, 0.0, -alt), 0.0
        for drone in ctx.reports:
            ctx.send_task(drone, code=code, waypoint_ned_m=wp, yaw_rad=yaw, reliable=False)


class FormationDrone(DroneAlgorithm):
    Params = FormationParams

    def exec_once(self, ctx: DroneContext) -> None:
        ln, le, _ = ctx.mission.initial_positions[int(ctx.params["leader"])]
        hn, he, _ = ctx.home_ned_m
        self.offset = (hn - ln, he - le)
        self.next_mark_s = 0.0

    def exec_loop(self, ctx: DroneContext) -> Setpoint:
        task, alt = ctx.last_task, float(ctx.params["altitude_m"])
        for drone in ctx.inferiors:  # relay the leader's waypoint down the hierarchy
            if task is not None:
                ctx.send_task(drone, code=task.code, waypoint_ned_m=task.waypoint_ned_m,
                              yaw_rad=task.yaw_rad, data=task.data, reliable=False)
        if task is None or task.code == HOLD or task.waypoint_ned_m is None:
            n, e, _ = ctx.home_ned_m
            return Setpoint.position(n, e, -alt, 0.0)
        psi = task.yaw_rad or 0.0
        c, s = math.cos(psi), math.sin(psi)
        on, oe = self.offset
        wn, we, wd = task.waypoint_ned_m
        target = (wn + c * on - s * oe, we + s * on + c * oe, wd)
        if ctx.stage_time_s >= self.next_mark_s:
            self.next_mark_s = ctx.stage_time_s + 1.0
            ctx.mark("formation_error", error_m=math.dist(ctx.pos_ned_m, target))
        return Setpoint.position(*target, psi)

    def exec_complete(self, ctx: DroneContext) -> bool:
        p = ctx.params
        if ctx.stage_time_s <= float(p["complete_after_s"]):
            return False
        tol = float(p["home_tolerance_m"])
        (n, e, _), (hn, he, _) = ctx.pos_ned_m, ctx.home_ned_m
        return abs(n - hn) < tol and abs(e - he) < tol


class FormationFleet(FleetAlgorithm):
    """:class:`FormationDrone` over the whole fleet at once (``algo=formation_batch``): the same logs.

    Each drone's latest task is kept in arrays (``on_task``); the targets of every following drone
    are one numpy expression, in the per-drone code's order of operations.
    """

    Params = FormationParams

    def setup(self, fleet: Fleet) -> None:
        p = fleet.params
        ln, le, _ = fleet.mission.initial_positions[int(p["leader"])]
        self.offset = fleet.home_ned_m[:, :2] - (ln, le)
        self.alt = float(p["altitude_m"])
        self.hold = fleet.home_ned_m.copy()
        self.hold[:, 2] = -self.alt
        self.code = np.full(fleet.n, -1)            # the latest task's code (-1: none yet)
        self.waypoint = np.zeros((fleet.n, 3))      # ... its waypoint
        self.has_waypoint = np.zeros(fleet.n, dtype=bool)
        self.psi = np.zeros(fleet.n)                # ... its yaw, None as 0.0
        self.next_mark_s = np.zeros(fleet.n)

    def on_task(self, fleet: Fleet, i: int, task: Task) -> None:
        self.code[i] = task.code
        self.has_waypoint[i] = task.waypoint_ned_m is not None
        if task.waypoint_ned_m is not None:
            self.waypoint[i] = task.waypoint_ned_m
        self.psi[i] = task.yaw_rad or 0.0

    def exec_once(self, fleet: Fleet, rows: np.ndarray) -> None:
        self.next_mark_s[rows] = 0.0

    def exec_loop(self, fleet: Fleet, rows: np.ndarray) -> FleetSetpoints:
        for i in rows.tolist():   # relay the leader's waypoint down the hierarchy
            ctx = fleet.ctx(i)
            task = ctx.last_task
            if task is not None:
                for drone in ctx.inferiors:
                    ctx.send_task(drone, code=task.code, waypoint_ned_m=task.waypoint_ned_m,
                                  yaw_rad=task.yaw_rad, data=task.data, reliable=False)
        ned, yaw = self.hold.copy(), np.zeros(fleet.n)
        follow = rows[(self.code[rows] > HOLD) & self.has_waypoint[rows]]   # a task, not HOLD
        if follow.size:
            psi = self.psi[follow]
            # math.cos/sin, as the per-drone code: numpy's may differ in the last bit (few distinct yaws)
            trig = {a: (math.cos(a), math.sin(a)) for a in set(psi.tolist())}
            c = np.array([trig[a][0] for a in psi.tolist()])
            s = np.array([trig[a][1] for a in psi.tolist()])
            (on, oe), w = self.offset[follow].T, self.waypoint[follow]
            target = np.column_stack((w[:, 0] + c * on - s * oe, w[:, 1] + s * on + c * oe, w[:, 2]))
            ned[follow], yaw[follow] = target, psi
            self._mark(fleet, follow, target)
        return FleetSetpoints.position(ned, yaw)

    def _mark(self, fleet: Fleet, follow: np.ndarray, target: np.ndarray) -> None:
        now = fleet.stage_time_s[follow]
        due = now >= self.next_mark_s[follow]
        self.next_mark_s[follow[due]] = now[due] + 1.0
        pos = fleet.pos_ned_m
        for i, t in zip(follow[due].tolist(), target[due].tolist(), strict=True):
            fleet.ctx(i).mark("formation_error", error_m=math.dist(pos[i].tolist(), t))

    def exec_complete(self, fleet: Fleet, rows: np.ndarray) -> np.ndarray:
        p = fleet.params
        tol = float(p["home_tolerance_m"])
        off = np.abs(fleet.pos_ned_m[:, :2] - fleet.home_ned_m[:, :2]) < tol
        return (fleet.stage_time_s > float(p["complete_after_s"])) & off[:, 0] & off[:, 1]
