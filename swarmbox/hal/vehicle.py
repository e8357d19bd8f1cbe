"""The contract between the swarm core and a flight stack: :class:`Vehicle`, :class:`Backend` and
:class:`VehicleEvent` (defined with the core's other ports in :mod:`swarmbox.core.ports`)."""

from swarmbox.core.ports import Backend, Vec3, Vehicle, VehicleEvent

__all__ = ["Backend", "Vec3", "Vehicle", "VehicleEvent"]
