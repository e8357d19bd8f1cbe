"""The object core's driver of a :class:`~swarmbox.api.FleetAlgorithm` (the batch algorithm API).

Every agent of a run holds a :class:`FleetMember` in place of a per-drone algorithm: the member
hands the per-drone events (stage entries, tasks, reports, proximity alerts, successors) to the
shared FleetAlgorithm with its row, and answers the agent's stage work with the row that
:meth:`FleetDriver.step` computed for it. The order of hook calls is the driver contract written
in :mod:`swarmbox.api.fleet`.

Two phases per tick (:meth:`FleetDriver.tick_agents`): every agent's inbound half (telemetry,
inbox, watchdog), then the loop hooks once for the fleet, then every agent's outbound half
(setpoint, Heartbeat/Report, rows). Between the halves an agent's calls on the network are held
(:class:`CallHolder`) and go out at the start of its outbound half: the network then sees
exactly the calls, in exactly the order, of agents ticking one after the other — the order its
random draws (loss, jitter) and its queues depend on — so a FleetAlgorithm and the DroneAlgorithm it
ports write the same logs. In ``run.runtime=processes`` an agent is a fleet of one and ticks as
usual; its stage work asks the driver for its row, which runs the loop hooks then.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from swarmbox.api import Setpoint, SetpointKind, Stage
from swarmbox.api.fleet import Fleet, FleetAlgorithm, FleetSetpoints
from swarmbox.core.node import AlgorithmError

_PREP, _EXEC = int(Stage.PREPARATION), int(Stage.EXECUTION)
_KINDS = {int(k): k for k in SetpointKind}
_NO_ROW = (True, None)


class CallHolder:
    """Stands in for an agent's transport between the halves of a tick: keeps its calls, in order,
    for :meth:`replay` at the start of the agent's outbound half."""

    __slots__ = ("net", "calls")

    def __init__(self, net: Any) -> None:
        self.net = net
        self.calls: list[tuple[Callable, tuple]] = []

    def send(self, msg: Any, dst: int) -> None:
        self.calls.append((self.net.send, (msg, dst)))

    def publish(self, msg: Any) -> None:
        self.calls.append((self.net.publish, (msg,)))

    def subscribe(self, subscriber: int, publisher: int) -> None:
        self.calls.append((self.net.subscribe, (subscriber, publisher)))

    def unsubscribe(self, subscriber: int, publisher: int) -> None:
        self.calls.append((self.net.unsubscribe, (subscriber, publisher)))

    def has_subscribers(self, publisher: int) -> bool:
        return self.net.has_subscribers(publisher)

    def replay(self) -> None:
        for fn, args in self.calls:
            fn(*args)
        self.calls.clear()


class FleetMember:
    """What an agent holds in place of a DroneAlgorithm: its row of a :class:`FleetDriver`."""

    __slots__ = ("driver", "row")

    def __init__(self, driver: FleetDriver, row: int) -> None:
        self.driver, self.row = driver, row

    @property
    def algorithm(self) -> FleetAlgorithm:
        return self.driver.algorithm

    def enter_stage(self, stage: Stage, _ctx: Any) -> None:
        self.driver.enter(stage, self.row)

    def run_stage(self, stage: Stage, _ctx: Any) -> tuple[bool, Setpoint | None]:
        return self.driver.result(self.row)

    def on_task(self, _ctx: Any, task: Any) -> None:
        self.driver.event("on_task", self.row, task)

    def on_report(self, _ctx: Any, report: Any) -> None:
        self.driver.event("on_report", self.row, report)

    def on_prox_alert(self, _ctx: Any, neighbours: Any) -> None:
        self.driver.event("on_prox_alert", self.row, neighbours)

    def successors(self, _ctx: Any) -> Sequence[int]:
        return self.driver.event("successors", self.row)


