"""The tick loop: one run of a swarm, from ICEBREAK to TERMINATION (or ABORT).

Per tick, in order: deliver due messages -> ground tick -> each agent tick (state machine, user
hook, setpoint to its vehicle, state row; with a FleetAlgorithm, every agent's inbound half, the
fleet's hooks, every agent's outbound half: ``core.batch``) -> the backend advances by one tick ->
vehicle events are logged. A simulation backend runs on a virtual clock as fast as the CPU allows; a real-time
backend (MAVLink, hardware) is paced on the wall clock, optionally sped up by the simulator's
speed factor.
"""

from __future__ import annotations

import gc
import heapq
import itertools
import json
import time as wall
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from typing import Protocol

from swarmbox.core.agent import AgentNode
from swarmbox.core.batch import FleetDriver
from swarmbox.core.clock import TimeSource
from swarmbox.core.ending import EndWatch, outcome
from swarmbox.core.ground import GroundNode
from swarmbox.core.ports import Backend, Network


@contextmanager
def gc_paused() -> Iterator[None]:
    enabled = gc.isenabled()
    gc.disable()
    try:
        yield
    finally:
        if enabled:
            gc.enable()


@dataclass(frozen=True, slots=True)
class Outcome:
    status: str        # "ok" | "aborted"
    reason: str
    sim_time_s: float
    ticks: int
    wall_time_s: float

    @property
    def real_time_factor(self) -> float:
        return self.sim_time_s / self.wall_time_s if self.wall_time_s > 0 else float("inf")


class StateLog(Protocol):
    """Writes the state rows of every agent that ticked, as one block (``record.fleet.FleetStateLog``)."""

    def __call__(self, tick: int) -> None: ...

    def refresh(self) -> None:
        """Take note of an agent removed from the loop."""


class Swarm:
    """Owns the nodes, the network, the backend and the clock of one run."""

    def __init__(self, *, time: TimeSource, tick_s: float, ground: GroundNode, agents: list[AgentNode],
                 medium: Network, backend: Backend, event_logs: dict[int, Callable]) -> None:
        self.time, self.tick_s = time, tick_s
        self.ground, self.agents = ground, agents
        self.medium, self.backend = medium, backend
        self._event_logs = event_logs
        self._scheduled: list[tuple[float, int, Callable[[Swarm], None]]] = []
        self._order = itertools.count()   # ties run in the order they were scheduled
        self._by_id = {a.node_id: a for a in agents}
        self.end_watch = EndWatch(ground.timing.lost_superior_ticks)   # every drone down or lost
        #: Writes every agent's state row of a tick as one block (set by the builder when the backend
        #: exports its fleet arrays; otherwise each agent logs its own row).
        self.state_log: StateLog | None = None
        #: Runs a FleetAlgorithm's hooks once per tick for every agent (None: per-drone algorithms)
        self.fleet_driver = FleetDriver.adopt(agents)

    def schedule(self, at_s: float, action: Callable[[Swarm], None]) -> None:
        """Run ``action(swarm)`` at the first tick at or after true time ``at_s``."""
        heapq.heappush(self._scheduled, (at_s, next(self._order), action))

    def remove_agent(self, drone_id: int) -> None:
        """The drone's companion computer dies: its node stops and its radio falls silent.

        The autopilot, no longer receiving setpoints, lands where it is (its offboard-loss failsafe).
        """
        agent = self._by_id[drone_id]
        agent.removed = agent.finished = True
        if self.state_log is not None:
            self.state_log.refresh()
        self.medium.disconnect(drone_id)
        agent.event("failsafe", "node_removed", drone_id, action="land")
        agent.vehicle.land()

    def step(self) -> None:
        t = self.time
        self.run_scheduled()
        self.medium.deliver_due()
        self.ground.tick()
        if self.fleet_driver is not None:
            self.fleet_driver.tick_agents()
        else:
            for agent in self.agents:
                if not agent.removed:
                    agent.tick()
        if self.state_log is not None:
            self.state_log(t.tick)
        self.backend.step(self.tick_s)
        self.vehicle_events()
        t.tick += 1
        t.t_s = t.tick * self.tick_s

    def run_scheduled(self) -> None:
        """What is scheduled for this tick (faults' onsets and ends, restarts), in time order."""
        t_s = self.time.t_s
        while self._scheduled and self._scheduled[0][0] <= t_s + 1e-9:
            heapq.heappop(self._scheduled)[2](self)

    def vehicle_events(self) -> None:
        """The backend's events of this step into their drones' event logs; a failure aborts its drone."""
        tick = self.time.tick
        for ev in self.backend.drain_events():
            log = self._event_logs.get(ev.drone_id)
            if log is not None:
                agent = self._by_id[ev.drone_id]
                log((agent.clock.now(), tick, ev.kind, ev.name, ev.drone_id,
                     json.dumps(ev.data, sort_keys=True, default=str)))
                if ev.kind == "failure":   # the autopilot cannot fly the mission: the drone aborts
                    self.before_failure()
                    agent.vehicle_failed(str(ev.data.get("reason", ev.name)))

    def before_failure(self) -> None:
        """Hook before a failing drone's agent acts (the fleet core refreshes its records here)."""

    def done(self) -> bool:
        return self.ground.finished and all(a.finished for a in self.agents)

    def run(self, max_sim_time_s: float, speed: float = 1.0,
            progress: Callable[[Swarm], None] | None = None) -> Outcome:
        """Tick until every node has finished, every drone is down or lost, or ``max_sim_time_s`` passes.

        The cyclic garbage collector is paused meanwhile: the loop allocates many small acyclic
        objects (messages, log rows) and full collections over the buffered logs cost more than
        the simulation itself.
        """
        with gc_paused():
            return self._run(max_sim_time_s, speed, progress)

    def _run(self, max_sim_time_s: float, speed: float,
             progress: Callable[[Swarm], None] | None) -> Outcome:
        start = wall.perf_counter()
        realtime = bool(getattr(self.backend, "realtime", False))
        max_ticks = int(round(max_sim_time_s / self.tick_s))
        report_every = max(1, int(round(1.0 / self.tick_s)))   # once per simulated second
        settled = False
        while not self.done() and self.time.tick < max_ticks:
            if self.end_watch.over(self):
                settled = True
                break
            self.step()
            if realtime:
                ahead = self.time.t_s / speed - (wall.perf_counter() - start)
                if ahead > 0:
                    wall.sleep(ahead)
            if progress is not None and self.time.tick % report_every == 0:
                progress(self)
        elapsed = wall.perf_counter() - start
        status, reason = outcome(self, max_sim_time_s, settled)
        return Outcome(status, reason, self.time.t_s, self.time.tick, elapsed)
