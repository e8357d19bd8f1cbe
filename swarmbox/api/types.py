"""The values user code sees: stages, setpoints, the drone's own state and the views of what the
network delivered. All are immutable ``NamedTuple``s or enums; none carries a wire detail (message
ids, counters, encoded sizes) or simulator ground truth."""

from __future__ import annotations

import math
from collections.abc import Mapping
from enum import IntEnum, StrEnum
from typing import Any, NamedTuple

Vec3 = tuple[float, float, float]


def wrap_angle(rad: float) -> float:
    """Wrap an angle to (-pi, pi]."""
    w = math.fmod(rad + math.pi, 2 * math.pi)
    if w <= 0:
        w += 2 * math.pi
    return w - math.pi


class Stage(IntEnum):
    """Mission stages. Codes match the reference implementation (ABORT is -1).

    The legal transitions live with the state machine in ``swarmbox.core.stages``.
    """

    ABORT = -1
    ICEBREAK = 1
    PREPARATION = 2
    EXECUTION = 3
    LANDING = 4
    TERMINATION = 5


class SetpointKind(IntEnum):
    POSITION = 0
    VELOCITY = 1
    ACCELERATION = 2


_POSITION, _VELOCITY, _ACCELERATION = SetpointKind.POSITION, SetpointKind.VELOCITY, SetpointKind.ACCELERATION


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
        # tuple.__new__: the NamedTuple's own constructor is one more Python call per drone and tick
        return tuple.__new__(cls, (_POSITION, (float(n_m), float(e_m), float(d_m)), yaw_rad))

    @classmethod
    def velocity(cls, n_m_s: float, e_m_s: float, d_m_s: float,
                 yaw_rad: float | None = None) -> Setpoint:
        return tuple.__new__(cls, (_VELOCITY, (float(n_m_s), float(e_m_s), float(d_m_s)),
                                   yaw_rad))

    @classmethod
    def acceleration(cls, n_m_s2: float, e_m_s2: float, d_m_s2: float,
                     yaw_rad: float | None = None) -> Setpoint:
        return tuple.__new__(cls, (_ACCELERATION, (float(n_m_s2), float(e_m_s2), float(d_m_s2)),
                                   yaw_rad))


class SetpointVerdict(NamedTuple):
    """What the vehicle's safety monitor did with one setpoint.

    ``action`` is ``ok``, ``clamped`` (``flown`` is the corrected setpoint) or ``refused``
    (``flown`` is None); ``reason`` says why for anything but ``ok``.
    """

    action: str
    reason: str = ""
    flown: Setpoint | None = None


class FlightMode(StrEnum):
    """What the vehicle's autopilot is doing, as reported in telemetry."""

    IDLE = "idle"          # on the ground, disarmed or waiting
    OFFBOARD = "offboard"  # following setpoints
    TAKEOFF = "takeoff"
    HOLD = "hold"
    LAND = "land"
    RTL = "rtl"


class Telemetry(NamedTuple):
    """One vehicle's state as its backend reports it to the framework, in the mission frame.

    ``pos_ned_m`` is the autopilot's *estimate*; ``gnss_ned_m`` the latest GNSS fix (None before the
    first) and ``gnss_seq`` counts fixes. ``true_pos_ned_m`` is ground truth, known only to
    simulators (None on hardware): the recorder logs it, but no algorithm ever sees it — hooks get
    a :class:`DroneState`.
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


class DroneState(NamedTuple):
    """A drone's own state as its autopilot knows it (what a real drone knows: no ground truth)."""

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
    link_ok: bool

    @classmethod
    def of(cls, tel: Telemetry) -> DroneState:
        return cls(tel.t_s, tel.pos_ned_m, tel.vel_ned_m_s, tel.yaw_rad, tel.gnss_ned_m, tel.gnss_seq,
                   tel.armed, tel.landed, tel.mode, tel.battery_frac, tel.ready_to_arm, tel.link_ok)


class MissionInfo(NamedTuple):
    """The mission as configured: visible to every node."""

    name: str
    swarm_size: int
    initial_positions: Mapping[int, Vec3]
    superiors: Mapping[int, int]
    values: Mapping[int, tuple[float, ...]]
    obstacles: tuple[Mapping[str, Any], ...] = ()   # static obstacles, as in the mission config


class DescendantState(NamedTuple):
    """A drone's stage and position as forwarded up the hierarchy (inside its superior's Report)."""

    drone_id: int
    stage: int
    pos_ned_m: Vec3


class InferiorReport(NamedTuple):
    """The latest Report of a direct inferior, as the network delivered it.

    ``received_s`` is the receiving node's clock when it arrived (compare with ``ctx.time_s`` to
    tell its age).
    """

    id: int
    stage: Stage
    complete: bool
    pos_ned_m: Vec3
    vel_ned_m_s: Vec3
    data: str
    received_s: float


class PeerState(NamedTuple):
    """A peer's latest Heartbeat: its stage, position and velocity, and when it arrived."""

    id: int
    stage: Stage
    pos_ned_m: Vec3
    vel_ned_m_s: Vec3
    received_s: float


class Task(NamedTuple):
    """A task command from a superior. Its meaning (``code``, ``data``) belongs to the algorithm.

    ``seq`` numbers the sender's commands to this drone; reliable ones reach ``on_task`` exactly
    once and in ``seq`` order.
    """

    src: int
    seq: int
    reliable: bool
    code: int
    waypoint_ned_m: Vec3 | None
    yaw_rad: float | None
    data: str
    received_s: float
