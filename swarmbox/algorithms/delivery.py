"""Package delivery (paper RQ4): nine allocation algorithms = 3 sorting rules x 3 assignment methods.

The mission's ``values`` are the packages (id -> [north, east], drop-off points around the depot).
Every delivery is a round trip: the drone flies from its home to the drop-off point at its own cruise
altitude and back; pickup and drop-off are instantaneous, a delivery counts on arrival (within
``arrival_tolerance_m`` and slower than ``arrival_speed_m_s``). Drone d cruises at
``cruise_altitude_m + altitude_step_m * d`` so that crossing paths never meet.

The ground (the dispatcher) sorts the packages and, by ``params.assign``:

- ``block`` / ``rr``: in PREPARATION sends every drone its whole list (task code PLAN, possibly
  empty); the drone is ready once it has its list;
- ``dynamic``: on entering EXECUTION sends every drone one package (code NEXT); each time a drone's
  Report shows its package delivered it sends the next package in sorted order, or END when none is
  left.

Drones report the ids of the packages they have delivered (all of them, in order) in every Report's
data, so a lost Report loses nothing. The ground marks ``delivered`` (fields package, drone) the first
time it sees a package there: the delivery-wait metric. A drone marks ``arrived`` at each drop-off
point. A drone is complete once its work is closed (PLAN or END received), nothing is left and it is
back home; the ground holds EXECUTION open until every package has been reported delivered.
All commands are reliable (acknowledged and re-sent), so a lost message cannot stall the mission.
Packages of a drone that is lost are not handed to another one: the mission then ends with the
EXECUTION timeout (status aborted, with the reason).

Params (``conf/delivery_base.yaml``): ``sort`` (none | azimuth | distance), ``assign`` (block |
rr | dynamic), ``cruise_altitude_m``, ``altitude_step_m``, ``arrival_tolerance_m``,
``arrival_speed_m_s``. Markers: ground ``plan`` (sort, assign, packages, order), ``assigned`` (drone,
packages), ``delivered`` (package, drone, count), ``duplicate`` (package, drone, first_drone);
drone ``received`` (packages), ``arrived`` (package, north_m, east_m), ``returned`` (package).

Difference from the reference implementation: its drones kept their packages in an id-ordered map
and always flew the smallest undelivered id, so in the pre-assigned modes the sorting rule chose
*which* packages a drone got but not the order it flew them. Here a drone flies its packages in the
assigned (sorted) order, as the paper describes. Also fixed: the ground records deliveries by package
id (the reference indexed its sorted list by id), block assignment works for any package count, a
drone with no package completes, and ties in sorting keep package-id order.

Sorting and assignment rules and the dataset generators are in :mod:`swarmbox.algorithms.delivery_plan`.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass
from enum import Enum

from swarmbox.api import DroneAlgorithm, DroneContext, GroundAlgorithm, GroundContext, Setpoint, Task

from .delivery_plan import (
    END,
    NEXT,
    PLAN,
    Package,
    assign_packages,
    decode_ids,
    decode_packages,
    encode_ids,
    encode_packages,
    packages_of,
    paper_points,
    random_points,
    sort_packages,
    strategy_of,
)

__all__ = ["DeliveryDrone", "DeliveryGround", "paper_points", "random_points"]


@dataclass
class DeliveryParams:
    """Typed ``params`` (see ``conf/delivery_base.yaml``)."""

    sort: str = 'distance'   # none | azimuth | distance (from the origin)
    assign: str = 'dynamic'   # block | rr | dynamic
    cruise_altitude_m: float = 10.0   # drone d cruises at cruise_altitude_m + altitude_step_m * d
    altitude_step_m: float = 2.0
    arrival_tolerance_m: float = 0.7   # a point is reached within this distance (3-D) ...
    arrival_speed_m_s: float = 0.7   # ... and below this speed


class DeliveryGround(GroundAlgorithm):
    """The dispatcher: sorts, assigns, records deliveries, holds EXECUTION until all are delivered."""

    Params = DeliveryParams

    def prep_once(self, ctx: GroundContext) -> None:
        self.strategy = strategy_of(ctx.params)
        self.drones = sorted(ctx.mission.initial_positions)
        missing = sorted(set(self.drones) - set(ctx.reports))
        if missing:
            raise ValueError(f"delivery needs every drone under the ground (topology centralized); "
                             f"drones {missing} are not direct inferiors")
        self.packages = packages_of(ctx.mission.values)
        self.pending = deque(sort_packages(self.packages, self.strategy.sort))
        self.delivered_by: dict[int, int] = {}
        self.outstanding: dict[int, int | None] = {}
        self._seen: dict[int, str] = {}
        self._counted: dict[int, set[int]] = {}
        ctx.mark("plan", sort=self.strategy.sort, assign=self.strategy.assign, packages=len(self.packages),
                 order=[p.id for p in self.pending])
        if self.strategy.preplanned:
            self._preassign(ctx)

    def _preassign(self, ctx: GroundContext) -> None:
        plan = assign_packages(list(self.pending), self.drones, self.strategy.assign)
        self.pending.clear()
        for drone, packages in plan.items():
            ctx.send_task(drone, code=PLAN, data=encode_packages(packages))
            ctx.mark("assigned", drone=drone, packages=[p.id for p in packages])

    def exec_once(self, ctx: GroundContext) -> None:
        if not self.strategy.preplanned:
            for drone in self.drones:
                self._dispatch(ctx, drone)

    def _dispatch(self, ctx: GroundContext, drone: int) -> None:
        """Give ``drone`` the next sorted package, or END when none is left."""
        if self.pending:
            package = self.pending.popleft()
            self.outstanding[drone] = package.id
            ctx.send_task(drone, code=NEXT, data=encode_packages([package]))
            ctx.mark("assigned", drone=drone, packages=[package.id])
        else:
            self.outstanding[drone] = None
            ctx.send_task(drone, code=END)

    def exec_loop(self, ctx: GroundContext) -> None:
        seen = self._seen
        for drone, report in sorted(ctx.reports.items()):
            data = report.data
            if data == seen.get(drone):
                continue
            seen[drone] = data
            for pid in decode_ids(data):
                self._record(ctx, pid, drone)
            outstanding = self.outstanding.get(drone)
            if outstanding is not None and outstanding in self.delivered_by:
                self._dispatch(ctx, drone)

    def _record(self, ctx: GroundContext, pid: int, drone: int) -> None:
        """Count a package id seen in ``drone``'s Report (each (drone, package) once)."""
        counted = self._counted.setdefault(drone, set())
        if pid in counted:
            return
        counted.add(pid)
        first = self.delivered_by.setdefault(pid, drone)
        if first != drone:
            ctx.mark("duplicate", package=pid, drone=drone, first_drone=first)
        else:
            ctx.mark("delivered", package=pid, drone=drone, count=len(self.delivered_by))

    def exec_complete(self, ctx: GroundContext) -> bool:
        return len(self.delivered_by) == len(self.packages)


