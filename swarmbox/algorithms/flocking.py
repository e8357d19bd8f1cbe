"""Optimized flocking (Vásárhelyi et al., Science Robotics 2018) in a walled arena.

Every drone's desired horizontal velocity is the sum of four terms of the published model:

- self-propulsion ``v_flock · v_i/|v_i|`` (a drone at rest uses its initial heading, drawn from the
  ground's seeded ``rng``);
- repulsion ``p_rep · (r0_rep − r_ij) · r̂_ij`` from every neighbour closer than ``r0_rep``;
- velocity alignment ("friction"): a neighbour whose velocity differs by more than the braking curve
  allows, ``v_ij^max = max(v_frict, D(r_ij − r0_frict, a_frict, p_frict))``, pulls the velocity
  difference down by ``C_frict · (|v_ij| − v_ij^max)``;
- walls: one *shill agent* per obstacle at its nearest surface point, moving away from it (into the
  arena) at ``v_shill``; the drone matches that velocity by ``C_shill · (|v_s − v_i| − v_max)`` along
  ``(v_s − v_i)`` wherever the mismatch exceeds ``D(r_is − r0_shill, a_shill, p_shill)``;

capped at ``v_max``. ``D(r, a, p)`` is the braking curve: 0 for r ≤ 0, ``r·p`` while ``r·p < a/p``,
``sqrt(2ar − a²/p²)`` beyond. Only neighbours within the communication range ``r_comm_m`` count.

The ground computes the whole swarm's velocities every ``1/command_hz`` s from the drones' Reports (a
k-d tree keeps the neighbour search O(N log N)) and sends each drone one unreliable task: code
FLOCK with the velocity in ``waypoint_ned_m`` (north, east, 0). That is O(N) messages per command,
where a drone-side version listening to every peer's Heartbeat would need O(N²). Drones climb to
``altitude_m`` above home, then fly the commanded velocity with altitude hold; the ground starts the
flock once every drone is up and sends BRAKE after ``flock_s``; a drone is complete once it has
braked. A drone that hears no command for ``stale_s`` brakes on its own.

The arena walls are the mission's static ``obstacles`` (segments, boxes or circles), passed in as
``params.obstacles`` — the simulator sees the same list as solid bodies.

Differences from the reference port: the wall term uses the published sign ``(v_s − v_i)`` with the
shill velocity pointing into the arena (the reference pointed it outward and used ``v_i − v_s``) and
has the gain ``C_shill``; a drone at rest self-propels along its initial heading (the reference's
fallback never fired); neighbours are limited to ``r_comm_m``; velocities are horizontal.

The drone side comes twice: :class:`FlockingDrone` per drone, :class:`FlockingFleet` over the whole
fleet at once (the batch API, ``algo=flocking_batch``).
"""

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy.spatial import cKDTree

from swarmbox.api import (
    DroneAlgorithm,
    DroneContext,
    Fleet,
    FleetAlgorithm,
    FleetSetpoints,
    GroundAlgorithm,
    GroundContext,
    Setpoint,
    SetpointKind,
    Task,
    row_norms,
)

TAKEOFF, FLOCK, BRAKE = 0, 1, 2


def braking_curve(r: np.ndarray, a: float, p: float) -> np.ndarray:
    """D(r, a, p): the largest velocity difference that can still be braked within distance ``r``
    with acceleration ``a`` and linear gain ``p``."""
    r = np.asarray(r, dtype=float)
    lin = r * p
    root = np.sqrt(np.maximum(2.0 * a * r - (a / p) ** 2, 0.0))
    return np.where(r <= 0.0, 0.0, np.where(lin < a / p, lin, root))


