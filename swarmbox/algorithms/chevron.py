"""Chevron (paper RQ5 case 3, leader-follower): a V formation that follows its leader.

The ground commands only the leader: it streams the leader's path (hold above home, then
``laps`` turns of a circle of ``radius_m`` at ``speed_m_s``, then back to the launch point) with
its heading and velocity. The leader relays *its own reported state* — estimated position,
velocity, heading and yaw rate — to its inferiors every tick. Each follower keeps its launch
offset from the leader's launch point, rotated by the leader's heading, around the leader's
reported position; it flies there with a velocity setpoint: the slot's own velocity (leader
velocity plus the rotation of the offset) as feed-forward plus a proportional correction. A
follower with inferiors of its own relays the leader's state unchanged, so chains and trees of
followers work too.

Phases (the task ``code``): ``HOLD`` hover above home, ``FOLLOW`` fly the formation,
``RETURN`` the leader is back over its launch point with heading 0 (the formation settles back
over the launch grid; a drone completes there).

Params (``conf/algo/chevron.yaml``): ``leader`` leader id, ``altitude_m``, ``start_s`` hold time
before the circle, ``radius_m``, ``speed_m_s`` leader speed on the circle (a mission may set both
with ``values: {0: [radius_m, speed_m_s]}``, sizing the circle to its formation), ``laps``, ``gain_1_s``
proportional gain of the tracking law (1/s), ``max_speed_m_s`` speed limit of the tracking law,
``ramp_s`` time to reach (and to leave) the circle speed,
``yaw_rate_tau_s`` time constant of the leader's yaw-rate filter, ``marker_period_s`` period of
each follower's ``formation_error`` marker, ``home_tolerance_m`` completion tolerance.

Differences from the reference implementation (ref-algorithms §10, §15): followers place
themselves around the leader's reported position and heading, not around the commanded target
with a bearing-to-target yaw (which is noisy when the target is close, and which the paper's
description does not match); the circle is exactly ``laps`` × 2π; its speed is a parameter, and
the defaults keep the tail of a 36-drone chevron below 8 m/s (the reference's 6.7 m/s leader made
the outer tail need ~16 m/s, above PX4's limit); the tracking law adds velocity feed-forward,
so the formation error does not grow with speed; completion is by phase and position, not by a
fixed tick count plus a per-axis proximity that could fire early.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from swarmbox.api import (
    DroneAlgorithm,
    DroneContext,
    GroundAlgorithm,
    GroundContext,
    Setpoint,
    Task,
    wrap_angle,
)

HOLD, FOLLOW, RETURN = 0, 1, 2
Vec2 = tuple[float, float]


def circle_angle(t_s: float, omega: float, total_rad: float, ramp_s: float) -> tuple[float, float]:
    """Angle and angular rate along the circle ``t_s`` after its start: a trapezoidal profile that
    accelerates to ``omega`` over ``ramp_s`` and slows down to stop after ``total_rad``."""
    ramp_s = min(ramp_s, total_rad / omega)
    end_s = total_rad / omega + ramp_s
    if t_s < ramp_s:
        return omega * t_s * t_s / (2 * ramp_s), omega * t_s / ramp_s
    if t_s < end_s - ramp_s:
        return omega * (t_s - ramp_s / 2), omega
    left = max(0.0, end_s - t_s)
    return total_rad - omega * left * left / (2 * ramp_s), omega * left / ramp_s


def circle_point(p: dict, t_s: float, origin: Vec2) -> tuple[int, Vec2, float, Vec2]:
    """The leader's commanded (phase, position, heading, velocity) ``t_s`` into EXECUTION.

    The circle starts at ``origin`` heading north and turns left around ``origin`` - (0, radius).
    """
    r, v, ramp = float(p["radius_m"]), float(p["speed_m_s"]), float(p["ramp_s"])
    omega, total = v / r, 2 * math.pi * float(p["laps"])
    tau = t_s - float(p["start_s"])
    if tau < 0:
        return HOLD, origin, 0.0, (0.0, 0.0)
    if tau >= total / omega + min(ramp, total / omega):
        return RETURN, origin, 0.0, (0.0, 0.0)
    theta, rate = circle_angle(tau, omega, total, ramp)
    s, c = math.sin(theta), math.cos(theta)
    pos = (origin[0] + r * s, origin[1] + r * c - r)
    return FOLLOW, pos, wrap_angle(-theta), (r * rate * c, -r * rate * s)


def rotate(vec: Vec2, yaw_rad: float) -> Vec2:
    """``vec`` (north, east) rotated by a heading ``yaw_rad`` (clockwise seen from above)."""
    c, s = math.cos(yaw_rad), math.sin(yaw_rad)
    return (c * vec[0] - s * vec[1], s * vec[0] + c * vec[1])


def track(ctx: DroneContext, target: Vec2, feed_forward: Vec2, yaw_rad: float) -> Setpoint:
    """Velocity setpoint: ``feed_forward`` + gain × position error, speed-limited; holds altitude."""
    p = ctx.params
    n, e, d = ctx.pos_ned_m
    k = float(p["gain_1_s"])
    vn, ve = feed_forward[0] + k * (target[0] - n), feed_forward[1] + k * (target[1] - e)
    speed, limit = math.hypot(vn, ve), float(p["max_speed_m_s"])
    if speed > limit:
        vn, ve = vn * limit / speed, ve * limit / speed
    vd = max(-2.0, min(1.0, 1.0 * (-float(p["altitude_m"]) - d)))
    return Setpoint.velocity(vn, ve, vd, yaw_rad)


@dataclass
class ChevronParams:
    """Typed ``params`` (see ``conf/algo/chevron.yaml``)."""

    leader: int = 0
    altitude_m: float = 10.0
    start_s: float = 15.0   # hover above home this long before the circle starts
    radius_m: float = 60.0   # the leader's circle (centre 60 m west of the leader's launch point)
    speed_m_s: float = 3.0   # leader speed on the circle: 0.05 rad/s, the 36-drone tail below 8 m/s
    laps: float = 1.0
    ramp_s: float = 8.0   # speed up to (and slow down from) speed_m_s over this long
    gain_1_s: float = 1.5   # tracking law: v = v_slot + gain x position error
    max_speed_m_s: float = 11.0
    yaw_rate_tau_s: float = 0.5   # low-pass time constant of the leader's yaw rate
    marker_period_s: float = 1.0   # each follower marks its formation error this often
    home_tolerance_m: float = 1.0   # completion: back over the launch point (horizontal, m)


class ChevronGround(GroundAlgorithm):
    """Streams the leader's path to the leader (and to nobody else)."""

    Params = ChevronParams

    def exec_once(self, ctx: GroundContext) -> None:
        self.path = dict(ctx.params)
        if 0 in ctx.mission.values:   # the mission may size the circle to its formation
            self.path["radius_m"], self.path["speed_m_s"] = ctx.mission.values[0][:2]

    def exec_loop(self, ctx: GroundContext) -> None:
        leader = int(ctx.params["leader"])
        if leader not in ctx.reports:
            return
        origin = ctx.mission.initial_positions[leader][:2]
        phase, pos, yaw, vel = circle_point(self.path, ctx.stage_time_s, origin)
        ctx.send_task(leader, code=phase, waypoint_ned_m=(*pos, -float(ctx.params["altitude_m"])),
                      yaw_rad=yaw, data=f"{vel[0]:.3f},{vel[1]:.3f}", reliable=False)


