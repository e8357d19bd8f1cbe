"""The batch algorithm API: a drone algorithm written over the whole fleet at once.

A :class:`FleetAlgorithm` is the array-shaped twin of :class:`~swarmbox.api.DroneAlgorithm`: one
instance drives every drone of a run (of one process, in ``run.runtime=processes``), its loop hooks
take the fleet's telemetry as arrays and return one setpoint row per drone. The per-drone events
(tasks, reports, proximity alerts) still arrive one drone at a time, with the same guarantees::

    class HoverFleet(FleetAlgorithm):
        def exec_once(self, fleet, rows):
            self.target = fleet.home_ned_m + (0.0, 0.0, -3.0)   # (N, 3): one row per drone
        def exec_loop(self, fleet, rows):
            return FleetSetpoints.position(self.target)
        def exec_complete(self, fleet, rows):
            return fleet.stage_time_s > 10.0

Rows: drone ``fleet.ids[i]`` is row ``i`` of every array, in the mission's drone order. A hook's
``rows`` (an int array) names the drones the call is for: the loop hooks get the drones in that
stage (``exec_loop``: those in EXECUTION and armed), the ``*_once`` hooks the drones entering it.
What the loop hooks return covers the whole fleet, ``N`` rows, of which only ``rows`` are read, so
a hook may compute over every drone or over ``rows`` alone (leaving the others NaN).

**Driver contract** (what every core that runs a FleetAlgorithm guarantees; the object core's
driver is ``swarmbox.core.batch``):

1. ``setup(fleet)`` runs once, before any other hook.
2. Each tick, every drone first reads its telemetry and drains its inbox, one drone after the
   other in row order. Meanwhile the per-drone hooks run exactly as for a DroneAlgorithm: a stage
   change runs ``prep_once``/``exec_once`` with that one drone's row (so a tick may call a
   ``*_once`` hook several times, with disjoint rows), then ``on_task``, ``on_report`` and
   ``on_prox_alert`` for what was delivered — reliable tasks exactly once, in send order, never
   before the ``*_once`` hook of the stage their sender was in.
3. Then the fleet's arrays are refreshed (one snapshot per tick) and the loop hooks run once each,
   in this order: ``prep_loop``, ``prep_complete`` (drones in PREPARATION), ``exec_loop`` (drones
   in EXECUTION whose vehicle is armed), ``exec_complete`` (drones in EXECUTION). A hook whose
   ``rows`` would be empty is not called.
4. Then each drone, in row order, sends its setpoint to its vehicle, publishes its Heartbeat and
   Report, and logs its rows, exactly as a DroneAlgorithm's drone would; messages a hook sent for
   drone ``i`` (``fleet.ctx(i).send_task``) leave with drone ``i``'s, in the order they were sent.

The arrays are that snapshot: during the per-drone hooks of step 2 they still hold the previous
tick's values; read drone ``i``'s current ones there through ``fleet.ctx(i)``. Every array is
read-only (``flags.writeable`` is False): copy before changing one.

A per-drone algorithm and its FleetAlgorithm port write the same logs when their arithmetic is the
same per element; :func:`row_norms` helps where the per-drone code used ``math.hypot``/``math.dist``,
and :func:`swarmbox.testing.check_batch_matches` checks a pair.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from typing import Any, ClassVar, NamedTuple

import numpy as np

from swarmbox.api.context import DroneContext
from swarmbox.api.types import DescendantState, InferiorReport, MissionInfo, SetpointKind, Task


class FleetSetpoints(NamedTuple):
    """One setpoint per drone: ``ned`` (N, 3), ``kind`` one :class:`SetpointKind` for all or an int
    array (N,) of kinds, ``yaw_rad`` None (keep every heading) or (N,), NaN keeping that drone's.

    A row of NaN in ``ned`` sends that drone no setpoint this tick (its vehicle keeps the last one);
    any other non-finite value where a setpoint is required fails the run.
    """

    kind: SetpointKind | np.ndarray
    ned: np.ndarray
    yaw_rad: np.ndarray | None = None

    @classmethod
    def position(cls, ned_m: Any, yaw_rad: Any = None) -> FleetSetpoints:
        return cls(SetpointKind.POSITION, np.asarray(ned_m, dtype=float), _yaw(yaw_rad))

    @classmethod
    def velocity(cls, ned_m_s: Any, yaw_rad: Any = None) -> FleetSetpoints:
        return cls(SetpointKind.VELOCITY, np.asarray(ned_m_s, dtype=float), _yaw(yaw_rad))

    @classmethod
    def acceleration(cls, ned_m_s2: Any, yaw_rad: Any = None) -> FleetSetpoints:
        return cls(SetpointKind.ACCELERATION, np.asarray(ned_m_s2, dtype=float), _yaw(yaw_rad))


def _yaw(yaw_rad: Any) -> np.ndarray | None:
    return None if yaw_rad is None else np.asarray(yaw_rad, dtype=float)


def row_norms(v: np.ndarray, near: float | np.ndarray) -> np.ndarray:
    """Euclidean norm of each row of ``v`` (k, m), for comparing with ``near``.

    numpy's norm and ``math.hypot`` may differ in the last bit; rows whose norm lies within a
    relative 1e-9 of ``near`` are therefore recomputed with ``math.hypot``, so that ``row_norms(v,
    x) <= x`` decides every row exactly as ``math.hypot(*row) <= x`` (and ``math.dist(p, q)`` is
    ``math.hypot`` of ``p - q``) would, at numpy speed.
    """
    v = np.asarray(v, dtype=float)
    norms = np.sqrt(np.einsum("ij,ij->i", v, v))
    limit = np.broadcast_to(np.asarray(near, dtype=float), norms.shape)
    close = np.flatnonzero(np.abs(norms - limit) <= 1e-9 * np.maximum(np.abs(limit), 1e-300))
    for i in close.tolist():
        norms[i] = math.hypot(*v[i].tolist())
    return norms


class Fleet:
    """Read-only view of the drones a :class:`FleetAlgorithm` drives (built by the driver).

    Constant: ``ids``, ``n``, ``home_ned_m``, ``params``, ``mission``, ``tick_s``. Per tick (the
    snapshot taken before the loop hooks): ``stage``, ``stage_tick``, ``stage_time_s``, ``time_s``
    and the telemetry ``pos_ned_m``, ``vel_ned_m_s``, ``yaw_rad``, ``armed``, ``landed``,
    ``battery_frac``, ``ready_to_arm``, ``link_ok``. Per drone: ``ctx(i)`` (the drone's
    :class:`DroneContext`: ``send_task``, ``mark``, ``report_data``, ``inferiors``, ``last_task`` ...)
    and ``rng(i)`` (the drone's own seeded generator, the one ``ctx.rng`` gives).
    """

    def __init__(self, nodes: Sequence[Any]) -> None:
        self._nodes = list(nodes)
        first = self._nodes[0]
        self.ids = _frozen(np.array([nd.node_id for nd in self._nodes], dtype=np.int64))
        self.n = len(self._nodes)
        self.home_ned_m = _frozen(np.array([nd.home_ned_m for nd in self._nodes], dtype=float))
        self.params: Mapping[str, Any] = first.params
        self.mission: MissionInfo = first.mission
        self.tick_s: float = first.tick_s
        self._row = {int(d): i for i, d in enumerate(self.ids.tolist())}
        self._cache: dict[str, np.ndarray] = {}
        self.refresh()

    def refresh(self) -> None:
        """Take this tick's snapshot (the driver calls this; the arrays are built on first use)."""
        self._tels = [nd.telemetry for nd in self._nodes]
        self._cache.clear()

    def row(self, drone_id: int) -> int:
        """The row of drone ``drone_id``."""
        return self._row[drone_id]

    def ctx(self, i: int) -> DroneContext:
        """Drone ``i``'s own context (row ``i``), as its DroneAlgorithm would get it."""
        return self._nodes[i].ctx

    def rng(self, i: int) -> np.random.Generator:
        """Drone ``i``'s seeded generator (the same object as ``fleet.ctx(i).rng``)."""
        return self._nodes[i].rng

    def _get(self, name: str, build: Callable[[], Any], dtype: Any) -> np.ndarray:
        arr = self._cache.get(name)
        if arr is None:
            arr = self._cache[name] = _frozen(np.array(build(), dtype=dtype))
        return arr

    @property
    def stage(self) -> np.ndarray:
        """Stage code of each drone (compare with ``Stage.EXECUTION`` ...)."""
        return self._get("stage", lambda: [nd.stage_code for nd in self._nodes], np.int64)

    @property
    def stage_tick(self) -> np.ndarray:
        """Ticks since each drone entered its stage (``ctx.tick``)."""
        return self._get("stage_tick", lambda: [nd.stage_tick for nd in self._nodes], np.int64)

    @property
    def stage_time_s(self) -> np.ndarray:
        """Seconds since each drone entered its stage (``ctx.stage_time_s``: ticks × tick period)."""
        return self._get("stage_time_s", lambda: self.stage_tick * self.tick_s, float)

    @property
    def time_s(self) -> np.ndarray:
        """Each drone's local clock (``ctx.time_s``)."""
        return self._get("time_s", lambda: [nd.clock.now() for nd in self._nodes], float)

    @property
    def pos_ned_m(self) -> np.ndarray:
        """Estimated positions (N, 3), NED, mission frame."""
        return self._get("pos", lambda: [t.pos_ned_m for t in self._tels], float)

    @property
    def vel_ned_m_s(self) -> np.ndarray:
        return self._get("vel", lambda: [t.vel_ned_m_s for t in self._tels], float)

    @property
    def yaw_rad(self) -> np.ndarray:
        return self._get("yaw", lambda: [t.yaw_rad for t in self._tels], float)

    @property
    def armed(self) -> np.ndarray:
        return self._get("armed", lambda: [t.armed for t in self._tels], bool)

    @property
    def landed(self) -> np.ndarray:
        return self._get("landed", lambda: [t.landed for t in self._tels], bool)

    @property
    def battery_frac(self) -> np.ndarray:
        return self._get("battery", lambda: [t.battery_frac for t in self._tels], float)

    @property
    def ready_to_arm(self) -> np.ndarray:
        return self._get("ready", lambda: [t.ready_to_arm for t in self._tels], bool)

    @property
    def link_ok(self) -> np.ndarray:
        return self._get("link_ok", lambda: [t.link_ok for t in self._tels], bool)


def _frozen(arr: np.ndarray) -> np.ndarray:
    arr.flags.writeable = False
    return arr


class FleetAlgorithm:
    """Base class of a drone algorithm written over the whole fleet (one instance per run).

    Select it like a DroneAlgorithm: ``algo.drone._target_`` names the class. Hooks, with the
    :class:`Fleet` view and the rows (int array) they are for; the order they run in is the driver
    contract of :mod:`swarmbox.api.fleet`:

    - ``setup(fleet)`` — once, before any other hook (allocate per-drone arrays here).
    - ``prep_once(fleet, rows)`` / ``exec_once(fleet, rows)`` — drones entering the stage.
    - ``prep_loop(fleet, rows)`` — every tick, drones in PREPARATION.
    - ``prep_complete(fleet, rows)`` -> bool array (N,); default: ``fleet.ready_to_arm``.
    - ``exec_loop(fleet, rows)`` -> :class:`FleetSetpoints` | None — every tick, drones in EXECUTION
      with an armed vehicle. None (or a NaN row) keeps the last setpoint. **Required.**
    - ``exec_complete(fleet, rows)`` -> bool array (N,) — every tick, drones in EXECUTION.
      **Required.**
    - ``on_task(fleet, i, task)``, ``on_report(fleet, i, report)``, ``on_prox_alert(fleet, i,
      neighbours)`` — per drone ``i`` (a row), as the DroneAlgorithm hooks of the same names.
    - ``successors(fleet, i)`` -> Sequence[int]; default: drone ``i``'s superior.

    A hook returning the wrong type or shape, a completion array that is not boolean, or a
    setpoint row that is partly non-finite fails the run, naming the hook and the drone. ``Params``:
    as for :class:`~swarmbox.api.DroneAlgorithm`.
    """

    Params: ClassVar[type | None] = None

    def setup(self, fleet: Fleet) -> None:
        """Called once, before any other hook."""

    def prep_once(self, fleet: Fleet, rows: np.ndarray) -> None:
        """Called for drones entering PREPARATION."""

    def prep_loop(self, fleet: Fleet, rows: np.ndarray) -> None:
        """Called every tick for the drones in PREPARATION."""

    def prep_complete(self, fleet: Fleet, rows: np.ndarray) -> np.ndarray:
        return fleet.ready_to_arm

    def exec_once(self, fleet: Fleet, rows: np.ndarray) -> None:
        """Called for drones entering EXECUTION (the framework arms them first)."""

    def exec_loop(self, fleet: Fleet, rows: np.ndarray) -> FleetSetpoints | None:
        raise NotImplementedError(f"{type(self).__name__} must implement exec_loop")

    def exec_complete(self, fleet: Fleet, rows: np.ndarray) -> np.ndarray:
        raise NotImplementedError(f"{type(self).__name__} must implement exec_complete")

    def on_task(self, fleet: Fleet, i: int, task: Task) -> None:
        """Called for every task delivered to drone ``i``."""

    def on_report(self, fleet: Fleet, i: int, report: InferiorReport) -> None:
        """Called for every Report delivered to drone ``i`` from a direct inferior."""

    def on_prox_alert(self, fleet: Fleet, i: int, neighbours: tuple[DescendantState, ...]) -> None:
        """Called for every proximity alert delivered to drone ``i`` (empty: all clear)."""

    def successors(self, fleet: Fleet, i: int) -> Sequence[int]:
        return (fleet.ctx(i).superior,)


__all__ = ["Fleet", "FleetAlgorithm", "FleetSetpoints", "row_norms"]
