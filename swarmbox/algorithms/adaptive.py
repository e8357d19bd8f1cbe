"""Adaptive swarm (Agishev 2019): a layered planner for a leader and a formation of followers.

- Global layer (ground, ``prep_once``): a rapidly-exploring random tree from the leader's launch
  point to ``goal_ne_m`` through the mission's obstacles, kept ``clearance_m`` away from them, then
  random shortcutting and resampling every ``waypoint_spacing_m``. Every random draw comes from the
  ground's seeded ``rng`` and the tree gives up after ``rrt_max_iters`` samples (the run then fails
  with that reason). Every tick the ground sends the leader its current waypoint, advancing when the
  leader is within ``advance_m``; code ARRIVED once the leader is within ``goal_radius_m`` of the end.
- Local layer (leader): an artificial potential field — attraction toward the waypoint at
  ``speed_m_s``, repulsion from every obstacle surface within ``influence_m`` and no motion into
  one at contact — flown as a
  velocity setpoint, once the leader and all its followers have climbed to ``altitude_m``.
- Formation (leader → followers): the leader keeps its trail (a point every 0.5 m) and places each
  follower: one launched ``b`` m behind and ``l`` m beside the leader gets the trail point ``b`` m back
  along the trail, moved ``l`` m sideways — less where that would come within ``slot_clearance_m`` of
  an obstacle, so the formation bends around corners and squeezes through passages. Every tick it
  sends each follower its slot, the course there, a feed-forward velocity (the leader's speed along
  that course) and the positions of the follower's neighbours within ``separation_m``; the leader
  also slows down while the formation lags (mean slot error above ``lag_m``/2).
- Followers fly the feed-forward velocity plus attraction to the slot (``k_formation``) plus
  repulsion from their neighbours, through the same obstacle field as the leader, capped at ``v_max``.

Topology: leader–follower (the leader's superior is the ground, every other drone's is the leader:
the mission's ``superiors``, or ``topology=leader_follower``).
Formation offsets are the launch offsets from the leader read with the formation facing north:
followers launch south of (behind) the leader.
Obstacles are the mission's static ``obstacles`` — the simulator's solid bodies — passed in as
``params.obstacles``. Markers: ``path_planned``, ``waypoint``, ``goal_reached`` (ground), and every
``mark_period_s`` the leader's ``formation`` (mean slot error, smallest obstacle clearance).

Differences from the reference port: seeded RRT with an iteration cap, extensions that never pass
their sample; obstacle repulsion from the nearest surface point of each obstacle (the reference
used one point per polygon at its vertex mean, singular near it); start, goal, obstacles and leader
come from the config; followers hold their altitude above home until the first relay; followers
follow the leader's trail, avoiding obstacles and each other, instead of a rigid offset rotated
with the leader's bearing (which swings the rear of a large formation through the obstacle a turn
goes around).
"""

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy.spatial import cKDTree

from swarmbox.api import DroneAlgorithm, DroneContext, GroundAlgorithm, GroundContext, Setpoint, Task

from .adaptive_plan import avoid, away_from, cap, clearance, resample, rrt, shortcut

GO, ARRIVED = 0, 1


@dataclass
class AdaptiveParams:
    """Typed ``params`` (see ``conf/algo/adaptive.yaml``)."""

    # the simulator's static bodies, seen by the planner and the fields
    obstacles: list[Any] = field(default_factory=list)
    leader: int = 0
    goal_ne_m: list[float] = field(default_factory=lambda: [5.0, -45.0])
    goal_radius_m: float = 2.0   # leader this close to the route's end: ARRIVED
    # RRT sampling box [[n_min, e_min], [n_max, e_max]]
    bounds_ne_m: list[list[float]] = field(default_factory=lambda: [[-40.0, -80.0], [80.0, 50.0]])
    altitude_m: float = 5.0
    altitude_gain: float = 1.0   # 1/s, vertical velocity per metre of altitude error
    clearance_m: float = 6.0   # m kept from obstacles by the route
    slot_clearance_m: float = 3.0   # m kept from obstacles by formation slots (squeezed toward the trail)
    rrt_step_m: float = 5.0
    rrt_goal_bias: float = 0.1
    rrt_max_iters: int = 4000
    shortcut_iters: int = 80
    waypoint_spacing_m: float = 3.0
    advance_m: float = 3.0   # next waypoint when the leader is this close
    speed_m_s: float = 2.0   # leader cruise speed
    lag_m: float = 3.0   # the leader slows down (to 1/4 at most) while the mean slot error exceeds lag_m/2
    slow_radius_m: float = 3.0   # the leader slows down within this of its waypoint
    v_max: float = 3.5
    influence_m: float = 3.0   # obstacle repulsion range
    k_obstacle: float = 2.0   # obstacle repulsion gain, m^3/s
    k_formation: float = 0.6   # 1/s, attraction to the formation slot
    separation_m: float = 3.0   # neighbour repulsion range
    k_separation: float = 3.0   # 1/s
    slot_tolerance_m: float = 1.5   # a follower is done within this of its slot
    mark_period_s: float = 1.0