class FleetDriver:
    """Runs one FleetAlgorithm for ``agents`` (every drone of the run, or the one of this process)."""

    def __init__(self, algorithm: FleetAlgorithm, agents: Sequence[Any]) -> None:
        self.algorithm, self.agents = algorithm, list(agents)
        self.fleet = Fleet(self.agents)
        self.members = [FleetMember(self, i) for i in range(len(self.agents))]
        self._time = self.agents[0].time
        self._set_up = False
        self._holders: list[CallHolder] = []   # set by adopt: the driver ticks the agents itself
        self._stepped = -1   # the tick whose rows are in _results
        self._results: list[tuple[bool, Setpoint | None]] = [_NO_ROW] * len(self.agents)
        # each row's last (n, e, d, yaw, kind) and its Setpoint (None: a NaN row)
        self._packed = np.full((len(self.agents), 5), np.nan)
        self._packed[:, 4] = -1.0   # no kind: the first row of every drone is new
        self._last: list[Setpoint | None] = [None] * len(self.agents)

    @classmethod
    def adopt(cls, agents: Sequence[Any]) -> FleetDriver | None:
        """One driver for every agent whose algorithm is a FleetAlgorithm (None: no agent's is).

        Each agent built a driver of its own (a fleet of one); here they join one fleet, with their
        network calls held between the halves of a tick.
        """
        members = [a.algorithm for a in agents if isinstance(a.algorithm, FleetMember)]
        if not members:
            return None
        algorithms = {id(m.algorithm) for m in members}
        if len(members) != len(agents) or len(algorithms) != 1:
            raise ValueError("a FleetAlgorithm must drive every drone of the run, as one instance")
        driver = cls(members[0].algorithm, agents)
        for agent, member in zip(agents, driver.members, strict=True):
            agent.algorithm = member
        driver._holders = [CallHolder(agent.net) for agent in agents]
        return driver

    # -- the tick (object core, one process) ----------------------------------------------------
    def tick_agents(self) -> None:
        """One tick of every agent not removed, in row order: inbound halves, hooks, outbound halves."""
        live = [(a, h) for a, h in zip(self.agents, self._holders, strict=True) if not a.removed]
        for agent, holder in live:
            agent.net = holder   # its network calls wait for its outbound half
            agent.begin_tick()
        self.step()
        for agent, holder in live:
            agent.net = holder.net
            if holder.calls:
                holder.replay()
            agent.finish_tick()

    def step(self) -> None:
        """Run the loop hooks for this tick and keep each drone's (complete, setpoint) row."""
        self._setup()
        fleet = self.fleet
        fleet.refresh()
        self._stepped = self._time.tick
        results = self._results = [_NO_ROW] * fleet.n
        stage = fleet.stage
        live = np.array([not a.removed for a in self.agents], dtype=bool)
        prep = np.flatnonzero((stage == _PREP) & live)
        exe = np.flatnonzero((stage == _EXEC) & live)
        if prep.size:
            self._call("prep_loop", prep)
            done = self._completion("prep_complete", prep)
            for i, d in zip(prep.tolist(), done, strict=True):
                results[i] = (d, None)
        if exe.size:
            flying = exe[fleet.armed[exe]]
            sps = self._setpoints(flying) if flying.size else {}
            done = self._completion("exec_complete", exe)
            for i, d in zip(exe.tolist(), done, strict=True):
                results[i] = (d, sps.get(i))

    def result(self, row: int) -> tuple[bool, Setpoint | None]:
        """Drone ``row``'s (complete, setpoint) for this tick (a fleet of one steps now)."""
        if self._stepped != self._time.tick:
            self.step()
        return self._results[row]

    # -- per-drone events -----------------------------------------------------------------------
    def enter(self, stage: Stage, row: int) -> None:
        self._setup()
        hook = {Stage.PREPARATION: "prep_once", Stage.EXECUTION: "exec_once"}.get(stage)
        if hook is not None:
            getattr(self.algorithm, hook)(self.fleet, np.array([row], dtype=np.int64))

    def event(self, hook: str, row: int, *args: Any) -> Any:
        self._setup()
        if hook == "successors":
            return tuple(self.algorithm.successors(self.fleet, row))
        return getattr(self.algorithm, hook)(self.fleet, row, *args)

    # -- checks ---------------------------------------------------------------------------------
    def _setup(self) -> None:
        if not self._set_up:
            self._set_up = True
            self._call("setup")

    def _call(self, hook: str, *args: Any) -> Any:
        try:
            return getattr(self.algorithm, hook)(self.fleet, *args)
        except AlgorithmError:
            raise
        except Exception as exc:  # the user's code may raise anything
            raise AlgorithmError(f"{self._who()}: {hook} raised {type(exc).__name__}: {exc}") from exc

    def _who(self, rows: Any = None) -> str:
        ids = self.fleet.ids.tolist() if rows is None else [int(self.fleet.ids[r]) for r in rows]
        return f"drone {ids[0]}" if len(ids) == 1 else f"fleet of {len(ids)} drones"

    def _completion(self, hook: str, rows: np.ndarray) -> list[bool]:
        done = self._call(hook, rows)
        n = self.fleet.n
        if not isinstance(done, np.ndarray) or done.dtype != np.bool_ or done.shape != (n,):
            what = (f"an array of {done.dtype} and shape {done.shape}" if isinstance(done, np.ndarray)
                    else f"{type(done).__name__}")
            raise AlgorithmError(f"{self._who()}: {hook} returned {what}, expected a bool array of "
                                 f"shape ({n},) (one per drone)")
        return done[rows].tolist()

    def _setpoints(self, rows: np.ndarray) -> dict[int, Setpoint]:
        out = self._call("exec_loop", rows)
        if out is None:
            return {}
        if type(out) is not FleetSetpoints:
            raise AlgorithmError(f"{self._who()}: exec_loop returned {type(out).__name__}, "
                                 "expected FleetSetpoints or None")
        packed = self._checked(out, rows)
        # A row bit for bit as last tick's gets last tick's Setpoint: a hover's rows never change
        same = (packed.view(np.int64) == self._packed[rows].view(np.int64)).all(axis=1)
        self._packed[rows] = packed
        last = self._last
        changed = np.flatnonzero(~same)
        for i, (n, e, d, yaw, kind) in zip(rows[changed].tolist(), packed[changed].tolist(), strict=True):
            last[i] = self._setpoint(i, n, e, d, yaw, _KINDS[int(kind)])
        return {i: last[i] for i in rows.tolist() if last[i] is not None}

    def _setpoint(self, i: int, n: float, e: float, d: float, yaw: float,
                  kind: SetpointKind) -> Setpoint | None:
        if n != n and e != e and d != d:   # a NaN row: no setpoint for this drone this tick
            return None
        if not (math.isfinite(n) and math.isfinite(e) and math.isfinite(d)) or math.isinf(yaw):
            raise AlgorithmError(f"drone {int(self.fleet.ids[i])}: exec_loop row {i} is not finite "
                                 f"(ned {(n, e, d)}, yaw {yaw}); a row of NaN means no setpoint")
        # built as Setpoint.position & co. build it (NaN yaw: keep the heading)
        return tuple.__new__(Setpoint, (kind, (n, e, d), None if yaw != yaw else yaw))

    def _checked(self, out: FleetSetpoints, rows: np.ndarray) -> np.ndarray:
        """The rows' (n, e, d, yaw, kind) as one float array, or an AlgorithmError naming what is wrong."""
        n = self.fleet.n
        ned = np.asarray(out.ned)
        if ned.shape != (n, 3) or ned.dtype.kind != "f":
            raise AlgorithmError(f"{self._who()}: exec_loop returned setpoints of shape {ned.shape} "
                                 f"({ned.dtype}), expected floats of shape ({n}, 3) (one row per drone)")
        packed = np.empty((rows.size, 5))
        packed[:, :3] = ned[rows]
        kind = out.kind
        if isinstance(kind, SetpointKind):
            packed[:, 4] = int(kind)
        else:
            k = np.asarray(kind)
            if k.shape != (n,) or k.dtype.kind not in "iu" or not np.isin(k[rows], list(_KINDS)).all():
                raise AlgorithmError(f"{self._who()}: exec_loop returned kinds {k.dtype} of shape {k.shape}, "
                                     f"expected a SetpointKind or SetpointKind codes of shape ({n},)")
            packed[:, 4] = k[rows]
        if out.yaw_rad is None:
            packed[:, 3] = math.nan
        else:
            yaw = np.asarray(out.yaw_rad)
            if yaw.shape != (n,) or yaw.dtype.kind != "f":
                raise AlgorithmError(f"{self._who()}: exec_loop returned yaw of shape {yaw.shape} "
                                     f"({yaw.dtype}), expected None or floats of shape ({n},)")
            packed[:, 3] = yaw[rows]
        return packed
