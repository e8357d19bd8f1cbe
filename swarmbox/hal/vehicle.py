"""The contract between the swarm core and a flight stack.

A :class:`Backend` owns a fleet of :class:`Vehicle` objects and advances them together (a simulator
steps its physics once for all vehicles; a MAVLink bridge services all its links). Commands are
requests: their effect shows up in later telemetry, exactly as with a real autopilot.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, NamedTuple, Protocol, runtime_checkable

from swarmbox.api import Setpoint, SetpointVerdict, Telemetry

Vec3 = tuple[float, float, float]


class VehicleEvent(NamedTuple):
    """Something a backend observed that belongs in the logs.

    ``kind`` is one of ``collision``, ``safety``, ``command``, ``estimator``, ``link`` or ``fault``;
    ``name`` says what happened (e.g. ``setpoint_refused``, ``drone_drone``, ``nack``); ``data``
    holds details.
    """

    t_s: float
    drone_id: int
    kind: str
    name: str
    data: dict[str, Any]


@runtime_checkable
class Vehicle(Protocol):
    """One drone's autopilot, in the mission frame."""

    drone_id: int
    home_ned_m: Vec3

    def arm(self) -> None:
        """Request arming (ignored unless ready to arm)."""

    def disarm(self) -> None:
        """Request disarming (only honoured on the ground)."""

    def takeoff(self, alt_m: float) -> None:
        """Climb vertically to ``alt_m`` above home and hold."""

    def setpoint(self, sp: Setpoint) -> SetpointVerdict:
        """Follow ``sp`` (position / velocity / acceleration, NED mission frame) in OFFBOARD mode.

        The backend's safety monitor refuses non-finite setpoints and keeps every kind within the
        speed, acceleration, geofence, ceiling and floor limits (docs/core.md, "Safety envelope"),
        emitting a ``safety`` event for each change; the returned verdict (ok / clamped / refused, or
        ignored when the vehicle cannot follow setpoints now, with the reason) goes to the log.
        """

    def land(self) -> None:
        """Descend where it is, touch down, disarm."""

    def return_to_launch(self) -> None:
        """Climb to the return altitude, fly home, land, disarm."""

    def hold(self) -> None:
        """Stop and hold the current position."""

    def telemetry(self) -> Telemetry:
        """The latest state (cheap: called every tick)."""


@runtime_checkable
class Backend(Protocol):
    """A fleet of vehicles advanced together.

    ``realtime`` False means the run loop may advance a virtual clock as fast as it likes
    (simulation); True means the loop paces itself on the wall clock (MAVLink, hardware).
    """

    realtime: bool
    vehicles: Sequence[Vehicle]

    def step(self, dt_s: float) -> None:
        """Advance the fleet by one tick (simulate, or service the links)."""

    def drain_events(self) -> list[VehicleEvent]:
        """Events since the last call (collisions, safety interventions, command failures...)."""

    def close(self) -> None:
        """Release every resource (processes, sockets); safe to call twice."""