class AdaptiveGround(GroundAlgorithm):
    """Plans the leader's route once, then streams the current waypoint to the leader."""

    Params = AdaptiveParams

    def prep_once(self, ctx: GroundContext) -> None:
        p = ctx.params
        start = np.array(ctx.mission.initial_positions[int(p["leader"])][:2], float)
        goal = np.array(p["goal_ne_m"], float)
        path = rrt(start, goal, p["obstacles"], np.array(p["bounds_ne_m"], float), ctx.rng, p)
        if path is None:
            raise RuntimeError(f"RRT found no path to {goal.tolist()} in {p['rrt_max_iters']} samples")
        path = shortcut(path, p["obstacles"], ctx.rng, int(p["shortcut_iters"]), float(p["clearance_m"]))
        self.route = resample(path, float(p["waypoint_spacing_m"]))
        self.index, self.arrived = 0, False
        length = float(sum(math.dist(a, b) for a, b in zip(self.route[:-1], self.route[1:], strict=True)))
        ctx.mark("path_planned", length_m=length, waypoints=len(self.route))

    def exec_loop(self, ctx: GroundContext) -> None:
        p = ctx.params
        rep = ctx.reports.get(int(p["leader"]))
        if rep is None:
            return
        here, last = rep.pos_ned_m[:2], len(self.route) - 1
        while self.index < last and math.dist(here, self.route[self.index]) < float(p["advance_m"]):
            self.index += 1
            n, e = self.route[self.index]
            ctx.mark("waypoint", index=self.index, n_m=n, e_m=e)
        if not self.arrived and math.dist(here, self.route[last]) < float(p["goal_radius_m"]):
            self.arrived = True
            ctx.mark("goal_reached", n_m=here[0], e_m=here[1])
        n, e = self.route[self.index]
        ctx.send_task(rep.id, code=ARRIVED if self.arrived else GO,
                      waypoint_ned_m=(n, e, -float(p["altitude_m"])), reliable=False)


