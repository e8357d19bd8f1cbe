"""Read-only views of what every node is handed: the algorithm's params and the mission.

Each node gets its own deep copy, frozen: mappings become ``MappingProxyType`` (a write raises
``TypeError``), lists become tuples, sets frozensets. A hook that tries to change ``ctx.params`` or
``ctx.mission`` therefore fails where it writes (the run's error names the node and the hook) instead
of changing what the other drones see, and it fails the same way in every runtime.
"""

from __future__ import annotations

from collections.abc import Mapping
from types import MappingProxyType
from typing import Any

from swarmbox.api.types import MissionInfo


def read_only(value: Any) -> Any:
    """A frozen deep copy of ``value`` (mappings, lists, tuples and sets, recursively)."""
    if isinstance(value, Mapping):
        return MappingProxyType({k: read_only(v) for k, v in value.items()})
    if isinstance(value, list | tuple):
        frozen = tuple(read_only(v) for v in value)
        return type(value)(*frozen) if hasattr(value, "_fields") else frozen   # a NamedTuple stays one
    if isinstance(value, set | frozenset):
        return frozenset(value)
    return value


def read_only_mission(info: MissionInfo) -> MissionInfo:
    """``info`` with every mapping frozen (its positions, superiors, values and obstacles).

    A mission frozen already (by an earlier call) is returned as it is: nothing can change it, so
    one frozen copy serves every node of a run (a copy per node cost O(N^2) at N drones).
    """
    if _frozen(info):
        return info
    return MissionInfo(info.name, info.swarm_size, read_only(info.initial_positions),
                       read_only(info.superiors), read_only(info.values), read_only(tuple(info.obstacles)))


def _frozen(info: MissionInfo) -> bool:
    """Whether ``info`` came out of :func:`read_only_mission` (its mappings are read-only proxies)."""
    mappings = (info.initial_positions, info.superiors, info.values, *info.obstacles)
    return isinstance(info.obstacles, tuple) and all(isinstance(m, MappingProxyType) for m in mappings)
