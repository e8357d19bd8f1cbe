"""Tracking (paper RQ5 case 5, centralized): one active tracker pursues a non-cooperative moving
target; sector sentinels wait at standby points and join the tracker when the target enters
their sector (an event-triggered rendezvous).

The ground owns every decision. At PREPARATION it gives each drone its role with one reliable
task: the ``tracker`` (params) waits over the area's centre; every other drone becomes a
sentinel of one sector of a rows × cols grid over the area, with a standby point in that sector.
In EXECUTION the ground moves the target (a random-waypoint walk at ``target_speed_m_s`` drawn
from its seeded ``rng``, appearing after ``start_s``) and streams, every tick, to each *active*
drone its slot on a ring around the target plus the target's velocity. The active drones are the
tracker and the sentinels of the target's current sector: when the target enters a new sector the
ground marks ``sector_entry``, sends the previous sector's sentinels back to standby (reliable),
and starts streaming to the new sector's sentinels; it marks ``rendezvous`` (with the delay since
the entry) once all of them are within ``rendezvous_m`` of their slots. It also marks
``tracking`` every second: the tracker's reported distance to the target, and the target's position.

Codes: ``ROLE`` (PREPARATION; data "tracker" or "sentinel:<sector>", waypoint = standby point),
``STANDBY`` (waypoint = standby point), ``ACTIVE`` (waypoint = slot, data = target velocity).

Mission data: ``values`` ``0: [north_min, east_min]``, ``1: [north_max, east_max]`` (the area),
``2: [rows, cols]`` (the sector grid).

Params (``conf/algo/tracking.yaml``): ``tracker`` id, ``altitude_m`` (tracker), ``layer_step_m``
(sentinels fly above it: one altitude per sentinel of a sector, neighbouring sectors on different
altitudes, so returning and joining sentinels never meet), ``start_s``, ``target_speed_m_s``,
``target_margin_m`` (the target stays this far inside the area), ``ring_m`` and
``min_spacing_m`` (ring radius, enlarged so neighbours on the ring keep this spacing),
``standby_frac`` (standby points lie on a circle of this fraction of the sector's half size),
``gain_1_s``, ``max_speed_m_s`` (pursuit law), ``stale_s`` (an active drone holds when the stream
stops for this long), ``rendezvous_m``, ``duration_s``.

Differences from the reference implementation (ref-algorithms §12, §15): roles, sectors and
standby points are computed from the mission's area and the fleet size (the reference indexed a
hard-coded role list by id, with ±50 ± 20 m standby offsets and four quadrants); roles arrive by a
reliable command with the role in ``data`` (not a presence flag); the target is a seeded random
walk at a speed the drones can follow (the reference's Lissajous peaked at 10.5 m/s); the pursuit
uses the target's velocity as feed-forward; sentinels fly on separated altitudes; the rendezvous
is detected and timed, not only implied.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.optimize import linear_sum_assignment

from swarmbox.api import (
    Area,
    DroneAlgorithm,
    DroneContext,
    GroundAlgorithm,
    GroundContext,
    Setpoint,
    Task,
    mission_area,
    mission_grid,
)

ROLE, STANDBY, ACTIVE = 10, 0, 1
Vec2 = tuple[float, float]


def sector_of(pos: Vec2, area: Area, grid: tuple[int, int]) -> int:
    """Sector index (row-major, row = north) of a position, clamped to the grid."""
    n0, e0, n1, e1 = area
    r = min(grid[0] - 1, max(0, int((pos[0] - n0) / (n1 - n0) * grid[0])))
    c = min(grid[1] - 1, max(0, int((pos[1] - e0) / (e1 - e0) * grid[1])))
    return r * grid[1] + c


def standby_points(area: Area, grid: tuple[int, int], counts: list[int], frac: float) -> list[list[Vec2]]:
    """``counts[s]`` points per sector ``s``, evenly on a circle around the sector's centre."""
    n0, e0, n1, e1 = area
    h, w = (n1 - n0) / grid[0], (e1 - e0) / grid[1]
    out = []
    for s, k in enumerate(counts):
        r, c = divmod(s, grid[1])
        cn, ce = n0 + (r + 0.5) * h, e0 + (c + 0.5) * w
        rad = frac * min(h, w) / 2 if k > 1 else 0.0
        out.append([(cn + rad * math.cos(2 * math.pi * j / k), ce + rad * math.sin(2 * math.pi * j / k))
                    for j in range(k)])
    return out


