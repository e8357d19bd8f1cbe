"""The fleet core's tick loop: the object core's (:class:`swarmbox.core.swarm.Swarm`) over arrays.

Per tick, in the object core's order: deliver what has arrived (receive rows; the ground's Reports
into its arrays; a Heartbeat that confirms a drone's stage into the liveness arrays; anything else
into the drone's inbox) -> the ground's tick -> every drone's tick (:meth:`FleetSwarm.tick_drones`)
-> the tick's messages routed as one batch -> the state rows -> the backend steps -> its events.

Hooks run per drone, through each drone's own context; a batch algorithm's
(:class:`~swarmbox.api.FleetAlgorithm`) loop hooks run once per tick over the fleet
(:meth:`FleetSwarm.run_batch`), in the order of the driver contract of :mod:`swarmbox.api.fleet`.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from swarmbox.core.clock import readings
from swarmbox.core.ending import EndWatch
from swarmbox.core.fleet.agents import (
    ABORT,
    ARMED_ONLY,
    DATA,
    EXECUTION,
    LANDING,
    PREPARATION,
    TERMINATION,
    FleetAgent,
    FleetState,
)
from swarmbox.core.fleet.ground import FleetGround
from swarmbox.core.fleet.network import HEARTBEAT, FleetNetwork
from swarmbox.core.fleet.rows import MessageRows, take
from swarmbox.core.fleet.setpoints import SetpointBatch, SetpointRows
from swarmbox.core.fleet.view import ArrayFleet
from swarmbox.core.messages import _REPORT_FIXED, TaskAck
from swarmbox.core.stages import Stage
from swarmbox.core.swarm import Outcome, Swarm


class FleetEndWatch(EndWatch):
    """EndWatch over the arrays (the readings are those of the last tick, as an agent's are)."""

    def all_down(self, swarm: FleetSwarm) -> bool:
        f = swarm.fleet
        terminal = (f.stage == TERMINATION) | (f.stage == ABORT)
        return bool((~f.link_ok | (f.landed & ~f.armed & terminal) | ~swarm.live).all())

    def over(self, swarm: FleetSwarm) -> bool:
        if not super().over(swarm):
            return False
        swarm.fleet.settle(swarm.vehicles)   # the run's outcome reads every drone's last record
        return True


class DroneNet:
    """Drone ``k``'s view of the fleet network with a batch algorithm: whatever it sends, whenever
    (its inbox, the fleet's hooks through ``fleet.ctx(k)``, its setpoint's turn), goes out in drone
    ``k``'s turn of the tick, in the order sent: what the object core's held calls
    (``swarmbox.core.batch.CallHolder``) replay."""

    __slots__ = ("net", "phase")

    def __init__(self, net: FleetNetwork, phase: int) -> None:
        self.net, self.phase = net, phase

    def send(self, msg: Any, dst: int) -> None:
        self.net.phase = self.phase
        self.net.send(msg, dst)

    def publish(self, msg: Any) -> None:
        self.net.phase = self.phase
        self.net.publish(msg)

    def subscribe(self, subscriber: int, publisher: int) -> None:
        self.net.subscribe(subscriber, publisher)

    def unsubscribe(self, subscriber: int, publisher: int) -> None:
        self.net.unsubscribe(subscriber, publisher)

    def has_subscribers(self, publisher: int) -> bool:
        return self.net.has_subscribers(publisher)


class FleetSwarm(Swarm):
    """A Swarm whose drones, network and ground inferiors are arrays (``run.core=fleet``)."""

    def __init__(self, *, fleet: FleetState, network: FleetNetwork, rows: MessageRows,
                 ground: FleetGround, agents: list[FleetAgent], **kw: Any) -> None:
        super().__init__(ground=ground, agents=agents, medium=network, **kw)
        self.fleet, self.network, self.rows = fleet, network, rows
        self.end_watch = FleetEndWatch(ground.timing.lost_superior_ticks)   # type: ignore[assignment]
        self._vehicles = [a.vehicle for a in agents]
        #: the telemetry records of a list of drones: the backend's in one pass where it has that entry
        self._records = getattr(self.backend, "telemetry_many", None) or (
            lambda ks: [self._vehicles[k].telemetry() for k in ks])
        self._clocks = [a.clock for a in agents]
        t = ground.timing
        self._lost_superior = t.lost_superior_ticks
        self._timeouts = np.zeros(len(Stage) + 1)   # by stage code (ABORT, -1: the last)
        for s in Stage:
            self._timeouts[int(s)] = t.timeouts_s[s.name]
        self._values = np.empty((14, fleet.n))
        self._landed = np.empty(fleet.n, dtype=bool)
        self._crashed = getattr(self.backend, "crashed", None)
        self.now = np.zeros(fleet.n)
        self._fix = np.full((3, fleet.n), np.nan)   # each drone's GNSS fix its last Report saw
        self._reports: tuple[np.ndarray, np.ndarray] | None = None   # see network.reports
        self._last_tick = 1 << 62   # the run's last tick (run sets it)
        self._turn = 0   # in a tick, the drone whose turn it is (those before it have ticked)
        self.live = np.ones(fleet.n, dtype=bool)   # not removed (a crash removes a drone's node)
        self._all_live = True
        # every drone's setpoint rows go through one buffer; the hooks drones' setpoints in one batch
        self.setpoint_rows = SetpointRows()
        for a in agents:
            self.setpoint_rows.appenders[a.node_id] = a.buffer_setpoints(self.setpoint_rows)
        self.batch = SetpointBatch(self.backend, self.setpoint_rows,
                                   np.array([a.node_id for a in agents], dtype=np.int16))
        if self.fleet_driver is not None:
            for k, agent in enumerate(agents):
                agent.net = DroneNet(network, k + 1)
            self.fleet_driver.fleet = ArrayFleet(agents, self)

    @property
    def values(self) -> np.ndarray:
        """This tick's ``state_into`` columns of every drone (14, N), read at the start of its tick."""
        return self._values

    @property
    def vehicles(self) -> list[Any]:
        return self._vehicles

    # -- the loop ----------------------------------------------------------------------------------
    def run(self, max_sim_time_s: float, speed: float = 1.0,
            progress: Callable[[Swarm], None] | None = None) -> Outcome:
        """Swarm.run; the buffered message and setpoint rows go to the nodes' logs before every progress call
        (where the recorder hands its buffers over) and at the end, whatever happens."""
        def hand_over(swarm: Swarm) -> None:
            self.hand_over_rows()
            if progress is not None:
                progress(swarm)

        self._last_tick = int(round(max_sim_time_s / self.tick_s))
        try:
            return super().run(max_sim_time_s, speed, hand_over)
        finally:
            self.hand_over_rows()
            self.fleet.settle(self._vehicles)

    def hand_over_rows(self) -> None:
        """The buffered message and setpoint rows to their nodes' logs, now: the live monitor's
        snapshots read the ground's (each node's rows keep their order whenever they are handed over)."""
        self.rows.hand_over()
        self.setpoint_rows.hand_over()

    def remove_agent(self, drone_id: int) -> None:
        super().remove_agent(drone_id)
        self.live[self.agents.index(self._by_id[drone_id])] = False
        self._all_live = False
        self._reports = None   # the Reports' records, for the drones left

    def done(self) -> bool:
        if not (self.ground.finished and bool(self.fleet.finished.all())):
            return False
        self.fleet.settle(self._vehicles)   # the run's outcome reads every drone's last record
        return True

    def step(self) -> None:
        t = self.time
        self.run_scheduled()
        self.deliver()
        self.network.phase = 0
        self._turn = 0
        try:
            self.ground.tick()
            self.tick_drones()
        except Exception:
            self.fail_midtick()
            raise
        self.network.route()
        if self.state_log is not None:
            self.state_log(t.tick)
        self.backend.step(self.tick_s)
        self.vehicle_events()
        t.tick += 1
        t.t_s = t.tick * self.tick_s
        if t.tick >= self._last_tick:   # the time is up: the run's outcome reads every drone's record
            self.fleet.settle(self._vehicles)

    def before_failure(self) -> None:
        self.fleet.settle(self._vehicles)   # the failing drone's agent reads its current record

    # -- deliveries --------------------------------------------------------------------------------
    def deliver(self) -> None:
        """Hand this tick's arrivals over: Reports to the ground's arrays, a Heartbeat confirming its
        drone's stage to the liveness arrays, everything else to its node's inbox, in order."""
        due = self.network.deliver()
        if not len(due["dsti"]):
            return
        f, net = self.fleet, self.network
        to_ground = due["dsti"] == 0
        if to_ground.any():
            reports = to_ground & (due["obj"] < 0)
            self.ground.due = take(due, reports)
            others = net.objects(due["obj"][to_ground & ~reports])
            self.ground.acks = [m for m in others if type(m) is TaskAck]
        k = due["dsti"] - 1
        to_drone = ~to_ground
        confirms = to_drone & (due["mtype"] == HEARTBEAT) & (due["stage"] == f.stage[np.maximum(k, 0)])
        slow = np.zeros(f.n, dtype=bool)
        slow[k[to_drone & ~confirms]] = True
        slow[k[to_drone]] |= f.sticky[k[to_drone]]
        fast = confirms & ~slow[np.maximum(k, 0)]
        f.sup_silent[k[fast]] = 0
        f.heard[k[fast]] = True
        mine = to_drone & ~fast
        if mine.any():
            f.busy |= slow
            for drone, msg in zip(k[mine].tolist(), net.objects(due["obj"][mine]), strict=True):
                self.agents[drone].inbox.append(msg)
        net.release(due["obj"])

    # -- the drones' ticks -------------------------------------------------------------------------
    def tick_drones(self) -> None:
        f, tick = self.fleet, self.time.tick
        self.backend.state_into(self._values, self._landed)   # the Reports' positions, read now
        crashed = self._crashed is not None and bool(self._crashed.any())
        f.read(self._vehicles, self._landed, crashed)
        stage = f.stage
        terminal = (stage == TERMINATION) | (stage == ABORT)
        loop = (stage == PREPARATION) | (stage == EXECUTION)
        watch = f.heard & ~terminal
        fires = watch & (f.sup_silent + 1 > self._lost_superior)   # the watchdog hands over or aborts
        full = (f.busy | f.sticky | (~f.link_ok & ~terminal) | fires) & self.live
        rest = ~full & self.live
        f.sup_silent[watch & rest] += 1
        hooks = rest & loop
        rest &= ~loop
        down = (stage == LANDING) | (stage == ABORT)
        f.complete[rest] = np.where(down, f.landed & ~f.armed, True)[rest]
        timed_out = (tick - f.entry_tick) * self.tick_s > self._timeouts[stage]
        f.finished[rest & terminal & (~f.armed | timed_out)] = True
        self.now = readings(self._clocks, self.time.t_s)
        if self.fleet_driver is not None:
            self.run_batch(np.flatnonzero(full), np.flatnonzero(hooks))
        else:
            self.run_hooks(np.flatnonzero(full), np.flatnonzero(hooks))
        f.busy[:] = False
        self.send_reports()

    def run_hooks(self, full: np.ndarray, hooks: np.ndarray) -> None:
        """The drones that tick in Python, in fleet order: ``full`` the whole tick (messages in their
        inbox, a watchdog firing), ``hooks`` only their loop stage's hooks, whose setpoints go to the
        backend in one batch after the last drone's tick (:mod:`swarmbox.core.fleet.setpoints`)."""
        net, agents, f, batch = self.network, self.agents, self.fleet, self.batch
        f.fetch(self._records, full)
        f.fetch(self._records, hooks)
        batch.begin(len(hooks), self.now)
        try:
            if not len(full):   # the usual tick: nothing a drone sends but its Report
                self.loop_hooks(hooks)
                return
            whole = set(full.tolist())
            for k in np.union1d(full, hooks).tolist():
                net.phase = k + 1   # what this drone sends goes out after the last drone's, before its Report
                self._turn = k
                if k in whole:
                    agents[k].fleet_tick()
                else:
                    f.complete[k] = agents[k].fleet_loop(f.tels[k], batch)
            self._turn = f.n
        finally:   # a failing hook: the drones before it have handed their setpoints over
            batch.flush(self.now, self.time.tick)

    def run_batch(self, full: np.ndarray, hooks: np.ndarray) -> None:
        """run_hooks for a batch algorithm: every ``full`` drone's inbound half in fleet order, the
        loop hooks once over the fleet (its snapshot reads every drone), then each drone's stage
        work (its row of the hooks' results: setpoint, rows) in fleet order, the setpoints of the
        drones not ticking whole handed over in one batch."""
        agents, f, batch = self.agents, self.fleet, self.batch
        f.fetch(self._records, full)
        for k in full.tolist():
            agents[k].fleet_inbound()
        self.fleet_driver.step()
        armed, whole = f.armed.tolist(), set(full.tolist())
        batch.begin(len(hooks), self.now)
        try:
            for k in np.union1d(full, hooks).tolist():
                self._turn = k
                if k in whole:
                    agents[k].fleet_outbound()
                else:
                    f.complete[k] = agents[k].fleet_loop(ARMED_ONLY[armed[k]], batch)
            self._turn = f.n
        finally:
            batch.flush(self.now, self.time.tick)

    def loop_hooks(self, hooks: np.ndarray) -> None:
        """The loop hooks of ``hooks`` (drones with nothing else to do this tick), in fleet order."""
        agents, f, batch = self.agents, self.fleet, self.batch
        tels, done, order = f.tels, [], hooks.tolist()
        append = done.append
        try:   # a loop, not a comprehension: when a hook raises, the drones before it have their results
            for k in order:
                append(agents[k].fleet_loop(tels[k], batch))
        finally:
            f.complete[hooks[:len(done)]] = done
            self._turn = order[len(done)] if len(done) < len(order) else f.n

    def fail_midtick(self) -> None:
        """A tick that fails part way (a hook raised): by then the object core had sent and routed
        the ground's messages, and every drone before the failing one had sent its own and its Report
        (``_turn``: the failing drone's index), so the fleet sends those Reports and routes the tick's
        messages before the failure goes on."""
        if not self.fleet.whole and self._turn:
            self.send_reports(upto=self._turn)
        self.network.route()

    def discrepancies(self) -> np.ndarray:
        """(3, N): GNSS fix - estimate of the drones with a new fix since their last Report, NaN for
        the others (AgentNode._publish; a fix is new when it differs: the fixes are noisy)."""
        fix, pos = self._values[6:9], self._values[0:3]
        new = (fix != self._fix).any(axis=0) & np.isfinite(fix).all(axis=0)
        self._fix[:, new] = fix[:, new]
        return np.where(new, fix - pos, np.nan)

    def send_reports(self, upto: int | None = None) -> None:
        """Every drone's Report, from the arrays (the superiors are fixed: every drone under the ground);
        with ``upto``, only those of the drones before it (a tick that failed there)."""
        f = self.fleet
        if upto is None:
            live = None if self._all_live else np.flatnonzero(self.live)   # a removed drone sends nothing
        else:
            live = np.flatnonzero(self.live[:upto])
        agents = self.agents if live is None else [self.agents[k] for k in live.tolist()]
        if upto is not None:
            reports = self.network.reports([a.node_id for a in agents], [a.superior for a in agents])
        else:
            if self._reports is None:
                self._reports = self.network.reports([a.node_id for a in agents],
                                                     [a.superior for a in agents])
            reports = self._reports
        seg, rows = (x.copy() for x in reports)
        data = list(map(DATA, agents))
        if live is None:
            f.seq += 1
        else:
            f.seq[live] += 1
        pick = (lambda a: a) if live is None else (lambda a: a[..., live])
        seg["msg_id"], seg["t_sent"] = pick(f.msg_id_base | f.seq), pick(self.now)
        seg["stage"], seg["complete"] = pick(f.stage), pick(f.complete)
        seg["alive"] = pick(f.stage) != ABORT
        seg["pos"], seg["vel"] = pick(self._values[0:3]).T, pick(self._values[3:6]).T
        seg["disc"] = pick(self.discrepancies()).T
        seg["nbytes"] = _REPORT_FIXED + np.fromiter(map(len, data), np.int32, len(agents))
        self.network.send_reports(seg, rows, data)