def nearest_surface(obstacle: Mapping[str, Any], pts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Nearest point of ``obstacle``'s surface to each of ``pts`` (N, 2) and the distance to it.

    ``obstacle`` is a mission obstacle: ``{kind: segment, a, b, radius_m}``, ``{kind: box, center,
    size}`` or ``{kind: circle, center, radius_m}``, coordinates [north, east].
    """
    kind = obstacle["kind"]
    if kind == "segment":
        a, b = np.asarray(obstacle["a"], float), np.asarray(obstacle["b"], float)
        ab = b - a
        t = np.clip((pts - a) @ ab / max(float(ab @ ab), 1e-12), 0.0, 1.0)
        core, radius = a + t[:, None] * ab, float(obstacle.get("radius_m", 0.1))
    elif kind == "circle":
        core = np.broadcast_to(np.asarray(obstacle["center"], float), pts.shape)
        radius = float(obstacle["radius_m"])
    elif kind == "box":
        c, half = np.asarray(obstacle["center"], float), np.asarray(obstacle["size"], float) / 2
        core, radius = np.clip(pts, c - half, c + half), 0.0
    else:
        raise ValueError(f"unknown obstacle kind {kind!r}")
    off = pts - core
    dist = np.hypot(off[:, 0], off[:, 1])
    unit = off / np.maximum(dist, 1e-9)[:, None]
    return core + unit * radius, dist - radius


def flocking_velocities(pos: np.ndarray, vel: np.ndarray, heading: np.ndarray,
                        obstacles: Sequence[Mapping[str, Any]], p: Mapping[str, Any]) -> np.ndarray:
    """Desired horizontal velocities (N, 2) of the model for positions ``pos`` and velocities ``vel``
    (N, 2); ``heading`` (N, 2) holds unit vectors used by drones at rest. ``p`` holds the parameters."""
    f = {k: float(v) for k, v in p.items() if isinstance(v, int | float)}
    speed = np.hypot(vel[:, 0], vel[:, 1])
    moving = (speed > 0.1)[:, None]
    out = f["v_flock"] * np.where(moving, vel / np.maximum(speed, 1e-9)[:, None], heading)
    pairs = cKDTree(pos).query_pairs(f["r_comm_m"], output_type="ndarray")
    if len(pairs):
        i, j = pairs[:, 0], pairs[:, 1]
        r = pos[i] - pos[j]
        d = np.maximum(np.hypot(r[:, 0], r[:, 1]), 1e-9)
        rep = (f["p_rep"] * np.maximum(f["r0_rep"] - d, 0.0) / d)[:, None] * r
        dv = vel[i] - vel[j]
        s = np.maximum(np.hypot(dv[:, 0], dv[:, 1]), 1e-9)
        vmax = np.maximum(f["v_frict"], braking_curve(d - f["r0_frict"], f["a_frict"], f["p_frict"]))
        frict = (f["C_frict"] * np.maximum(s - vmax, 0.0) / s)[:, None] * dv
        np.add.at(out, i, rep - frict)
        np.add.at(out, j, frict - rep)
    for ob in obstacles:
        surface, dist = nearest_surface(ob, pos)
        inward = (pos - surface) / np.maximum(dist, 1e-9)[:, None]
        dv = f["v_shill"] * inward - vel
        s = np.maximum(np.hypot(dv[:, 0], dv[:, 1]), 1e-9)
        vmax = braking_curve(dist - f["r0_shill"], f["a_shill"], f["p_shill"])
        out += (f["C_shill"] * np.maximum(s - vmax, 0.0) / s)[:, None] * dv
    norm = np.hypot(out[:, 0], out[:, 1])
    return out * np.minimum(1.0, f["v_max"] / np.maximum(norm, 1e-9))[:, None]


def order_parameter(vel: np.ndarray) -> float:
    """Velocity alignment |Σ v_i| / Σ |v_i| (1 = all parallel), NaN at rest."""
    total = float(np.hypot(*vel.sum(axis=0)))
    norms = float(np.hypot(vel[:, 0], vel[:, 1]).sum())
    return total / norms if norms > 1e-9 else math.nan


@dataclass
class FlockingParams:
    """Typed ``params`` (see ``conf/algo/flocking.yaml``)."""

    # the arena walls: the simulator's static bodies, seen by the model
    obstacles: list[Any] = field(default_factory=list)
    altitude_m: float = 5.0
    altitude_gain: float = 1.0   # 1/s, vertical velocity per metre of altitude error
    takeoff_timeout_s: float = 30.0   # start flocking after this even if a drone is not yet up
    flock_s: float = 90.0   # flocking time, then BRAKE
    command_hz: float = 20.0   # velocity command rate
    stale_s: float = 1.0   # a drone without a command for this long brakes
    mark_period_s: float = 1.0   # period of the 'flock' marker
    r_comm_m: float = 50.0   # communication (neighbour) range
    v_flock: float = 4.0   # m/s, preferred speed
    v_max: float = 6.0   # m/s, cap of the desired velocity
    r0_rep: float = 8.0   # m, repulsion range
    p_rep: float = 0.5   # 1/s, repulsion gain
    r0_frict: float = 85.3   # m, alignment: distance where the braking curve starts
    C_frict: float = 0.05   # alignment gain
    v_frict: float = 0.63   # m/s, velocity difference always tolerated
    p_frict: float = 5.2   # 1/s
    a_frict: float = 4.16   # m/s^2
    r0_shill: float = 0.3   # m, walls: distance where the braking curve starts
    v_shill: float = 13.6   # m/s, shill agents' speed (into the arena)
    p_shill: float = 3.55   # 1/s
    a_shill: float = 3.02   # m/s^2
    C_shill: float = 1.0   # wall gain


class FlockingGround(GroundAlgorithm):
    """Computes every drone's velocity from its Reports and streams it as a FLOCK command."""

    Params = FlockingParams

    def exec_once(self, ctx: GroundContext) -> None:
        angles = ctx.rng.uniform(0.0, 2 * math.pi, size=len(ctx.mission.initial_positions))
        self.heading = {d: (math.cos(a), math.sin(a)) for d, a in zip(ctx.mission.initial_positions, angles,
                                                                         strict=True)}
        self.start_s: float | None = None
        self.period = max(1, round(1.0 / (float(ctx.params["command_hz"]) * ctx.tick_s)))
        self.next_mark_s = 0.0

    def exec_loop(self, ctx: GroundContext) -> None:
        p, reps = ctx.params, ctx.reports
        if self.start_s is None:
            up = all(-r.pos_ned_m[2] > float(p["altitude_m"]) - 0.5 for r in reps.values())
            if not (reps and (up or ctx.stage_time_s > float(p["takeoff_timeout_s"]))):
                return
            self.start_s = ctx.stage_time_s
            ctx.mark("flock_start", drones=len(reps))
        if ctx.stage_time_s - self.start_s >= float(p["flock_s"]):
            for drone in reps:
                ctx.send_task(drone, code=BRAKE, reliable=False)
            return
        if ctx.tick % self.period:
            return
        ids = sorted(reps)
        pos = np.array([reps[d].pos_ned_m[:2] for d in ids])
        vel = np.array([reps[d].vel_ned_m_s[:2] for d in ids])
        cmd = flocking_velocities(pos, vel, np.array([self.heading[d] for d in ids]), p["obstacles"], p)
        for d, (vn, ve) in zip(ids, cmd.tolist(), strict=True):
            ctx.send_task(d, code=FLOCK, waypoint_ned_m=(vn, ve, 0.0), yaw_rad=math.atan2(ve, vn),
                          reliable=False)
        if ctx.stage_time_s >= self.next_mark_s:
            self.next_mark_s = ctx.stage_time_s + float(p["mark_period_s"])
            self._mark(ctx, pos, vel)

    def _mark(self, ctx: GroundContext, pos: np.ndarray, vel: np.ndarray) -> None:
        """One ``flock`` marker: order, closest pair and closest wall, from the Reports."""
        sep = float(cKDTree(pos).query(pos, k=2)[0][:, 1].min()) if len(pos) > 1 else math.nan
        walls = [float(nearest_surface(ob, pos)[1].min()) for ob in ctx.params["obstacles"]]
        ctx.mark("flock", order=order_parameter(vel), min_separation_m=sep,
                 wall_min_m=min(walls, default=math.nan),
                 speed_mean_m_s=float(np.hypot(vel[:, 0], vel[:, 1]).mean()))


class FlockingDrone(DroneAlgorithm):
    """Climbs above home, then flies the ground's velocity commands at constant altitude."""

    Params = FlockingParams

    def exec_once(self, ctx: DroneContext) -> None:
        self.heard_s = -math.inf

    def on_task(self, ctx: DroneContext, task: Task) -> None:
        self.heard_s = ctx.time_s

    def exec_loop(self, ctx: DroneContext) -> Setpoint:
        p, task = ctx.params, ctx.last_task
        alt_d = -float(p["altitude_m"])
        if task is None or task.code == TAKEOFF:
            n, e, _ = ctx.home_ned_m
            return Setpoint.position(n, e, alt_d)
        vz = float(p["altitude_gain"]) * (alt_d - ctx.pos_ned_m[2])
        stale = ctx.time_s - self.heard_s > float(p["stale_s"])
        if task.code == BRAKE or stale or task.waypoint_ned_m is None:
            return Setpoint.velocity(0.0, 0.0, vz)
        vn, ve, _ = task.waypoint_ned_m
        return Setpoint.velocity(vn, ve, vz, task.yaw_rad)

    def exec_complete(self, ctx: DroneContext) -> bool:
        task = ctx.last_task
        return task is not None and task.code == BRAKE and math.hypot(*ctx.vel_ned_m_s[:2]) < 0.3


class FlockingFleet(FleetAlgorithm):
    """:class:`FlockingDrone` over the whole fleet at once (``algo=flocking_batch``): the same logs."""

    Params = FlockingParams

    def setup(self, fleet: Fleet) -> None:
        p = fleet.params
        self.alt_d, self.gain = -float(p["altitude_m"]), float(p["altitude_gain"])
        self.stale_s = float(p["stale_s"])
        self.heard_s = np.full(fleet.n, -math.inf)
        self.code = np.full(fleet.n, -1)   # the latest task's code (-1: none yet)
        self.command = np.zeros((fleet.n, 3))   # its velocity (north, east) and yaw (NaN: None)
        self.has_command = np.zeros(fleet.n, dtype=bool)   # it carried a velocity
        self.takeoff = fleet.home_ned_m.copy()
        self.takeoff[:, 2] = self.alt_d

    def exec_once(self, fleet: Fleet, rows: np.ndarray) -> None:
        self.heard_s[rows] = -math.inf

    def on_task(self, fleet: Fleet, i: int, task: Task) -> None:
        self.heard_s[i] = fleet.ctx(i).time_s
        self.code[i] = task.code
        self.has_command[i] = task.waypoint_ned_m is not None
        if task.waypoint_ned_m is not None:
            yaw = math.nan if task.yaw_rad is None else task.yaw_rad
            self.command[i] = (task.waypoint_ned_m[0], task.waypoint_ned_m[1], yaw)

    def exec_loop(self, fleet: Fleet, rows: np.ndarray) -> FleetSetpoints:
        code = self.code
        vz = self.gain * (self.alt_d - fleet.pos_ned_m[:, 2])
        stale = fleet.time_s - self.heard_s > self.stale_s
        climb = (code == -1) | (code == TAKEOFF)   # no task yet, or TAKEOFF: climb above home
        fly = ~climb & (code != BRAKE) & ~stale & self.has_command   # the commanded velocity
        ned = np.where(fly[:, None], self.command, 0.0)   # else brake: zero horizontal velocity
        ned[:, 2] = vz
        yaw = np.where(fly, self.command[:, 2], np.nan)
        ned[climb], yaw[climb] = self.takeoff[climb], np.nan
        kind = np.where(climb, int(SetpointKind.POSITION), int(SetpointKind.VELOCITY))
        return FleetSetpoints(kind, ned, yaw)

    def exec_complete(self, fleet: Fleet, rows: np.ndarray) -> np.ndarray:
        return (self.code == BRAKE) & (row_norms(fleet.vel_ned_m_s[:, :2], 0.3) < 0.3)
