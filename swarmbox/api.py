"""The algorithm API: everything a swarm algorithm may touch, and nothing more.

An algorithm is two small classes, one per role::

    class MyDrone(DroneAlgorithm):            # one instance per drone
        def exec_loop(self, ctx): return Setpoint.position(0, 0, -3)
        def exec_complete(self, ctx): return ctx.stage_time_s > 10

    class MyGround(GroundAlgorithm):          # one instance on the ground node
        def prep_once(self, ctx): ...

plus one YAML file in ``conf/algo/`` naming them. The framework owns the lifecycle (the ``@final``
driver methods); user code overrides the hooks. Hooks receive a *context*: a narrow façade over the
node that runs them — own telemetry in the mission frame, reports as delivered by the network,
``send_task``, ``mark``, ``params`` and a seeded ``rng``. No backend object ever reaches user code,
so the same classes fly on the pymunk simulator, on PX4 and on real drones.

Frames and units: positions are NED metres in the mission frame (north, east, down; altitude 3 m is
``d = -3``), velocities m/s, angles radians, times seconds.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from enum import IntEnum, StrEnum
from typing import TYPE_CHECKING, Any, NamedTuple, final

from swarmbox.area import Area, mission_area, mission_grid
from swarmbox.core.messages import DescendantState, Heartbeat, ProxAlert, Report, TaskCommand
from swarmbox.core.stages import Stage

if TYPE_CHECKING:  # only for type checkers: the node classes stay out of the user's namespace
    import numpy as np

__all__ = [
    "Area", "DescendantState", "DroneAlgorithm", "DroneContext", "FlightMode", "GroundAlgorithm",
    "GroundContext", "Heartbeat", "MissionInfo", "ProxAlert", "Report", "Setpoint", "SetpointKind",
    "Stage", "TaskCommand", "Telemetry", "mission_area", "mission_grid", "wrap_angle",
]

Vec3 = tuple[float, float, float]


def wrap_angle(rad: float) -> float:
    """Wrap an angle to (-pi, pi]."""
    w = math.fmod(rad + math.pi, 2 * math.pi)
    if w <= 0:
        w += 2 * math.pi
    return w - math.pi


class SetpointKind(IntEnum):
    POSITION = 0
    VELOCITY = 1
    ACCELERATION = 2


class Setpoint(NamedTuple):
    """A target for the vehicle's controller, in the mission's NED frame.

    ``ned`` is metres for POSITION, m/s for VELOCITY and m/s² for ACCELERATION. ``yaw_rad`` None
    keeps the current heading.
    """

    kind: SetpointKind
    ned: Vec3
    yaw_rad: float | None = None

    @classmethod
    def position(cls, n_m: float, e_m: float, d_m: float, yaw_rad: float | None = None) -> Setpoint:
        return cls(SetpointKind.POSITION, (float(n_m), float(e_m), float(d_m)), yaw_rad)

    @classmethod
    def velocity(cls, n_m_s: float, e_m_s: float, d_m_s: float,
                 yaw_rad: float | None = None) -> Setpoint:
        return cls(SetpointKind.VELOCITY, (float(n_m_s), float(e_m_s), float(d_m_s)), yaw_rad)

    @classmethod
    def acceleration(cls, n_m_s2: float, e_m_s2: float, d_m_s2: float,
                     yaw_rad: float | None = None) -> Setpoint:
        return cls(SetpointKind.ACCELERATION, (float(n_m_s2), float(e_m_s2), float(d_m_s2)), yaw_rad)


class FlightMode(StrEnum):
    """What the vehicle's autopilot is doing, as reported in telemetry."""

    IDLE = "idle"          # on the ground, disarmed or waiting
    OFFBOARD = "offboard"  # following setpoints
    TAKEOFF = "takeoff"
    HOLD = "hold"
    LAND = "land"
    RTL = "rtl"


class Telemetry(NamedTuple):
    """One vehicle's state as its autopilot reports it, in the mission frame.

    ``pos_ned_m`` is the autopilot's *estimate* (what a real drone knows); ``gnss_ned_m`` is the
    latest GNSS fix (None before the first) and ``gnss_seq`` counts fixes, so a new fix can be told
    from an old one. ``true_pos_ned_m`` is ground truth, known only to simulators (None on hardware).
    """

    t_s: float
    pos_ned_m: Vec3
    vel_ned_m_s: Vec3
    yaw_rad: float
    gnss_ned_m: Vec3 | None
    gnss_seq: int
    armed: bool
    landed: bool
    mode: FlightMode
    battery_frac: float
    ready_to_arm: bool
    true_pos_ned_m: Vec3 | None
    link_ok: bool = True


class MissionInfo(NamedTuple):
    """The mission as configured: visible to every node."""

    name: str
    swarm_size: int
    initial_positions: Mapping[int, Vec3]
    superiors: Mapping[int, int]
    values: Mapping[int, tuple[float, ...]]
    obstacles: tuple[Mapping[str, Any], ...] = ()   # static obstacles, as in the mission config


