"""The :class:`~swarmbox.api.Fleet` view of a batch algorithm on the fleet core, read from its arrays.

The object core's view builds each array from the drones' telemetry records of the tick; here the
same numbers come from the arrays the fleet core read at the start of the tick (the backend's
``state_into`` columns are the records' own floats, ``armed``/``landed``/``link_ok`` the fleet's
readings, the clocks the tick's readings), so no drone's record is fetched for the hooks.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

from swarmbox.api.fleet import Fleet

if TYPE_CHECKING:
    from swarmbox.core.fleet.swarm import FleetSwarm


def _frozen(arr: np.ndarray) -> np.ndarray:
    arr.flags.writeable = False
    return arr


class ArrayFleet(Fleet):
    """Fleet over a :class:`~swarmbox.core.fleet.swarm.FleetSwarm`'s arrays (same values, same dtypes)."""

    def __init__(self, nodes: list[Any], swarm: FleetSwarm) -> None:
        self._swarm = swarm
        super().__init__(nodes)

    def refresh(self) -> None:
        self._cache.clear()

    def _arr(self, name: str, build: Any) -> np.ndarray:
        arr = self._cache.get(name)
        if arr is None:
            arr = self._cache[name] = _frozen(build())
        return arr

    @property
    def stage(self) -> np.ndarray:
        return self._arr("stage", lambda: self._swarm.fleet.stage.copy())

    @property
    def stage_tick(self) -> np.ndarray:
        return self._arr("stage_tick", lambda: self._swarm.time.tick - self._swarm.fleet.entry_tick)

    @property
    def time_s(self) -> np.ndarray:
        return self._arr("time_s", lambda: self._swarm.now.copy())

    @property
    def pos_ned_m(self) -> np.ndarray:
        return self._arr("pos", lambda: np.ascontiguousarray(self._swarm.values[0:3].T))

    @property
    def vel_ned_m_s(self) -> np.ndarray:
        return self._arr("vel", lambda: np.ascontiguousarray(self._swarm.values[3:6].T))

    @property
    def yaw_rad(self) -> np.ndarray:
        return self._arr("yaw", lambda: self._swarm.values[12].copy())

    @property
    def battery_frac(self) -> np.ndarray:
        return self._arr("battery", lambda: self._swarm.values[13].copy())

    @property
    def armed(self) -> np.ndarray:
        return self._arr("armed", lambda: self._swarm.fleet.armed.copy())

    @property
    def landed(self) -> np.ndarray:
        return self._arr("landed", lambda: self._swarm.fleet.landed.copy())

    @property
    def link_ok(self) -> np.ndarray:
        return self._arr("link_ok", lambda: self._swarm.fleet.link_ok.copy())

    @property
    def ready_to_arm(self) -> np.ndarray:
        # not among the arrays; the GNSS readiness it reports does not change within a tick
        return self._arr("ready", lambda: np.array([v.telemetry().ready_to_arm for v in self._swarm.vehicles],
                                                   dtype=bool))
