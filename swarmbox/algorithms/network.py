"""Network (paper RQ5 case 4, decentralized): drones place themselves as mobile hotspots over a
moving communication demand, by local rules only.

The ground broadcasts, once per ``broadcast_period_s``, a compact demand heat map (one digit 0-9
per cell) and, with ``broadcast_positions``, every drone's reported position and velocity. It
never sends a position command. Each drone runs a local coverage-control rule (Lloyd's algorithm
restricted to what it senses): it takes the demand-weighted centroid of the part of its
neighbourhood (``sense_radius_m``) that is nearer to it than to any other drone it knows of, and
flies towards it with a velocity setpoint. A drone with no demand in that region, or a redundant
one (all the demand within its ``coverage_radius_m`` is also within that of another drone), heads
instead for the nearest demand cell no drone it knows of serves yet. A repulsion within
``separation_m`` spreads crowds and keeps drones apart, and the drones fly on ``layers``
altitudes. Neighbours' positions come from their Heartbeats when the topology sets ``peers: all``
(fresh, for small swarms), otherwise from the ground's broadcast, moved on by the broadcast
velocity for the broadcast's age (1 Hz, scales to hundreds of drones). The ground marks the
fraction of the demand within ``coverage_radius_m`` of some drone (``demand_coverage``).

Demand schedule (as the reference): the whole area for ``warmup_s``, then each quadrant of
``schedule`` for ``phase_s``, then the whole area again; drones complete after ``duration_s``.

Mission data: ``values`` ``0: [north_min, east_min]``, ``1: [north_max, east_max]`` (the area),
``2: [rows, cols]`` (the heat map's cells; row = north, column = east) and, optionally,
``3: [warmup_s, phase_s, duration_s]`` (replaces those params: larger swarms need longer phases).

Params (``conf/algo/network.yaml``): ``altitude_m``, ``layers``, ``layer_step_m`` (altitude of
layer k: altitude_m + k × layer_step_m, by id rank), ``broadcast_period_s``,
``broadcast_positions``, ``warmup_s``, ``phase_s``, ``schedule`` (quadrants: sw, se, ne, nw),
``duration_s``, ``coverage_radius_m``, ``sense_radius_m``, ``sample_m`` (sample spacing of the
local demand integral), ``update_period_s`` (target recomputation), ``control_period_s`` (velocity
recomputation; held in between), ``gain_1_s`` (velocity per metre to the target),
``max_speed_m_s``, ``separation_m`` and ``repulsion_gain_m_s`` (repulsion speed at contact,
falling linearly to 0 at ``separation_m``).

Differences from the reference implementation (ref-algorithms §11, §15): the velocity is
recomputed ten times a second from the drone's own position (the reference held a 1 Hz velocity;
its damping term dominated the speed cap, so drones oscillated); attraction is to the centroid of
the drone's own (Voronoi) share of the demand, not of all hot cells, so the drones spread over
the demand instead of clumping at one centroid; quadrants are exact halves (the reference's "> 5"
dropped a row and a column) and the first seconds are a deliberate warm-up, not an unsigned
underflow; positions in the broadcast carry drone ids and velocities (the reference mapped
positions to ids by their order).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, fields

import numpy as np
from scipy.spatial import cKDTree

from swarmbox.api import (
    Area,
    DroneAlgorithm,
    DroneContext,
    GroundAlgorithm,
    GroundContext,
    Setpoint,
    Stage,
    Task,
    mission_area,
    mission_grid,
)

Track = tuple[float, float, float, float]  # north, east (m), velocity north, east (m/s)
QUADRANTS = {"sw": (0, 0), "se": (0, 1), "nw": (1, 0), "ne": (1, 1)}   # (north half, east half)


def phase_at(t_s: float, p: dict) -> str:
    """The demand phase ``t_s`` into EXECUTION: "full" or a quadrant name."""
    tau = t_s - float(p["warmup_s"])
    schedule = list(p["schedule"])
    if tau < 0 or tau >= len(schedule) * float(p["phase_s"]):
        return "full"
    return str(schedule[int(tau // float(p["phase_s"]))])


def demand_map(phase: str, shape: tuple[int, int]) -> np.ndarray:
    """Demand level (0-9) per cell: 9 in the active quadrant (or everywhere for "full")."""
    rows, cols = shape
    grid = np.zeros(shape, dtype=np.int8)
    if phase == "full":
        grid[:] = 9
    else:
        qn, qe = QUADRANTS[phase]
        rs = slice(0, rows // 2) if qn == 0 else slice(rows // 2, rows)
        cs = slice(0, cols // 2) if qe == 0 else slice(cols // 2, cols)
        grid[rs, cs] = 9
    return grid


def sample_points(area: Area, spacing_m: float) -> np.ndarray:
    """Centres of a regular grid of ``spacing_m`` over the area, shape (k, 2)."""
    n0, e0, n1, e1 = area
    ns = np.arange(n0 + spacing_m / 2, n1, spacing_m)
    es = np.arange(e0 + spacing_m / 2, e1, spacing_m)
    nn, ee = np.meshgrid(ns, es, indexing="ij")
    return np.column_stack([nn.ravel(), ee.ravel()])


def demand_at(points: np.ndarray, grid: np.ndarray, area: Area) -> np.ndarray:
    """The demand level of the heat-map cell under each point (0 outside the area)."""
    n0, e0, n1, e1 = area
    rows, cols = grid.shape
    r = np.floor((points[:, 0] - n0) / (n1 - n0) * rows).astype(int)
    c = np.floor((points[:, 1] - e0) / (e1 - e0) * cols).astype(int)
    inside = (r >= 0) & (r < rows) & (c >= 0) & (c < cols)
    out = np.zeros(len(points))
    out[inside] = grid[r[inside], c[inside]]
    return out


def demand_coverage(grid: np.ndarray, area: Area, positions: np.ndarray, radius_m: float,
                    spacing_m: float = 2.0) -> float:
    """Fraction of the total demand within ``radius_m`` of at least one of ``positions`` (k, 2)."""
    points = sample_points(area, spacing_m)
    weight = demand_at(points, grid, area)
    if weight.sum() <= 0:
        return 1.0
    if len(positions) == 0:
        return 0.0
    dist, _ = cKDTree(np.asarray(positions, dtype=float)).query(points)
    return float(weight[dist <= radius_m].sum() / weight.sum())


def encode(grid: np.ndarray, tracks: dict[int, Track] | None) -> str:
    """``rows x cols | digits | id,n,e,vn,ve;...`` (positions in dm, velocities in dm/s)."""
    digits = "".join(str(int(v)) for v in grid.ravel())
    pos = "" if tracks is None else ";".join(
        f"{i},{round(n * 10)},{round(e * 10)},{round(vn * 10)},{round(ve * 10)}"
        for i, (n, e, vn, ve) in tracks.items())
    return f"{grid.shape[0]}x{grid.shape[1]}|{digits}|{pos}"


def decode(data: str) -> tuple[np.ndarray, dict[int, Track]]:
    shape, digits, pos = data.split("|")
    rows, cols = (int(x) for x in shape.split("x"))
    grid = np.frombuffer(digits.encode(), dtype=np.uint8).astype(np.int8) - ord("0")
    tracks = {}
    for item in filter(None, pos.split(";")):
        i, n, e, vn, ve = item.split(",")
        tracks[int(i)] = (int(n) / 10, int(e) / 10, int(vn) / 10, int(ve) / 10)
    return grid.reshape(rows, cols), tracks


def schedule(params: dict, values: dict[int, tuple[float, ...]]) -> dict:
    """The demand schedule's params, with the mission's ``values[3]`` = [warmup_s, phase_s,
    duration_s] (if given) taking precedence: a large swarm needs longer phases to move."""
    out = dict(params)
    if 3 in values:
        out["warmup_s"], out["phase_s"], out["duration_s"] = values[3][:3]
    return out


@dataclass
class NetworkParams:
    """Typed ``params`` (see ``conf/algo/network.yaml``)."""

    altitude_m: float = 10.0
    layers: int = 4   # drones fly on this many altitudes (by id rank), layer_step_m apart:
    layer_step_m: float = 2.0   # repulsion acts on positions up to 1 s old; layers make contacts rarer
    broadcast_period_s: float = 1.0   # heat map (+ positions) broadcast period
    broadcast_positions: bool = True   # include every drone's reported position and velocity in the broadcast
    warmup_s: float = 5.0   # whole-area demand first (a mission's values 3 may replace these three)
    phase_s: float = 20.0   # then each quadrant of `schedule` this long, then the whole area again
    schedule: list[str] = field(default_factory=lambda: ['sw', 'se', 'ne', 'nw'])
    duration_s: float = 105.0   # a drone completes after this long in EXECUTION
    coverage_radius_m: float = 10.0   # a drone serves the demand within this radius (the metric)
    sense_radius_m: float = 25.0   # the local rule looks this far around the drone
    sample_m: float = 2.0   # sample spacing of the local rule's demand integral
    update_period_s: float = 0.25   # how often the local target is recomputed
    control_period_s: float = 0.1   # how often the velocity is recomputed (held in between)
    gain_1_s: float = 0.6   # v = gain x (target - position) + repulsion
    max_speed_m_s: float = 5.0
    separation_m: float = 12.0   # repulsion radius: spreads a crowd fast (Lloyd alone diffuses slowly)
    repulsion_gain_m_s: float = 3.0   # repulsion speed at contact (grows linearly from 0 at separation_m)


class NetworkGround(GroundAlgorithm):
    """Broadcasts the demand (and positions); measures the demand coverage."""

    Params = NetworkParams

    def exec_once(self, ctx: GroundContext) -> None:
        self.area = mission_area(ctx.mission.values, "network")
        self.shape = mission_grid(ctx.mission.values, "network", min_cells=2)
        self.params = schedule(dict(ctx.params), dict(ctx.mission.values))
        self.next_s = 0.0
        self.phase = ""

    def exec_loop(self, ctx: GroundContext) -> None:
        p = self.params
        if ctx.stage_time_s < self.next_s:
            return
        self.next_s += float(p["broadcast_period_s"])
        phase = phase_at(ctx.stage_time_s, p)
        grid = demand_map(phase, self.shape)
        if phase != self.phase:
            self.phase = phase
            ctx.mark("heatmap", phase=phase, hot_cells=int((grid > 0).sum()))
        tracks = self._airborne(ctx)
        data = encode(grid, tracks if p["broadcast_positions"] else None)
        for drone in ctx.reports:
            ctx.send_task(drone, code=0, data=data, reliable=False)
        positions = np.array([t[:2] for t in tracks.values()]).reshape(-1, 2)
        frac = demand_coverage(grid, self.area, positions, float(p["coverage_radius_m"]))
        ctx.mark("demand_coverage", covered_frac=round(frac, 4), phase=phase, airborne=len(tracks))

    def _airborne(self, ctx: GroundContext) -> dict[int, Track]:
        """Reported position (and velocity, for direct inferiors) of every drone up and working."""
        low = 0.5 * float(self.params["altitude_m"])
        out = {}
        for i, st in sorted(ctx.swarm.items()):
            if st.stage == Stage.EXECUTION and -st.pos_ned_m[2] > low:
                rep = ctx.reports.get(i)
                vn, ve = (rep.vel_ned_m_s[0], rep.vel_ned_m_s[1]) if rep is not None else (0.0, 0.0)
                out[i] = (st.pos_ned_m[0], st.pos_ned_m[1], vn, ve)
        return out


@dataclass(frozen=True, slots=True)
class LocalRule:
    """The drone-side parameters (see the module docstring)."""

    altitude_m: float
    layer_step_m: float
    layers: float
    sense_radius_m: float
    sample_m: float
    update_period_s: float
    control_period_s: float
    gain_1_s: float
    max_speed_m_s: float
    separation_m: float
    repulsion_gain_m_s: float
    coverage_radius_m: float
    duration_s: float

    @classmethod
    def from_params(cls, params: dict) -> LocalRule:
        return cls(**{f.name: float(params[f.name]) for f in fields(cls)})


class NetworkDrone(DroneAlgorithm):
    """Lloyd-style local coverage rule on the broadcast demand; velocity setpoints only."""

    Params = NetworkParams

    def __init__(self) -> None:
        self.grid: np.ndarray | None = None
        self.tracks: dict[int, Track] = {}
        self.track_ids = np.zeros(0, dtype=int)
        self.track_arr = np.zeros((0, 4))   # north, east, v_north, v_east of self.track_ids
        self.heard_s = 0.0
        self.free_key, self.free_cells = -1.0, np.zeros((0, 2))
        self.target: tuple[float, float] | None = None
        self.close: list[int] = []
        self.next_update_s = self.next_control_s = 0.0
        self.climbed = False

    def on_task(self, ctx: DroneContext, task: Task) -> None:
        if not task.data:
            return
        self.grid, self.tracks = decode(task.data)
        others = [i for i in self.tracks if i != ctx.id]
        self.track_ids = np.array(others, dtype=int)
        self.track_arr = np.array([self.tracks[i] for i in others], dtype=float).reshape(-1, 4)
        self.heard_s = ctx.stage_time_s
        for drone in ctx.inferiors:   # relay down a hierarchy, if there is one
            ctx.send_task(drone, code=task.code, data=task.data, reliable=False)

    def exec_once(self, ctx: DroneContext) -> None:
        self.rule = rule = LocalRule.from_params(schedule(dict(ctx.params), dict(ctx.mission.values)))
        self.area = mission_area(ctx.mission.values, "network")
        rank = sorted(ctx.mission.initial_positions).index(ctx.id)
        self.alt_m = rule.altitude_m + rule.layer_step_m * (rank % max(1, int(rule.layers)))
        r = rule.sense_radius_m
        ks = np.arange(-r, r + 1e-9, rule.sample_m)
        self.offsets = np.array([(a, b) for a in ks for b in ks if a * a + b * b <= r * r])

    def _known(self, ctx: DroneContext) -> tuple[np.ndarray, np.ndarray]:
        """Other drones' ids and positions now (k, 2): peers' Heartbeats if any, else the
        broadcast, moved on by the broadcast velocities for its age (at most 2 s)."""
        if ctx.peers:
            ids = [i for i in ctx.peers if i != ctx.id]
            pos = [ctx.peers[i].pos_ned_m[:2] for i in ids]
            return np.array(ids, dtype=int), np.array(pos, dtype=float).reshape(-1, 2)
        age = min(2.0, ctx.stage_time_s - self.heard_s)
        return self.track_ids, self.track_arr[:, :2] + age * self.track_arr[:, 2:]

    def exec_loop(self, ctx: DroneContext) -> Setpoint | None:
        rule = self.rule
        n, e, d = ctx.pos_ned_m
        alt = self.alt_m
        if not self.climbed:   # straight up above home first
            self.climbed = -d >= alt - 0.5
            return Setpoint.position(ctx.home_ned_m[0], ctx.home_ned_m[1], -alt, 0.0)
        if ctx.stage_time_s < self.next_control_s:
            return None   # the vehicle keeps flying the last velocity
        self.next_control_s = ctx.stage_time_s + rule.control_period_s - 1e-9
        if self.grid is not None and ctx.stage_time_s >= self.next_update_s:
            self._update(ctx, (n, e))
        vn = ve = 0.0
        if self.target is not None:
            vn, ve = rule.gain_1_s * (self.target[0] - n), rule.gain_1_s * (self.target[1] - e)
        rn, re = self._repulsion(ctx, (n, e))
        vn, ve = vn + rn, ve + re
        speed, limit = math.hypot(vn, ve), rule.max_speed_m_s
        if speed > limit:
            vn, ve = vn * limit / speed, ve * limit / speed
        return Setpoint.velocity(vn, ve, max(-2.0, min(1.0, -alt - d)))

    def _update(self, ctx: DroneContext, me_ne: tuple[float, float]) -> None:
        """Recompute the local target, and which drones are near enough to repel."""
        rule = self.rule
        self.next_update_s = ctx.stage_time_s + rule.update_period_s
        ids, others = self._known(ctx)
        me = np.array(me_ne)
        dist = np.hypot(*(others - me).T)
        centroid, redundant = self._centroid(me, others[dist < 2 * rule.sense_radius_m])
        if centroid is None or redundant:
            key = ctx.stage_time_s if ctx.peers else self.heard_s
            gap = self._nearest_free_demand(me, others, key, fallback_to_any=centroid is None)
            centroid = gap if gap is not None else centroid
        self.target = centroid
        reach = rule.separation_m + 2 * rule.max_speed_m_s * rule.update_period_s
        self.close = ids[dist < reach].tolist()

    def _centroid(self, me: np.ndarray, near: np.ndarray) -> tuple[tuple[float, float] | None, bool]:
        """Demand-weighted centroid of this drone's sensed Voronoi share (None if it has none),
        and whether the drone is redundant: all the demand it serves, others serve too."""
        pts = me + self.offsets
        weight = demand_at(pts, self.grid, self.area)
        hot = weight > 0
        pts, weight = pts[hot], weight[hot]
        redundant = False
        if len(pts) and len(near):
            d_me = np.hypot(*(pts - me).T)
            d_other, _ = cKDTree(near).query(pts)
            served = d_me <= self.rule.coverage_radius_m
            redundant = bool(served.any() and (d_other[served] <= self.rule.coverage_radius_m).all())
            mine = d_me <= d_other
            pts, weight = pts[mine], weight[mine]
        if weight.sum() > 0:
            c = (pts * weight[:, None]).sum(axis=0) / weight.sum()
            return (float(c[0]), float(c[1])), redundant
        return None, redundant

    def _nearest_free_demand(self, me: np.ndarray, others: np.ndarray, key: float,
                             fallback_to_any: bool) -> tuple[float, float] | None:
        """Centre of the nearest demand cell no known drone serves yet: drones that are outside
        the demand or redundant stream to its gaps, not to its nearest edge. With no gap left,
        the nearest demand cell if ``fallback_to_any``, else None. The gaps are computed once per
        ``key`` (a broadcast's arrival time)."""
        if self.free_key != key:
            self.free_key, self.free_cells = key, self._free_cells(others)
        cells = self.free_cells if len(self.free_cells) or not fallback_to_any else self._hot_centres()
        if len(cells) == 0:
            return None
        best = cells[np.argmin(np.hypot(*(cells - me).T))]
        return float(best[0]), float(best[1])

    def _hot_centres(self) -> np.ndarray:
        rows, cols = self.grid.shape
        n0, e0, n1, e1 = self.area
        hot = np.argwhere(self.grid > 0)
        return np.column_stack([n0 + (hot[:, 0] + 0.5) * (n1 - n0) / rows,
                                e0 + (hot[:, 1] + 0.5) * (e1 - e0) / cols])

    def _free_cells(self, others: np.ndarray) -> np.ndarray:
        """Centres of the demand cells farther than ``coverage_radius_m`` from every known drone."""
        centres = self._hot_centres()
        if len(others) == 0 or len(centres) == 0:
            return centres
        served, _ = cKDTree(others).query(centres)
        return centres[served > self.rule.coverage_radius_m]

    def _repulsion(self, ctx: DroneContext, me: tuple[float, float]) -> tuple[float, float]:
        """Push away from drones closer than ``separation_m``, linearly up to the gain at contact."""
        radius, gain = self.rule.separation_m, self.rule.repulsion_gain_m_s
        peers = ctx.peers
        age = min(2.0, ctx.stage_time_s - self.heard_s)
        vn = ve = 0.0
        for i in self.close:
            if i in peers:
                qn, qe = peers[i].pos_ned_m[:2]
            elif i in self.tracks:
                n, e, tvn, tve = self.tracks[i]
                qn, qe = n + tvn * age, e + tve * age
            else:
                continue
            dn, de = me[0] - qn, me[1] - qe
            dist = math.hypot(dn, de)
            if 1e-6 < dist < radius:
                k = gain * (radius - dist) / radius / dist
                vn, ve = vn + k * dn, ve + k * de
        return vn, ve

    def exec_complete(self, ctx: DroneContext) -> bool:
        return ctx.stage_time_s >= self.rule.duration_s