class _Context:
    """What both kinds of context share."""

    __slots__ = ("_node",)

    def __init__(self, node: Any) -> None:
        self._node = node

    @property
    def stage(self) -> Stage:
        return self._node.stage

    @property
    def tick(self) -> int:
        """Ticks since this node entered its current stage (0 on the entry tick)."""
        return self._node.stage_tick

    @property
    def time_s(self) -> float:
        """This node's local clock."""
        return self._node.clock.now()

    @property
    def stage_time_s(self) -> float:
        """Seconds since this node entered its current stage (ticks × tick period)."""
        return self._node.stage_tick * self._node.tick_s

    @property
    def tick_s(self) -> float:
        return self._node.tick_s

    @property
    def params(self) -> Mapping[str, Any]:
        """The algorithm's ``params`` from its config (read-only)."""
        return self._node.params

    @property
    def rng(self) -> np.random.Generator:
        """This node's own seeded random generator; use it for every random choice."""
        return self._node.rng

    @property
    def mission(self) -> MissionInfo:
        return self._node.mission

    def mark(self, name: str, **fields: Any) -> None:
        """Record a named event marker (with JSON-serialisable fields) in this node's log.

        Markers turn into mission metrics in the analyzer (see ``metrics`` in the algo config).
        """
        self._node.mark(name, fields)

    def send_task(self, dst: int, *, code: int = 0, waypoint_ned_m: Sequence[float] | None = None,
                  yaw_rad: float | None = None, data: str = "", reliable: bool = True) -> None:
        """Send a TaskCommand to a direct inferior ``dst``.

        Reliable commands (the default) are acknowledged and re-sent until they are, so a lost
        packet cannot stall the mission; pass ``reliable=False`` for streams re-sent every tick.
        """
        wp = None if waypoint_ned_m is None else tuple(float(x) for x in waypoint_ned_m)
        self._node.send_task(dst, code, wp, None if yaw_rad is None else float(yaw_rad), data,
                             reliable)


@final
class DroneContext(_Context):
    """What a drone's algorithm sees."""

    __slots__ = ()

    @property
    def id(self) -> int:
        return self._node.node_id

    @property
    def superior(self) -> int:
        """Current superior (-1 = the ground); changes on a handover."""
        return self._node.superior

    @property
    def state(self) -> Telemetry:
        return self._node.telemetry

    @property
    def pos_ned_m(self) -> Vec3:
        return self._node.telemetry.pos_ned_m

    @property
    def vel_ned_m_s(self) -> Vec3:
        return self._node.telemetry.vel_ned_m_s

    @property
    def home_ned_m(self) -> Vec3:
        """This drone's launch point in the mission frame (its ``initial_positions`` entry)."""
        return self._node.home_ned_m

    @property
    def inferiors(self) -> Mapping[int, Report]:
        """Latest Report of each alive direct inferior, as delivered by the network."""
        return self._node.alive_reports()

    @property
    def peers(self) -> Mapping[int, Heartbeat]:
        """Latest Heartbeat (with position and velocity) of each peer this drone listens to."""
        return self._node.peer_heartbeats

    @property
    def last_task(self) -> TaskCommand | None:
        """The most recent TaskCommand received (each one also goes to ``on_task``)."""
        return self._node.last_task

    @property
    def proximity(self) -> tuple[DescendantState, ...]:
        """Drones the ground saw within ``run.proximity_m`` of this one (its latest ProxAlert).

        Empty once the ground sends its all-clear, or when no alert came for ``lost_inferior_ticks``.
        """
        alert = self._node.prox_alert
        return () if alert is None else alert.neighbours

    @property
    def report_data(self) -> str:
        return self._node.report_data

    @report_data.setter
    def report_data(self, value: str) -> None:
        """Free-form payload carried by every following Report to the superior."""
        self._node.report_data = str(value)

    def has_reached(self, target_ned_m: Sequence[float], d_m: float = 0.7, v_m_s: float = 0.7) -> bool:
        """True when within ``d_m`` (3-D) of the target and slower than ``v_m_s``."""
        p, v = self._node.telemetry.pos_ned_m, self._node.telemetry.vel_ned_m_s
        dist = math.dist(p, target_ned_m)
        return dist <= d_m and math.hypot(*v) <= v_m_s


@final
class GroundContext(_Context):
    """What the ground algorithm sees."""

    __slots__ = ()

    @property
    def reports(self) -> Mapping[int, Report]:
        """Latest Report of each alive direct inferior, as delivered by the network."""
        return self._node.alive_reports()

    @property
    def alive(self) -> frozenset[int]:
        """Direct inferiors currently heard from."""
        return frozenset(self._node.alive_reports())

    @property
    def swarm(self) -> Mapping[int, DescendantState]:
        """Every drone the ground knows of (direct inferiors and the descendants they forward)."""
        return self._node.swarm_view()

    @property
    def swarm_size(self) -> int:
        return self._node.mission.swarm_size


