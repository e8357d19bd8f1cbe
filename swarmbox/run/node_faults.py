"""The fault models in a node process: each process applies the part of a fault that it owns.

A network fault (latency, loss, burst loss, partition, link cut) installs its hook in every
process's medium, which applies it at the receiver to each (message, destination) once, as the
simulated medium does at the sender. A clock fault skews the clock of the process that owns the
target node; the other processes leave it alone. A GNSS fault the autopilot applies to itself
(``gps_dropout``, ``gps_failure``: MAV_CMD_INJECT_FAILURE) is sent by the agent process that owns
the target's vehicle, to that vehicle only. The other vehicle and GNSS faults write a whole
fleet's backend inputs and are refused here with a message that says so. Fault start/end events
are logged by the ground process only, as in a single-process run.
"""

from __future__ import annotations

import heapq
import itertools
from collections.abc import Callable
from typing import Any

from omegaconf import DictConfig

from swarmbox.core.messages import GROUND_ID
from swarmbox.faults import FaultConfigError, install_faults
from swarmbox.faults.install import selected

#: Fault models a node process can apply (the others act on a whole fleet's backend).
DISTRIBUTED_FAULTS = frozenset({"latency", "packet_loss", "burst_loss", "partition", "link_cut",
                                "clock_skew", "gps_dropout", "gps_failure"})
#: ... of which these act on the vehicle, through its autopilot
AUTOPILOT_FAULTS = frozenset({"gps_dropout", "gps_failure"})


class OwnVehicle:
    """The fault view of this process's backend: fleet index ``own`` is its one vehicle (index 0);
    failures of vehicles other processes own are theirs to send. The ground owns none."""

    def __init__(self, backend: Any, own: int | None) -> None:
        self._backend, self._own = backend, own

    def inject_failure(self, i: int, unit: str, kind: str, instance: int = 0) -> None:
        if i == self._own:
            self._backend.inject_failure(0, unit, kind, instance)


class _Untouched:
    """The clock of a node another process owns: that process applies the skew."""

    def skew(self, *args: Any, **kwargs: Any) -> None:
        pass

    def resync(self) -> None:
        pass


class _Remote:
    """A node that runs in another process."""

    clock = _Untouched()

    def event(self, *args: Any, **kwargs: Any) -> None:
        pass


class LocalSwarm:
    """What the fault models need from a run, for the one node of this process."""

    def __init__(self, node: Any, node_id: int, drone_ids: list[int], medium: Any, time: Any,
                 tick_s: float) -> None:
        self.medium, self.time, self.tick_s = medium, time, tick_s
        self.ground = node if node_id == GROUND_ID else _Remote()
        self.agents = [node if i == node_id else _Remote() for i in drone_ids]
        self._scheduled: list[tuple[float, int, Callable[[Any], None]]] = []
        self._order = itertools.count()

    def schedule(self, at_s: float, action: Callable[[Any], None]) -> None:
        heapq.heappush(self._scheduled, (at_s, next(self._order), action))

    def run_due(self) -> None:
        """Run every action due by now (call once per tick, before the node ticks)."""
        while self._scheduled and self._scheduled[0][0] <= self.time.t_s + 1e-9:
            heapq.heappop(self._scheduled)[2](self)


def check(cfg: DictConfig) -> set[str]:
    """The selected fault models; FaultConfigError for one a node process cannot apply."""
    names = set(selected(cfg.get("fault")))
    refused = sorted(names - DISTRIBUTED_FAULTS)
    if refused:
        supported = ", ".join(sorted(DISTRIBUTED_FAULTS))
        raise FaultConfigError(f"fault {'+'.join(refused)} cannot run with run.runtime=processes (it acts "
                               f"on a whole fleet's backend); supported: {supported}")
    return names


def install(cfg: DictConfig, swarm: LocalSwarm, mission: Any, backend: Any,
            rng_for: Callable[[str], Any]) -> None:
    """Install ``cfg.fault`` on this process's node."""
    names = check(cfg)
    if names:
        if names & AUTOPILOT_FAULTS:
            own = next((k for k, a in enumerate(swarm.agents) if not isinstance(a, _Remote)), None)
            if own is not None and not hasattr(backend, "inject_failure"):
                raise FaultConfigError(f"fault {'+'.join(sorted(names & AUTOPILOT_FAULTS))} with "
                                       "run.runtime=processes needs an autopilot backend (mavsim, px4)")
            backend = OwnVehicle(backend, own)
        install_faults(cfg, swarm, mission, backend, rng_for)