def ring_slots(count: int, ring_m: float, min_spacing_m: float) -> list[Vec2]:
    """Offsets of ``count`` drones evenly on a ring around the target; the first is due south."""
    if count == 1:
        return [(-ring_m, 0.0)]
    radius = max(ring_m, min_spacing_m / (2 * math.sin(math.pi / count)))
    return [(radius * math.cos(math.pi + 2 * math.pi * j / count),
             radius * math.sin(math.pi + 2 * math.pi * j / count)) for j in range(count)]


class RandomWalkTarget:
    """A random-waypoint target: straight legs at constant speed between uniform random points."""

    def __init__(self, rng: np.random.Generator, area: Area, margin_m: float, speed_m_s: float) -> None:
        n0, e0, n1, e1 = area
        self.lo, self.hi = (n0 + margin_m, e0 + margin_m), (n1 - margin_m, e1 - margin_m)
        self.rng, self.speed = rng, speed_m_s
        self.pos = self._draw()
        self.goal = self._draw()

    def _draw(self) -> Vec2:
        n, e = self.rng.uniform(self.lo, self.hi)
        return (float(n), float(e))

    def step(self, dt_s: float) -> Vec2:
        """Advance by ``dt_s``; returns the velocity (m/s) of this step."""
        dn, de = self.goal[0] - self.pos[0], self.goal[1] - self.pos[1]
        dist = math.hypot(dn, de)
        move = self.speed * dt_s
        if dist <= move:
            self.pos, self.goal = self.goal, self._draw()
            return (dn / dt_s, de / dt_s)
        self.pos = (self.pos[0] + dn / dist * move, self.pos[1] + de / dist * move)
        return (dn / dist * self.speed, de / dist * self.speed)


@dataclass
class TrackingParams:
    """Typed ``params`` (see ``conf/algo/tracking.yaml``)."""

    tracker: int = 0   # the active tracker; every other drone is a sector sentinel
    altitude_m: float = 10.0   # the tracker's altitude
    layer_step_m: float = 2.0   # sentinels fly above: one altitude per sentinel of a sector, neighbour
    start_s: float = 15.0   # the target appears this long into EXECUTION (everyone at standby)
    target_speed_m_s: float = 4.0
    target_margin_m: float = 10.0   # the target's random waypoints stay this far inside the area
    ring_m: float = 5.0   # ring radius around the target (tracker due south)...
    min_spacing_m: float = 4.0   # ...enlarged so that neighbours on the ring stay this far apart
    standby_frac: float = 0.5   # standby points: on a circle of this fraction of the sector's half size
    gain_1_s: float = 1.2   # pursuit: v = v_target + gain x (slot - position)
    max_speed_m_s: float = 11.0
    stale_s: float = 0.5   # no slot update for this long: hold the last slot
    rendezvous_m: float = 3.0   # a sentinel has joined when within this of its slot
    duration_s: float = 150.0   # a drone completes after this long in EXECUTION