class AdaptiveDrone(DroneAlgorithm):
    """The leader (``params.leader``) flies the potential field and places the followers; the
    others fly to the slot their leader gives them, avoiding obstacles and each other."""

    Params = AdaptiveParams

    def exec_once(self, ctx: DroneContext) -> None:
        p = ctx.params
        self.leads = ctx.id == int(p["leader"])
        ln, le, _ = ctx.mission.initial_positions[int(p["leader"])]
        self.offsets = {d: (n - ln, e - le) for d, (n, e, _) in ctx.mission.initial_positions.items()}
        depth = math.ceil(max(-on for on, _ in self.offsets.values()) + 5.0)
        self.trail = [(ln - k, le) for k in range(depth, 0, -1)]   # oldest first, due south
        self.trail_len = 2 * depth                                   # points 0.5-1 m apart
        self.started, self.next_mark_s, self.slot_error, self.lag_m = False, 0.0, math.inf, 0.0

    def exec_loop(self, ctx: DroneContext) -> Setpoint:
        p, task = ctx.params, ctx.last_task
        alt = float(p["altitude_m"])
        if self.leads and not self.started:
            up = [-ctx.pos_ned_m[2], *(-r.pos_ned_m[2] for r in ctx.inferiors.values())]
            self.started = task is not None and min(up) > alt - 0.5
        if task is None or task.waypoint_ned_m is None or (self.leads and not self.started):
            n, e, _ = ctx.home_ned_m
            return Setpoint.position(n, e, -alt, 0.0)
        pos = np.array(ctx.pos_ned_m[:2])
        v = self._lead(ctx, pos, task.waypoint_ned_m[:2]) if self.leads else self._follow(ctx, pos, task)
        vz = float(p["altitude_gain"]) * (-alt - ctx.pos_ned_m[2])
        yaw = math.atan2(v[1], v[0]) if np.hypot(*v) > 0.5 else None
        return Setpoint.velocity(float(v[0]), float(v[1]), vz, task.yaw_rad if not self.leads else yaw)

    def _lead(self, ctx: DroneContext, pos: np.ndarray, waypoint: tuple[float, ...]) -> np.ndarray:
        p = ctx.params
        to = np.array(waypoint, float) - pos
        speed = float(p["speed_m_s"]) * min(1.0, max(0.25, 1.5 - self.lag_m / float(p["lag_m"])))
        v = speed * to / max(float(np.hypot(*to)), float(p["slow_radius_m"]))
        v = avoid(p["obstacles"], pos, v, float(p["influence_m"]), float(p["k_obstacle"]))
        v = cap(v, float(p["v_max"]))
        if math.dist(pos, self.trail[-1]) >= 0.5:
            self.trail = [*self.trail[1 - self.trail_len:], tuple(pos.tolist())]
        self._relay(ctx, pos, float(np.hypot(*v)))
        return v

    def _slots(self, ctx: DroneContext, pos: np.ndarray, ids: list[int]) -> tuple[np.ndarray, np.ndarray]:
        """Slots (M, 2) and unit course (M, 2) of followers ``ids``: a follower launched ``b`` m behind
        and ``l`` m beside the leader keeps ``b`` m behind it *along its trail* and up to ``l`` m beside
        the trail: less where that would come within ``slot_clearance_m`` of an obstacle."""
        pts = np.vstack([pos, np.array(self.trail[::-1])])
        cum = np.concatenate(([0.0], np.cumsum(np.hypot(*np.diff(pts, axis=0).T))))
        off = np.array([self.offsets[d] for d in ids])

        def at(s: np.ndarray) -> np.ndarray:
            return np.stack([np.interp(s, cum, pts[:, 0]), np.interp(s, cum, pts[:, 1])], axis=1)

        back = np.maximum(-off[:, 0], 0.0)
        course = at(np.maximum(back - 1.0, 0.0)) - at(back + 1.0)
        course /= np.maximum(np.hypot(*course.T), 1e-9)[:, None]
        side = off[:, 1:2] * np.stack([-course[:, 1], course[:, 0]], axis=1)
        slots, margin = at(back), float(ctx.params["slot_clearance_m"])
        for k in range(len(ids)):   # squeeze toward the trail until clear of obstacles
            for shrink in (1.0, 0.75, 0.5, 0.25, 0.0):
                n, e = (slots[k] + shrink * side[k]).tolist()
                if clearance(ctx.params["obstacles"], n, e) >= margin:
                    break
            slots[k] = (n, e)
        return slots, course

    def _relay(self, ctx: DroneContext, pos: np.ndarray, speed: float) -> None:
        """Send each follower its slot, course, feed-forward velocity and neighbours; mark progress."""
        reps, code, p = ctx.inferiors, ctx.last_task.code, ctx.params
        ids = list(reps)
        if not ids:
            return
        slots, course = self._slots(ctx, pos, ids)
        pts = np.array([reps[d].pos_ned_m[:2] for d in ids] + [pos.tolist()])
        errors = np.hypot(*(pts[:-1] - slots).T)
        self.lag_m = float(errors.mean())
        tree = cKDTree(pts)
        for k, d in enumerate(ids):
            near = ";".join(f"{pts[j, 0]:.2f},{pts[j, 1]:.2f}"
                            for j in tree.query_ball_point(pts[k], float(p["separation_m"])) if j != k)
            (sn, se), (cn, ce) = slots[k].tolist(), course[k].tolist()
            ctx.send_task(d, code=code, waypoint_ned_m=(sn, se, -float(p["altitude_m"])),
                          yaw_rad=math.atan2(ce, cn), data=f"{speed * cn:.3f},{speed * ce:.3f}|{near}",
                          reliable=False)
        if ctx.stage_time_s >= self.next_mark_s:
            self.next_mark_s = ctx.stage_time_s + float(p["mark_period_s"])
            ctx.mark("formation", error_mean_m=self.lag_m, error_max_m=float(errors.max()),
                     clearance_min_m=min(clearance(p["obstacles"], n, e) for n, e in pts.tolist()))

    def _follow(self, ctx: DroneContext, pos: np.ndarray, task: Task) -> np.ndarray:
        p = ctx.params
        head, _, rest = task.data.partition("|")
        others = np.array([q.split(",") for q in rest.split(";")], float) if rest else np.empty((0, 2))
        slot = np.array(task.waypoint_ned_m[:2])
        self.slot_error = float(np.hypot(*(slot - pos)))
        v = cap(np.array(head.split(","), float) + float(p["k_formation"]) * (slot - pos), float(p["v_max"]))
        v += away_from(others, pos, float(p["separation_m"]), float(p["k_separation"]))
        return cap(avoid(p["obstacles"], pos, v, float(p["influence_m"]), float(p["k_obstacle"])),
                   float(p["v_max"]))

    def exec_complete(self, ctx: DroneContext) -> bool:
        task = ctx.last_task
        if task is None or task.code != ARRIVED or math.hypot(*ctx.vel_ned_m_s[:2]) > 0.5:
            return False
        return self.leads or self.slot_error < float(ctx.params["slot_tolerance_m"])