class DroneAlgorithm:
    """Base class of a drone's algorithm (one instance per drone).

    Hooks, in lifecycle order (each receives a :class:`DroneContext`):

    - ``prep_once`` — once, on entering PREPARATION.
    - ``prep_loop`` — every tick of PREPARATION.
    - ``prep_complete`` -> bool — every tick of PREPARATION; default: the vehicle is ready to arm.
    - ``exec_once`` — once, on entering EXECUTION (the framework arms the vehicle first).
    - ``exec_loop`` -> Setpoint | None — every tick of EXECUTION once armed; None keeps the last
      setpoint. **Required.**
    - ``exec_complete`` -> bool — every tick of EXECUTION; may flip back. **Required.**
    - ``on_task(ctx, task)`` — for every TaskCommand delivered, in order, before the tick's loop hook.
    - ``on_report(ctx, report)`` — for every Report delivered from a direct inferior.
    - ``on_prox_alert(ctx, alert)`` — for every ProxAlert from the ground: every tick while other
      drones are within ``run.proximity_m`` (``alert.neighbours``), then once empty (all clear).
    - ``successors`` -> Sequence[int] — the fallback superiors this drone advertises to its own
      inferiors; default: its own superior.

    Landing, termination, arming, failsafes and messaging are the framework's job.
    """

    def prep_once(self, ctx: DroneContext) -> None:
        """Called once on entering PREPARATION."""

    def prep_loop(self, ctx: DroneContext) -> None:
        """Called every tick of PREPARATION."""

    def prep_complete(self, ctx: DroneContext) -> bool:
        return ctx.state.ready_to_arm

    def exec_once(self, ctx: DroneContext) -> None:
        """Called once on entering EXECUTION."""

    def exec_loop(self, ctx: DroneContext) -> Setpoint | None:
        raise NotImplementedError(f"{type(self).__name__} must implement exec_loop")

    def exec_complete(self, ctx: DroneContext) -> bool:
        raise NotImplementedError(f"{type(self).__name__} must implement exec_complete")

    def on_task(self, ctx: DroneContext, task: TaskCommand) -> None:
        """Called for every TaskCommand delivered to this drone."""

    def on_report(self, ctx: DroneContext, report: Report) -> None:
        """Called for every Report delivered from a direct inferior."""

    def on_prox_alert(self, ctx: DroneContext, alert: ProxAlert) -> None:
        """Called for every ProxAlert delivered (``alert.neighbours``: ids and reported positions)."""

    def successors(self, ctx: DroneContext) -> Sequence[int]:
        return (ctx.superior,)

    @final
    def enter_stage(self, stage: Stage, ctx: DroneContext) -> None:
        """Framework driver: run the entry hook of ``stage``."""
        if stage is Stage.PREPARATION:
            self.prep_once(ctx)
        elif stage is Stage.EXECUTION:
            self.exec_once(ctx)

    @final
    def run_stage(self, stage: Stage, ctx: DroneContext) -> tuple[bool, Setpoint | None]:
        """Framework driver: one tick of ``stage``; returns (complete, setpoint)."""
        if stage is Stage.PREPARATION:
            self.prep_loop(ctx)
            return bool(self.prep_complete(ctx)), None
        if stage is Stage.EXECUTION:
            sp = self.exec_loop(ctx) if ctx.state.armed else None
            return bool(self.exec_complete(ctx)), sp
        return True, None


class GroundAlgorithm:
    """Base class of the ground node's algorithm (one instance per run).

    Hooks (each receives a :class:`GroundContext`): ``prep_once``, ``prep_loop``, ``exec_once``,
    ``exec_loop``, ``exec_complete`` -> bool (default True: EXECUTION ends when every drone reports
    complete; return False to hold it open), ``on_report(ctx, report)`` for every Report delivered.
    The ground's progress through the stages is decided by the drones' Reports and the stage
    timeouts; the hooks only add mission logic.
    """

    def prep_once(self, ctx: GroundContext) -> None:
        """Called once on entering PREPARATION (e.g. assign tasks)."""

    def prep_loop(self, ctx: GroundContext) -> None:
        """Called every tick of PREPARATION."""

    def exec_once(self, ctx: GroundContext) -> None:
        """Called once on entering EXECUTION."""

    def exec_loop(self, ctx: GroundContext) -> None:
        """Called every tick of EXECUTION."""

    def exec_complete(self, ctx: GroundContext) -> bool:
        return True

    def on_report(self, ctx: GroundContext, report: Report) -> None:
        """Called for every Report delivered from a direct inferior."""

    @final
    def enter_stage(self, stage: Stage, ctx: GroundContext) -> None:
        """Framework driver: run the entry hook of ``stage``."""
        if stage is Stage.PREPARATION:
            self.prep_once(ctx)
        elif stage is Stage.EXECUTION:
            self.exec_once(ctx)

    @final
    def run_stage(self, stage: Stage, ctx: GroundContext) -> bool:
        """Framework driver: one tick of ``stage``; returns whether the ground is satisfied."""
        if stage is Stage.PREPARATION:
            self.prep_loop(ctx)
        elif stage is Stage.EXECUTION:
            self.exec_loop(ctx)
            return bool(self.exec_complete(ctx))
        return True