class ChevronDrone(DroneAlgorithm):
    """The leader flies the ground's path and relays its own state; followers keep their slots."""

    Params = ChevronParams

    def exec_once(self, ctx: DroneContext) -> None:
        p = ctx.params
        self.leader = int(p["leader"])
        ln, le, _ = ctx.mission.initial_positions[self.leader]
        hn, he, _ = ctx.home_ned_m
        self.offset = (hn - ln, he - le)
        self.next_mark_s = 0.0
        self.yaw_rate = 0.0
        self.last_yaw: float | None = None
        self.phase = HOLD
        self.settled = False

    def on_task(self, ctx: DroneContext, task: Task) -> None:
        if ctx.id != self.leader:   # a follower relays the leader's state down its own subtree
            for drone in ctx.inferiors:
                ctx.send_task(drone, code=task.code, waypoint_ned_m=task.waypoint_ned_m,
                              yaw_rad=task.yaw_rad, data=task.data, reliable=False)

    def exec_loop(self, ctx: DroneContext) -> Setpoint:
        task = ctx.last_task
        if ctx.id == self.leader:
            self._relay_own_state(ctx)
        if task is None or task.code == HOLD or task.waypoint_ned_m is None:
            hn, he, _ = ctx.home_ned_m
            return Setpoint.position(hn, he, -float(ctx.params["altitude_m"]), 0.0)
        self.phase = task.code
        ff = tuple(float(x) for x in task.data.split(","))
        if ctx.id == self.leader:
            sp = track(ctx, task.waypoint_ned_m[:2], ff[:2], task.yaw_rad)
        else:
            sp = self._follow(ctx, task, ff)
        self.settled = self.phase == RETURN and self._at_home(ctx)
        return sp

    def _follow(self, ctx: DroneContext, task: Task, ff: tuple[float, ...]) -> Setpoint:
        psi = task.yaw_rad or 0.0
        slot = rotate(self.offset, psi)
        ln, le, _ = task.waypoint_ned_m
        target = (ln + slot[0], le + slot[1])
        vn, ve, rate = ff
        feed_forward = (vn - rate * slot[1], ve + rate * slot[0])   # v_leader + ω × slot
        if ctx.stage_time_s >= self.next_mark_s and task.code == FOLLOW:
            self.next_mark_s = ctx.stage_time_s + float(ctx.params["marker_period_s"])
            n, e, _ = ctx.pos_ned_m
            ctx.mark("formation_error", error_m=round(math.hypot(n - target[0], e - target[1]), 4))
        return track(ctx, target, feed_forward, psi)

    def _relay_own_state(self, ctx: DroneContext) -> None:
        """Send the leader's reported state (position, velocity, heading, yaw rate) to its inferiors."""
        tel = ctx.state
        if self.last_yaw is not None:
            raw = wrap_angle(tel.yaw_rad - self.last_yaw) / ctx.tick_s
            alpha = ctx.tick_s / (float(ctx.params["yaw_rate_tau_s"]) + ctx.tick_s)
            self.yaw_rate += alpha * (raw - self.yaw_rate)
        self.last_yaw = tel.yaw_rad
        task = ctx.last_task
        code = HOLD if task is None else task.code
        data = f"{tel.vel_ned_m_s[0]:.3f},{tel.vel_ned_m_s[1]:.3f},{self.yaw_rate:.5f}"
        for drone in ctx.inferiors:
            ctx.send_task(drone, code=code, waypoint_ned_m=tel.pos_ned_m, yaw_rad=tel.yaw_rad, data=data,
                          reliable=False)

    def _at_home(self, ctx: DroneContext) -> bool:
        (n, e, _), (hn, he, _) = ctx.pos_ned_m, ctx.home_ned_m
        vn, ve, _ = ctx.vel_ned_m_s
        return math.hypot(n - hn, e - he) < float(ctx.params["home_tolerance_m"]) and math.hypot(vn, ve) < 0.5

    def exec_complete(self, ctx: DroneContext) -> bool:
        return self.settled