class Phase(Enum):
    CLIMB = "climb"   # taking off to cruise altitude above home
    HOME = "home"     # hovering above home, waiting for work
    OUT = "out"       # flying to a drop-off point
    BACK = "back"     # flying home from a drop-off point


class DeliveryDrone(DroneAlgorithm):
    """Flies its packages one round trip at a time, in the order the ground gave them."""

    Params = DeliveryParams

    def __init__(self) -> None:
        self.queue: deque[Package] = deque()   # received, not yet flown, in the ground's order
        self.delivered: list[int] = []         # package ids, in delivery order
        self.closed = False                    # PLAN or END received: no more work will come

    def prep_once(self, ctx: DroneContext) -> None:
        self.strategy = strategy_of(ctx.params)

    def on_task(self, ctx: DroneContext, task: Task) -> None:
        if task.code in (PLAN, NEXT):
            packages = decode_packages(task.data)
            self.queue.extend(packages)
            ctx.mark("received", packages=[p.id for p in packages])
        self.closed = self.closed or task.code in (PLAN, END)

    def prep_complete(self, ctx: DroneContext) -> bool:
        return ctx.state.ready_to_arm and (self.closed or not self.strategy.preplanned)

    def exec_once(self, ctx: DroneContext) -> None:
        p = ctx.params
        n, e, _ = ctx.home_ned_m
        alt = float(p["cruise_altitude_m"]) + float(p["altitude_step_m"]) * ctx.id
        self.home = (n, e, -alt)
        self.tol_m, self.speed_m_s = float(p["arrival_tolerance_m"]), float(p["arrival_speed_m_s"])
        self.phase = Phase.CLIMB
        self.current: Package | None = None
        self._climb_sent = False

    def exec_loop(self, ctx: DroneContext) -> Setpoint | None:
        if self.phase is Phase.CLIMB:
            if not ctx.has_reached(self.home, self.tol_m, self.speed_m_s):
                return self._climb()
            self.phase = Phase.HOME
        elif self.phase is Phase.OUT:
            return self._outbound(ctx)
        elif self.phase is Phase.BACK:
            if not ctx.has_reached(self.home, self.tol_m, self.speed_m_s):
                return None
            self.phase = Phase.HOME
            ctx.mark("returned", package=self.current.id)
        if self.queue:
            return self._depart(ctx)
        return None

    def _climb(self) -> Setpoint | None:
        if self._climb_sent:
            return None
        self._climb_sent = True
        return Setpoint.position(*self.home, 0.0)

    def _depart(self, ctx: DroneContext) -> Setpoint:
        self.current = self.queue.popleft()
        self.phase = Phase.OUT
        target = (self.current.north_m, self.current.east_m, self.home[2])
        return Setpoint.position(*target, _bearing(ctx.pos_ned_m, target))

    def _outbound(self, ctx: DroneContext) -> Setpoint | None:
        pkg = self.current
        target = (pkg.north_m, pkg.east_m, self.home[2])
        if not ctx.has_reached(target, self.tol_m, self.speed_m_s):
            return None
        self.delivered.append(pkg.id)
        ctx.report_data = encode_ids(self.delivered)
        ctx.mark("arrived", package=pkg.id, north_m=pkg.north_m, east_m=pkg.east_m)
        self.phase = Phase.BACK
        return Setpoint.position(*self.home, _bearing(ctx.pos_ned_m, self.home))

    def exec_complete(self, ctx: DroneContext) -> bool:
        return self.closed and not self.queue and self.phase is Phase.HOME


def _bearing(frm: tuple[float, float, float], to: tuple[float, float, float]) -> float:
    """Heading (rad, from north toward east) from ``frm`` to ``to``."""
    return math.atan2(to[1] - frm[1], to[0] - frm[0])
