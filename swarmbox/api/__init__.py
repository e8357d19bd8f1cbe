"""The algorithm API: everything a swarm algorithm may touch, and nothing more.

An algorithm is two small classes, one per role::

    class MyDrone(DroneAlgorithm):            # one instance per drone
        def exec_loop(self, ctx): return Setpoint.position(0, 0, -3)
        def exec_complete(self, ctx): return ctx.stage_time_s > 10

    class MyGround(GroundAlgorithm):          # one instance on the ground node
        def prep_once(self, ctx): ...

plus one YAML file in ``conf/algo/`` naming them (a drone algorithm may instead be written over the
whole fleet at once, arrays in and out: :class:`FleetAlgorithm`, ``swarmbox.api.fleet``). The
framework owns the lifecycle (the ``@final`` driver methods); user code overrides the hooks. Hooks
receive a *context*: a narrow façade over the node that runs them — own telemetry in the mission
frame, reports as delivered by the network, ``send_task``, ``mark``, ``params`` and a seeded
``rng``. What the network delivered reaches hooks as views (:class:`InferiorReport`,
:class:`PeerState`, :class:`Task`), never as wire messages, and no context carries simulator ground
truth. No backend object ever reaches user code, so the same classes fly on the pymunk simulator, on
PX4 and on real drones.

Frames and units: positions are NED metres in the mission frame (north, east, down; altitude 3 m is
``d = -3``), velocities m/s, angles radians, times seconds.
"""

from __future__ import annotations

from swarmbox.api.algorithm import DroneAlgorithm, GroundAlgorithm
from swarmbox.api.context import DroneContext, GroundContext
from swarmbox.api.types import (
    DescendantState,
    DroneState,
    FlightMode,
    InferiorReport,
    MissionInfo,
    PeerState,
    Setpoint,
    SetpointKind,
    SetpointVerdict,
    Stage,
    Task,
    Telemetry,
    Vec3,
    wrap_angle,
)
from swarmbox.area import Area, mission_area, mission_grid  # the mission-area helper, for algorithms

__all__ = [
    "Area", "DescendantState", "DroneAlgorithm", "DroneContext", "DroneState", "Fleet", "FleetAlgorithm",
    "FleetSetpoints", "FlightMode",
    "GroundAlgorithm", "GroundContext", "InferiorReport", "MissionInfo", "PeerState", "Setpoint",
    "SetpointKind", "SetpointVerdict", "Stage", "Task", "Telemetry", "Vec3", "mission_area",
    "mission_grid", "row_norms", "wrap_angle",
]

#: The batch API (``swarmbox.api.fleet``), loaded on first use: it needs numpy, and importing
#: ``swarmbox.api`` alone (``swarmbox check --help``, a config check) should not pay for it.
_FLEET_NAMES = frozenset({"Fleet", "FleetAlgorithm", "FleetSetpoints", "row_norms"})


def __getattr__(name: str) -> object:
    if name in _FLEET_NAMES:
        from swarmbox.api import fleet

        return getattr(fleet, name)
    raise AttributeError(f"module 'swarmbox.api' has no attribute {name!r}")
