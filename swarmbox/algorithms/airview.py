"""Airview (paper RQ5 case 1, hybrid): collaborative area coverage by sector partition.

The ground splits the mission area into one rectangular sector per drone and assigns the sectors
to the drones (one reliable task each, at PREPARATION). Each drone then plans and flies a
lawnmower (boustrophedon) path over its own sector, and returns home. The ground estimates the
covered fraction of the area from the drones' reported positions with a square sensor footprint
and marks it periodically (marker ``coverage``; ``coverage_90`` once when 90 % is reached).

Mission data: ``mission.values`` ``0: [north_min, east_min]`` and ``1: [north_max, east_max]``
bound the area (m, mission frame).

Params (``conf/algo/airview.yaml``): ``altitude_m`` lowest flight altitude, ``altitude_step_m``
vertical spacing of the drones' altitudes (each drone flies at its own altitude, the one with the
nearest sector lowest, so transits over other sectors cannot collide), ``sweep_width_m`` largest
distance between legs, ``footprint_m`` half side of the square sensor footprint, ``min_alt_frac``
fraction of ``altitude_m`` above which the sensor counts, ``lookahead_m`` distance of the moving
position setpoint ahead of the drone (sets the cruise speed, about 0.95 × lookahead m/s),
``accept_m`` horizontal waypoint acceptance radius, ``coverage_period_s`` period of the coverage
marker.

Differences from the reference implementation (ref-algorithms §8, §15): the area comes from the
mission (the reference read a bound it never used and hard-wired 4 sectors per row, so with 36
drones most sectors fell outside its 400 m × 400 m coverage map); sectors are rows × columns
sized to the area and matched to the drones by launch position (an optimal assignment, not by
id); the legs run along the longer side of the sector, are spaced evenly so the whole sector is
covered, and stop short of the sector's edges so neighbours never meet there; coverage only
counts drones in EXECUTION above ``min_alt_frac`` × altitude; every drone flies at its own
altitude (the reference flew all at 10 m across each other's paths); waypoints are accepted
within a radius (no out-of-range read at the end of the path); a drone completes once back above
home and down to ``altitude_m``, not when it turns for home.
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
    Stage,
    Task,
    mission_area,
)

CLIMB, SURVEY, RETURN, DESCEND, DONE = range(5)   # a drone's flight phases
Sector = tuple[float, float, float, float]   # north_min, east_min, north_max, east_max (m)
Point = tuple[float, float]                  # north, east (m)


def split_area(area: Area, count: int) -> list[Sector]:
    """Split ``area`` into ``count`` rectangles of equal area: rows along north, columns along east.

    The number of rows follows the area's aspect ratio; when ``count`` is not a multiple of it,
    the first rows get one column more (their sectors are narrower).
    """
    n0, e0, n1, e1 = area
    height, width = n1 - n0, e1 - e0
    rows = min(count, max(1, round(math.sqrt(count * height / width))))
    base, extra = divmod(count, rows)
    sectors = []
    for r in range(rows):
        cols = base + (1 if r < extra else 0)
        row_n0 = n0 + height * r / rows
        row_n1 = n0 + height * (r + 1) / rows
        for c in range(cols):
            sectors.append((row_n0, e0 + width * c / cols, row_n1, e0 + width * (c + 1) / cols))
    return sectors


def assign_sectors(homes: dict[int, Point], sectors: list[Sector]) -> dict[int, Sector]:
    """Match drones to sectors minimising the total home-to-sector-centre distance."""
    ids = sorted(homes)
    cost = np.array([[math.dist(homes[i], ((s[0] + s[2]) / 2, (s[1] + s[3]) / 2)) for s in sectors]
                     for i in ids])
    rows, cols = linear_sum_assignment(cost)
    return {ids[r]: sectors[c] for r, c in zip(rows, cols, strict=True)}


def lawnmower(sector: Sector, sweep_width_m: float, start: Point) -> list[Point]:
    """A boustrophedon path covering ``sector`` with legs ``sweep_width_m`` apart (at most).

    Legs run along the sector's longer side and stop half a sweep width short of its edges (the
    footprint reaches them; neighbours' turns stay apart); the path starts from the corner
    nearest ``start``.
    """
    n0, e0, n1, e1 = sector
    legs_along_east = (e1 - e0) >= (n1 - n0)
    step_lo, step_hi, leg_lo, leg_hi = (n0, n1, e0, e1) if legs_along_east else (e0, e1, n0, n1)
    s_start, l_start = (start[0], start[1]) if legs_along_east else (start[1], start[0])
    legs = max(1, math.ceil((step_hi - step_lo) / sweep_width_m - 1e-9))
    spacing = (step_hi - step_lo) / legs
    steps = [step_lo + (k + 0.5) * spacing for k in range(legs)]
    if abs(s_start - step_hi) < abs(s_start - step_lo):
        steps.reverse()
    inset = min(sweep_width_m / 2, (leg_hi - leg_lo) / 2)  # the footprint still reaches the edge
    leg_lo, leg_hi = leg_lo + inset, leg_hi - inset
    ends = (leg_lo, leg_hi) if abs(l_start - leg_lo) <= abs(l_start - leg_hi) else (leg_hi, leg_lo)
    path = []
    for k, s in enumerate(steps):
        a, b = ends if k % 2 == 0 else ends[::-1]
        path.extend([(s, a), (s, b)])
    return path if legs_along_east else [(e, n) for n, e in path]


def encode_task(sector: Sector, altitude_m: float) -> str:
    return ":".join(f"{x:.2f}" for x in (*sector, altitude_m))


def decode_task(data: str) -> tuple[Sector, float]:
    n0, e0, n1, e1, alt = (float(x) for x in data.split(":"))
    return (n0, e0, n1, e1), alt


def altitudes_m(homes: dict[int, Point], sectors: dict[int, Sector], base_m: float,
                step_m: float) -> dict[int, float]:
    """One altitude per drone, ``step_m`` apart, the drone with the nearest sector lowest.

    Transits cross other sectors and other transits; distinct altitudes keep every pair of paths
    vertically separated (the near sectors' drones, which depart first, climb least).
    """
    def reach(i: int) -> float:
        n0, e0, n1, e1 = sectors[i]
        return math.dist(homes[i], ((n0 + n1) / 2, (e0 + e1) / 2))

    return {i: base_m + step_m * rank for rank, i in enumerate(sorted(sectors, key=lambda i: (reach(i), i)))}


class CoverageMap:
    """A 1 m grid over the area; a cell is covered once inside some drone's footprint."""

    def __init__(self, area: Area, footprint_m: float) -> None:
        self.area, self.footprint_m = area, footprint_m
        n0, e0, n1, e1 = area
        self.cells = np.zeros((math.ceil(n1 - n0), math.ceil(e1 - e0)), dtype=bool)

    def observe(self, n_m: float, e_m: float) -> None:
        """Mark the cells whose centres lie within the square footprint around (n, e)."""
        n0, e0, _, _ = self.area
        f = self.footprint_m
        rows, cols = self.cells.shape
        lo_n, hi_n = max(0, math.ceil(n_m - n0 - f - 0.5)), min(rows, math.floor(n_m - n0 + f - 0.5) + 1)
        lo_e, hi_e = max(0, math.ceil(e_m - e0 - f - 0.5)), min(cols, math.floor(e_m - e0 + f - 0.5) + 1)
        if lo_n < hi_n and lo_e < hi_e:
            self.cells[lo_n:hi_n, lo_e:hi_e] = True

    @property
    def covered_frac(self) -> float:
        return float(self.cells.mean())


@dataclass
class AirviewParams:
    """Typed ``params`` (see ``conf/algo/airview.yaml``)."""

    altitude_m: float = 10.0   # lowest flight altitude (and the altitude drones descend to at home)
    # each drone flies at its own altitude, this far apart (nearest sector lowest)
    altitude_step_m: float = 1.2
    sweep_width_m: float = 10.0   # at most this far between two legs (= 2 x footprint_m: no gaps)
    footprint_m: float = 5.0   # half side of the square sensor footprint (11 x 11 one-metre cells)
    min_alt_frac: float = 0.8   # the sensor counts above this fraction of altitude_m
    lookahead_m: float = 8.0   # moving setpoint this far ahead: cruise at about 0.95 x 8 = 7.6 m/s
    accept_m: float = 1.0   # horizontal waypoint acceptance radius
    coverage_period_s: float = 1.0   # period of the ground's `coverage` marker


class AirviewGround(GroundAlgorithm):
    """Assigns sectors at PREPARATION; tracks coverage during EXECUTION."""

    Params = AirviewParams

    def prep_once(self, ctx: GroundContext) -> None:
        p = ctx.params
        self.area = mission_area(ctx.mission.values, "airview")
        drones = sorted(ctx.reports)
        homes = {i: ctx.mission.initial_positions[i][:2] for i in drones}
        sectors = assign_sectors(homes, split_area(self.area, len(drones)))
        alts = altitudes_m(homes, sectors, float(p["altitude_m"]), float(p["altitude_step_m"]))
        for drone, sector in sectors.items():
            ctx.send_task(drone, code=0, data=encode_task(sector, alts[drone]))
            ctx.mark("sector_assigned", drone=drone, sector=[round(x, 2) for x in sector],
                     altitude_m=alts[drone])

    def exec_once(self, ctx: GroundContext) -> None:
        self.coverage = CoverageMap(self.area, float(ctx.params["footprint_m"]))
        self.next_mark_s = 0.0
        self.reached_90 = False
        self.min_alt_m = float(ctx.params["min_alt_frac"]) * float(ctx.params["altitude_m"])

    def exec_loop(self, ctx: GroundContext) -> None:
        for st in ctx.swarm.values():
            if st.stage == Stage.EXECUTION and -st.pos_ned_m[2] >= self.min_alt_m:
                self.coverage.observe(st.pos_ned_m[0], st.pos_ned_m[1])
        if ctx.stage_time_s >= self.next_mark_s:
            self.next_mark_s += float(ctx.params["coverage_period_s"])
            frac = self.coverage.covered_frac
            ctx.mark("coverage", covered_frac=round(frac, 5), covered_cells=int(self.coverage.cells.sum()))
            if frac >= 0.9 and not self.reached_90:
                self.reached_90 = True
                ctx.mark("coverage_90", covered_frac=round(frac, 5))


class AirviewDrone(DroneAlgorithm):
    """Climbs above home, flies the lawnmower path over its sector, returns and descends above home.

    The whole flight is at the altitude the ground assigned; the final descent goes down to
    ``altitude_m`` above home so that landing is short.
    """

    Params = AirviewParams

    def __init__(self) -> None:
        self.path: list[Point] = []
        self.alt_m = 0.0
        self.k = 0
        self.phase = CLIMB

    def on_task(self, ctx: DroneContext, task: Task) -> None:
        if self.path or not task.data:
            return
        sector, self.alt_m = decode_task(task.data)
        self.path = lawnmower(sector, float(ctx.params["sweep_width_m"]), ctx.home_ned_m[:2])
        ctx.mark("path_planned", waypoints=len(self.path), altitude_m=self.alt_m)

    def prep_complete(self, ctx: DroneContext) -> bool:
        return bool(self.path) and ctx.state.ready_to_arm

    def exec_loop(self, ctx: DroneContext) -> Setpoint:
        n, e, d = ctx.pos_ned_m
        home_n, home_e, _ = ctx.home_ned_m
        if self.phase == CLIMB:  # straight up first: no diagonal take-offs across the launch grid
            if -d >= self.alt_m - 0.5:
                self.phase = SURVEY
            return Setpoint.position(home_n, home_e, -self.alt_m, 0.0)
        if self.phase == SURVEY:
            accept = float(ctx.params["accept_m"])
            while self.k < len(self.path) and math.dist((n, e), self.path[self.k]) <= accept:
                self.k += 1
            if self.k < len(self.path):
                return self._carrot(ctx, self.path[self.k])
            self.phase = RETURN
            ctx.mark("path_done", waypoints=len(self.path))
        if self.phase == RETURN:
            if ctx.has_reached((home_n, home_e, -self.alt_m), d_m=1.0, v_m_s=1.0):
                self.phase = DESCEND
            return self._carrot(ctx, (home_n, home_e))
        low_m = min(self.alt_m, float(ctx.params["altitude_m"]))
        if self.phase == DESCEND and -d <= low_m + 0.5:
            self.phase = DONE
        return Setpoint.position(home_n, home_e, -low_m)

    def _carrot(self, ctx: DroneContext, goal: Point) -> Setpoint:
        """A position setpoint at most ``lookahead_m`` ahead towards ``goal`` (caps the speed)."""
        n, e, _ = ctx.pos_ned_m
        dn, de = goal[0] - n, goal[1] - e
        dist = math.hypot(dn, de)
        if dist < 1.0:
            return Setpoint.position(goal[0], goal[1], -self.alt_m)
        step = min(dist, float(ctx.params["lookahead_m"]))
        return Setpoint.position(n + dn / dist * step, e + de / dist * step, -self.alt_m, math.atan2(de, dn))

    def exec_complete(self, ctx: DroneContext) -> bool:
        return self.phase == DONE