class TrackingGround(GroundAlgorithm):
    """Assigns roles, moves the target, commands the active drones, detects rendezvous."""

    Params = TrackingParams

    def prep_once(self, ctx: GroundContext) -> None:
        p = ctx.params
        self.area = mission_area(ctx.mission.values, "tracking")
        self.grid = mission_grid(ctx.mission.values, "tracking")
        self.tracker = int(p["tracker"])
        sentinels = sorted(i for i in ctx.reports if i != self.tracker)
        n_sec = self.grid[0] * self.grid[1]
        counts = [len(sentinels) // n_sec + (1 if s < len(sentinels) % n_sec else 0) for s in range(n_sec)]
        points = standby_points(self.area, self.grid, counts, float(p["standby_frac"]))
        slots = [(s, j, pt) for s, pts in enumerate(points) for j, pt in enumerate(pts)]
        homes = [ctx.mission.initial_positions[i][:2] for i in sentinels]
        cost = np.array([[math.dist(h, pt) for _, _, pt in slots] for h in homes]).reshape(len(homes), -1)
        rows, cols = linear_sum_assignment(cost)
        self.sector_of_drone: dict[int, int] = {}
        self.standby: dict[int, tuple[float, float, float]] = {}
        alt, step, kmax = float(p["altitude_m"]), float(p["layer_step_m"]), max(counts, default=1)
        for r, c in zip(rows, cols, strict=True):
            drone, (s, j, pt) = sentinels[r], slots[c]
            checker = sum(divmod(s, self.grid[1])) % 2
            self.sector_of_drone[drone] = s
            self.standby[drone] = (*pt, -(alt + step * (1 + j + kmax * checker)))
            ctx.send_task(drone, code=ROLE, waypoint_ned_m=self.standby[drone], data=f"sentinel:{s}")
        n0, e0, n1, e1 = self.area
        self.standby[self.tracker] = ((n0 + n1) / 2, (e0 + e1) / 2, -alt)
        if self.tracker in ctx.reports:
            ctx.send_task(self.tracker, code=ROLE, waypoint_ned_m=self.standby[self.tracker], data="tracker")

    def exec_once(self, ctx: GroundContext) -> None:
        p = ctx.params
        self.target = RandomWalkTarget(ctx.rng, self.area, float(p["target_margin_m"]),
                                       float(p["target_speed_m_s"]))
        self.sector = -1
        self.pending: tuple[int, float] | None = None   # (sector, entry time) awaiting its rendezvous
        self.next_mark_s = 0.0

    def members(self, sector: int) -> list[int]:
        return sorted(d for d, s in self.sector_of_drone.items() if s == sector)

    def exec_loop(self, ctx: GroundContext) -> None:
        p = ctx.params
        if ctx.stage_time_s < float(p["start_s"]):
            return
        vel = self.target.step(ctx.tick_s)
        pos = self.target.pos
        sector = sector_of(pos, self.area, self.grid)
        if sector != self.sector:
            self._enter(ctx, sector)
        active = [self.tracker, *self.members(sector)]
        offsets = ring_slots(len(active), float(p["ring_m"]), float(p["min_spacing_m"]))
        slots = {d: (pos[0] + o[0], pos[1] + o[1]) for d, o in zip(active, offsets, strict=True)}
        data = f"{vel[0]:.3f},{vel[1]:.3f}"
        for drone, (n, e) in slots.items():
            if drone in ctx.reports:
                ctx.send_task(drone, code=ACTIVE, waypoint_ned_m=(n, e, self.standby[drone][2]),
                              data=data, reliable=False)
        self._check_rendezvous(ctx, slots)
        self._mark_tracking(ctx, pos)

    def _enter(self, ctx: GroundContext, sector: int) -> None:
        """The event: the target entered ``sector``; release the previous sector's sentinels."""
        for drone in self.members(self.sector):
            if drone in ctx.reports:
                ctx.send_task(drone, code=STANDBY, waypoint_ned_m=self.standby[drone])
        ctx.mark("sector_entry", sector=sector, previous=self.sector, sentinels=self.members(sector))
        self.sector = sector
        self.pending = (sector, ctx.stage_time_s) if self.members(sector) else None

    def _check_rendezvous(self, ctx: GroundContext, slots: dict[int, Vec2]) -> None:
        if self.pending is None:
            return
        sector, since = self.pending
        limit = float(ctx.params["rendezvous_m"])
        joined = [d for d in self.members(sector)
                  if d in ctx.reports and math.dist(ctx.reports[d].pos_ned_m[:2], slots[d]) <= limit]
        if len(joined) == len(self.members(sector)):
            ctx.mark("rendezvous", sector=sector, delay_s=round(ctx.stage_time_s - since, 3), drones=joined)
            self.pending = None

    def _mark_tracking(self, ctx: GroundContext, pos: Vec2) -> None:
        if ctx.stage_time_s < self.next_mark_s or self.tracker not in ctx.reports:
            return
        self.next_mark_s = ctx.stage_time_s + 1.0
        tn, te, _ = ctx.reports[self.tracker].pos_ned_m
        ctx.mark("tracking", distance_m=round(math.hypot(tn - pos[0], te - pos[1]), 3),
                 target_n=round(pos[0], 2), target_e=round(pos[1], 2), sector=self.sector)


class TrackingDrone(DroneAlgorithm):
    """Waits at its standby point, or pursues its ring slot around the target while active."""

    Params = TrackingParams

    def __init__(self) -> None:
        self.role = ""
        self.standby: tuple[float, float, float] | None = None
        self.mode = STANDBY
        self.slot: Task | None = None
        self.slot_time_s = -1e9
        self.last_seq = -1
        self.climbed = False

    def on_task(self, ctx: DroneContext, task: Task) -> None:
        if task.seq < self.last_seq:   # a late, older command: ignore it
            return
        self.last_seq = task.seq
        if task.code == ROLE:
            self.role, self.standby = task.data, task.waypoint_ned_m
            ctx.mark("role", role=task.data, standby=list(task.waypoint_ned_m))
        elif task.code == STANDBY:
            self.standby = task.waypoint_ned_m or self.standby
            self._switch(ctx, STANDBY)
        elif task.code == ACTIVE:
            self.slot, self.slot_time_s = task, ctx.stage_time_s
            self._switch(ctx, ACTIVE)

    def _switch(self, ctx: DroneContext, mode: int) -> None:
        if mode != self.mode:
            self.mode = mode
            ctx.mark("mode", mode="active" if mode == ACTIVE else "standby")

    def prep_complete(self, ctx: DroneContext) -> bool:
        return bool(self.role) and ctx.state.ready_to_arm

    def exec_loop(self, ctx: DroneContext) -> Setpoint:
        n, e, d = ctx.pos_ned_m
        sn, se, sd = self.standby
        if not self.climbed:   # straight up above home first
            self.climbed = d <= sd + 0.5
            return Setpoint.position(ctx.home_ned_m[0], ctx.home_ned_m[1], sd, 0.0)
        slot = self.slot
        if self.mode == ACTIVE and slot is not None:
            wn, we, wd = slot.waypoint_ned_m
            if ctx.stage_time_s - self.slot_time_s > float(ctx.params["stale_s"]):
                return Setpoint.position(wn, we, wd)   # the stream stopped: hold the last slot
            return self._pursue(ctx, (wn, we, wd), tuple(float(x) for x in slot.data.split(",")))
        yaw = math.atan2(se - e, sn - n) if math.hypot(sn - n, se - e) > 2.0 else None
        return Setpoint.position(sn, se, sd, yaw)

    def _pursue(self, ctx: DroneContext, slot: tuple[float, float, float], ff: tuple[float, ...]) -> Setpoint:
        """Velocity setpoint: the target's velocity + gain × error to the slot, speed-limited."""
        n, e, d = ctx.pos_ned_m
        k, limit = float(ctx.params["gain_1_s"]), float(ctx.params["max_speed_m_s"])
        vn, ve = ff[0] + k * (slot[0] - n), ff[1] + k * (slot[1] - e)
        speed = math.hypot(vn, ve)
        if speed > limit:
            vn, ve = vn * limit / speed, ve * limit / speed
        return Setpoint.velocity(vn, ve, max(-2.0, min(1.0, slot[2] - d)))

    def exec_complete(self, ctx: DroneContext) -> bool:
        return ctx.stage_time_s >= float(ctx.params["duration_s"])
