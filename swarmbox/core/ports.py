"""The core's ports: what the swarm core needs from a network and from a flight stack, as Protocols.

The core is written against these and nothing else: the in-process simulated network
(:class:`swarmbox.net.medium.SimMedium`) and Zenoh (:class:`swarmbox.net.zenoh_medium.ZenohMedium`) are
:class:`Network` s; the simulator (:class:`swarmbox.hal.sim.SimBackend`) and the PX4 bridge
(:class:`swarmbox.hal.px4.Px4Backend`) are :class:`Backend` s of :class:`Vehicle` s. A new backend or
transport implements these; the conformance suites in :mod:`swarmbox.testing` check it does.

A :class:`Backend` owns a fleet of :class:`Vehicle` objects and advances them together (a simulator
steps its physics once for all vehicles; a MAVLink bridge services all its links). Commands are
requests: their effect shows up in later telemetry, exactly as with a real autopilot.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, Any, NamedTuple, Protocol, runtime_checkable

from swarmbox.api import Setpoint, SetpointVerdict, Telemetry

if TYPE_CHECKING:   # annotations only: the ports load no numpy (a backend check never needs it)
    from swarmbox.core.clock import NodeClock


class Transport(Protocol):
    """What a node needs from the network."""

    def send(self, msg: Any, dst: int) -> None: ...
    def publish(self, msg: Any) -> None: ...
    def subscribe(self, subscriber: int, publisher: int) -> None: ...
    def unsubscribe(self, subscriber: int, publisher: int) -> None: ...
    def has_subscribers(self, publisher: int) -> bool: ...


class Network(Transport, Protocol):
    """What the tick loop needs of a network besides a node's view of it (``swarmbox.net.transport.Medium``
    adds the fault hooks)."""

    def register(self, node_id: int, clock: NodeClock, log: Callable[[bytes], None]) -> list:
        """Attach a node; returns the inbox list it drains each tick."""

    def disconnect(self, node_id: int) -> None:
        """The node falls silent: nothing it sends leaves, nothing reaches it."""

    def deliver_due(self) -> None:
        """Hand every message due by now to its node's inbox, logging a ``recv`` (or ``drop``) row."""


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
