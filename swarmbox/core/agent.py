"""A drone's agent node: the per-agent state machine that mirrors the ground's.

Per tick: read telemetry -> drain the inbox (Heartbeats, and tasks from the superior, may move the
stage; tasks go to ``on_task`` in order, never ahead of their stage's ``*_once``) -> superior
watchdog (handover / failsafe) -> inferior bookkeeping -> stage work (user hooks, setpoint to the
vehicle) -> Heartbeat and Report out -> task retries -> state row.
"""

from __future__ import annotations

from functools import partial

from swarmbox.api import (
    DescendantState,
    DroneAlgorithm,
    DroneContext,
    DroneState,
    FlightMode,
    PeerState,
    Setpoint,
    SetpointKind,
    Task,
    Telemetry,
)
from swarmbox.api.fleet import FleetAlgorithm
from swarmbox.api.views import read_only, read_only_mission
from swarmbox.core.batch import FleetDriver
from swarmbox.core.delivery import DELIVERED, NEW, Window
from swarmbox.core.messages import GROUND_ID, Heartbeat, ProxAlert, Report, TaskAck, TaskCommand
from swarmbox.core.node import STAGE_OF, AlgorithmError, Node, call_hook, hook_error
from swarmbox.core.ports import Vehicle
from swarmbox.core.rows import NO_TEXT, TEXTS, pack_setpoint
from swarmbox.core.stages import TERMINAL, Stage, path_to

#: a setpoint kind's and an ok verdict's codes in the log's text table
_KIND_CODES = {SetpointKind.POSITION: TEXTS.code("position"), SetpointKind.VELOCITY: TEXTS.code("velocity"),
               SetpointKind.ACCELERATION: TEXTS.code("acceleration")}
_LOOP_HOOK = {Stage.PREPARATION: "prep_loop/prep_complete", Stage.EXECUTION: "exec_loop/exec_complete"}
# Enum members as globals for the per-tick paths (a class-attribute lookup costs several times more)
_EXECUTION, _ABORT = Stage.EXECUTION, Stage.ABORT
_LOOP_STAGES = frozenset(_LOOP_HOOK)
_DOWN_STAGES = frozenset({Stage.LANDING, Stage.ABORT})
#: Mode text by mode (``FlightMode.value`` is a Python-level property; a dict lookup is not).
MODE_TEXT = {m: m.value for m in FlightMode}
_NAN = float("nan")
_new_state = partial(tuple.__new__, DroneState)
_new_report = partial(tuple.__new__, Report)   # Report(*all 13 fields), built in C
_new_peer = partial(tuple.__new__, PeerState)
_NAN3 = (_NAN, _NAN, _NAN)
_OK_CODE = TEXTS.code("ok")


class AgentNode(Node):
    def __init__(self, node_id: int, *, superior: int, algorithm: DroneAlgorithm | FleetAlgorithm,
                 vehicle: Vehicle,
                 **kw) -> None:
        super().__init__(node_id, **kw)
        # its own frozen copies: a hook that writes them fails, and no other node sees a change
        self.params, self.mission = read_only(self.params), read_only_mission(self.mission)
        self.tasks_refused = 0   # send_task calls refused (the destination not an alive direct inferior)
        self.superior, self.algorithm, self.vehicle = superior, algorithm, vehicle
        self.home_ned_m = tuple(float(x) for x in vehicle.home_ned_m)
        self.ctx = DroneContext(self)
        self.telemetry: Telemetry = vehicle.telemetry()
        if isinstance(algorithm, FleetAlgorithm):   # a fleet of one, until a swarm adopts it
            self.algorithm = FleetDriver(algorithm, [self]).members[0]
        self.complete = False
        self.removed = False
        self.reason = ""
        self.report_data = ""
        self.last_task: Task | None = None
        self.proximity: tuple[DescendantState, ...] = ()
        self._prox_tick = 0
        self.peer_view: dict[int, PeerState] = {}
        self._own: DroneState | None = None
        self._sup_silent, self._heard_superior = 0, False
        self._successor_list: tuple[int, ...] = ()
        self._abandoned: set[int] = set()
        t = self.timing
        self._window = Window(t.task_retry_ticks * (t.task_max_retries + 2))
        self._gnss_seq = -1
        self._exec_done = False
        self._window_busy = False   # a stage change may release held tasks: drain even without mail
        self._state_every = t.state_every_ticks
        self._lost_superior_ticks = t.lost_superior_ticks
        self.own_state_rows = True   # False: a fleet-wide log writes this drone's state rows
        self._log_state = kw["log"].appender("state")
        self._log_setpoint = kw["log"].appender("setpoints")
        self.net.subscribe(node_id, superior)

    # -- the tick -------------------------------------------------------------------------------
    def tick(self) -> None:
        self.begin_tick()
        self.finish_tick()

    def begin_tick(self) -> None:
        """The inbound half of a tick: telemetry, inbox (stage changes, tasks), watchdogs.

        A fleet driver (``core.batch``) runs every agent's inbound half, then the fleet's loop hooks,
        then every agent's :meth:`finish_tick`.
        """
        self.stage_tick += 1
        tel = self.telemetry = self.vehicle.telemetry()
        self._own = None
        if not tel.link_ok and self.stage not in TERMINAL:
            self.event("failsafe", "vehicle_link_lost", self.node_id, action="return_to_launch")
            self.enter(Stage.ABORT, "link to the autopilot lost", failsafe=True)
        if self.inbox or self._window_busy or self.proximity:
            self._drain_inbox()
        if self._heard_superior and self.stage not in TERMINAL:   # the superior watchdog
            self._sup_silent += 1
            if self._sup_silent > self._lost_superior_ticks:
                self._hand_over("silent")
        if self.inferiors:
            self.age_inferiors()

    def finish_tick(self) -> None:
        """The outbound half of a tick: stage work (user hooks, setpoint), Heartbeat/Report, rows."""
        tel = self.telemetry
        now = self.clock.now()   # the clock stands still within a tick: one reading for its records
        self.complete = self._stage_work(tel, now)
        self._publish(tel, now)
        if self.outbox.pending:
            self.retry_tasks()
        if self.own_state_rows and self.time.tick % self._state_every == 0:
            self._record_state(tel)
        if self.stage in TERMINAL and (not tel.armed or self.stage_timed_out()):
            self.finished = True

    def own_state(self) -> DroneState:
        """This tick's telemetry without ground truth (built once, on first use)."""
        if self._own is None:
            tel = self.telemetry   # DroneState.of(tel), without the Python-level NamedTuple constructor
            self._own = _new_state((*tel[:11], tel.link_ok))
        return self._own

    def _drain_inbox(self) -> None:
        inbox = self.inbox
        now = None
        for msg in inbox:
            kind = type(msg)
            if kind is Heartbeat:
                if msg.src == self.superior:
                    self._sup_silent, self._heard_superior = 0, True
                    self._successor_list = msg.successors
                    commanded = STAGE_OF[msg.stage]
                    if commanded is not self.stage:
                        self._follow(commanded)
                else:
                    if now is None:
                        now = self.clock.now()
                    self.peer_view[msg.src] = _new_peer((msg.src, STAGE_OF[msg.stage], msg.pos_ned_m,
                                                         msg.vel_ned_m_s, now))
            elif kind is Report:
                if self.on_report(msg):
                    call_hook(self, "on_report", self.algorithm.on_report, self.ctx,
                              self._alive[msg.src])
            elif kind is TaskCommand:
                self._on_task(msg)
            elif kind is TaskAck:
                self.on_ack(msg)
            elif kind is ProxAlert:
                self._on_prox_alert(msg)
        inbox.clear()
        if self._window_busy:
            for src in self._window.holding():   # a stage change may have released held tasks
                self._deliver_ready(src)
            self._window_busy = bool(self._window.holding())
        if self.proximity and self.time.tick - self._prox_tick > self.timing.lost_inferior_ticks:
            self.proximity = ()   # the ground's all-clear was lost, or the ground fell silent

    def _on_prox_alert(self, alert: ProxAlert) -> None:
        self.proximity, self._prox_tick = alert.neighbours, self.time.tick   # empty: all clear
        call_hook(self, "on_prox_alert", self.algorithm.on_prox_alert, self.ctx, alert.neighbours)

    def _on_task(self, cmd: TaskCommand) -> None:
        if cmd.src == self.superior and cmd.stage > self.stage and self.stage not in TERMINAL:
            self._follow(STAGE_OF[cmd.stage])   # the task announces its sender's stage
        if not cmd.reliable:
            if cmd.stage <= self.stage or self.stage is Stage.ABORT:
                self._deliver(cmd)   # best effort: one from a stage not reached yet is dropped
            return
        verdict = self._window.accept(cmd, self.time.tick)
        if verdict is NEW:
            self._deliver_ready(cmd.src)
            self._window_busy = True
        elif verdict is DELIVERED:   # its acknowledgement was lost: say it again
            self._ack(cmd)
        if self._window.notes:
            self._log_skips()

    def _deliver_ready(self, src: int) -> None:
        """Hand over what the window releases; each is acknowledged only once ``on_task`` has it."""
        for cmd in self._window.release(src, int(self.stage), self.time.tick):
            self._deliver(cmd)
            self._ack(cmd)
        if self._window.notes:
            self._log_skips()

    def _ack(self, cmd: TaskCommand) -> None:
        self.net.send(TaskAck(self.next_msg_id(), self.clock.now(), self.node_id, cmd.src, cmd.seq,
                              cmd.incarnation), cmd.src)

    def _log_skips(self) -> None:
        """Every reliable task this drone will never deliver, as ``error/task_skipped`` events."""
        for skip in self._window.notes:
            self.event("error", "task_skipped", skip.src, first=skip.first, last=skip.last,
                       incarnation=skip.incarnation, reason=skip.reason)
        self._window.notes.clear()

    def _deliver(self, cmd: TaskCommand) -> None:
        task = self.last_task = Task(cmd.src, cmd.seq, cmd.reliable, cmd.code, cmd.waypoint_ned_m,
                                     cmd.yaw_rad, cmd.data, self.clock.now())
        call_hook(self, "on_task", self.algorithm.on_task, self.ctx, task)

    # -- stages ---------------------------------------------------------------------------------
    def _follow(self, commanded: Stage) -> None:
        """Adopt the superior's stage, running the entry action of every stage passed through."""
        if commanded == self.stage or self.stage in TERMINAL:
            return
        if commanded is Stage.ABORT:
            if self.superior != GROUND_ID:   # a drone superior lost its vehicle or hit a failsafe
                self.event("topology", "superior_aborted", self.node_id, superior=self.superior)
                self._hand_over("aborted")
            else:
                self.enter(Stage.ABORT, "superior aborted")
        elif commanded > self.stage:
            for stage in path_to(self.stage, commanded):
                self.enter(stage)

    def enter(self, stage: Stage, reason: str = "", *, failsafe: bool = False) -> None:
        self.set_stage(stage, reason)
        self.complete = False
        vehicle = self.vehicle
        if stage is Stage.EXECUTION:
            vehicle.arm()
        elif stage is Stage.LANDING:
            vehicle.land()
        elif stage is Stage.TERMINATION and self.telemetry.armed:
            vehicle.disarm()
        elif stage is Stage.ABORT:
            self.reason = reason
            tel = self.telemetry
            if tel.armed and not tel.landed:
                vehicle.return_to_launch() if failsafe else vehicle.land()
            elif tel.armed:
                vehicle.disarm()
        call_hook(self, f"{stage.name.lower()} entry", self.algorithm.enter_stage, stage, self.ctx)

    def _stage_work(self, tel: Telemetry, now: float) -> bool:
        stage = self.stage
        if stage in _LOOP_STAGES:
            complete, sp = self._loop_hooks(stage, tel)
            if sp is not None:
                self.send_setpoint(sp, now)
            if stage is _EXECUTION and complete != self._exec_done:
                self._note_exec(complete)
            return complete
        if stage in _DOWN_STAGES:
            return tel.landed and not tel.armed  # touched down and disarmed by the autopilot

        return True  # ICEBREAK, TERMINATION

    def _loop_hooks(self, stage: Stage, tel: Telemetry) -> tuple[bool, Setpoint | None]:
        """A loop stage's work before its setpoint: the arming retry and the hooks' (complete, setpoint)."""
        if (stage is _EXECUTION and not tel.armed
                and self.stage_tick % self.timing.arm_retry_ticks == 0):
            self.vehicle.arm()
        try:   # call_hook, inlined: this runs once per drone and tick
            complete, sp = self.algorithm.run_stage(stage, self.ctx)
        except AlgorithmError:   # a fleet hook's, naming its drones already
            raise
        except Exception as exc:  # the user's code may raise anything
            raise hook_error(self, _LOOP_HOOK[stage], exc) from exc
        if sp is not None and type(sp) is not Setpoint:
            raise TypeError(f"drone {self.node_id}: exec_loop returned {type(sp).__name__}, "
                            "expected Setpoint or None")
        return complete, sp

    def send_setpoint(self, sp: Setpoint, now: float) -> None:
        """Hand ``sp`` to the vehicle and log it with the safety monitor's verdict."""
        verdict = self.vehicle.setpoint(sp)
        n, e, d = sp.ned
        yaw = sp.yaw_rad
        if verdict is None or (verdict.action == "ok" and not verdict.reason):   # the usual case
            action, why = _OK_CODE, NO_TEXT
        else:
            action, why = TEXTS.code(verdict.action), TEXTS.code(verdict.reason)
        self._log_setpoint(pack_setpoint(now, self.time.tick, _KIND_CODES[sp.kind], n, e, d,
                                         _NAN if yaw is None else yaw, action, why))

    def _note_exec(self, complete: bool) -> None:
        """The execution stage's completion changed: a progress event (the ground's stage follows it)."""
        self._exec_done = complete
        self.event("progress", "exec_complete" if complete else "exec_incomplete", self.node_id)

    # -- superior watchdog ----------------------------------------------------------------------
    def _hand_over(self, why: str) -> None:
        """The superior is gone (``silent``) or out of the mission (``aborted``): follow the next of
        its successors, or abort when none is left."""
        lost = self.superior
        self._abandoned.add(lost)
        options = [s for s in self._successor_list if s != self.node_id and s not in self._abandoned]
        if options:
            self.net.unsubscribe(self.node_id, lost)
            self.superior = options[0]
            self.net.subscribe(self.node_id, self.superior)
            self._sup_silent = 0
            self.event("topology", "handover", self.node_id, lost=lost, new=self.superior)
            return
        if why == "aborted":   # every successor is out too (the whole mission aborts): land
            self.enter(Stage.ABORT, "superior aborted")
            return
        self.event("failsafe", "superior_lost", self.node_id, superior=lost, action="return_to_launch")
        self.enter(Stage.ABORT, f"lost superior {lost} with no successor left", failsafe=True)

    def vehicle_failed(self, reason: str) -> None:
        """The autopilot refused a flight command to the end of its retries: this drone aborts."""
        if self.stage not in TERMINAL:
            self.event("failsafe", "vehicle_failed", self.node_id, reason=reason, action="land")
            self.enter(Stage.ABORT, reason)

    # -- outgoing -------------------------------------------------------------------------------
    def _publish(self, tel: Telemetry, now: float) -> None:
        node_id, net = self.node_id, self.net
        if net.has_subscribers(node_id):
            succ = tuple(call_hook(self, "successors", self.algorithm.successors, self.ctx))
            net.publish(Heartbeat(self.next_msg_id(), now, node_id, self.stage_code, succ,
                                  tel.pos_ned_m, tel.vel_ned_m_s))
        disc = None
        if tel.gnss_seq != self._gnss_seq and tel.gnss_ned_m is not None:
            self._gnss_seq = tel.gnss_seq
            g, p = tel.gnss_ned_m, tel.pos_ned_m
            disc = (g[0] - p[0], g[1] - p[1], g[2] - p[2])
        stage = self.stage
        if self.inferiors:
            total, alive = self.head_count()
            complete, below = self.complete and self.inferiors_complete(), self.descendants()
        else:   # a leaf (most drones): nothing below it
            total = alive = 0
            complete, below = self.complete, ()
        superior = self.superior
        net.send(_new_report((self.next_msg_id(), now, node_id, superior, self.stage_code, complete,
                              total + 1, alive + (stage is not _ABORT), tel.pos_ned_m, tel.vel_ned_m_s,
                              disc, self.report_data, below)), superior)

    def _record_state(self, tel: Telemetry) -> None:
        p, v = tel.pos_ned_m, tel.vel_ned_m_s
        g = tel.gnss_ned_m or _NAN3
        tp = tel.true_pos_ned_m or _NAN3
        self._log_state((self.clock.now(), self.time.tick, self.stage_code, tel.armed, tel.landed,
                         MODE_TEXT[tel.mode], p[0], p[1], p[2], v[0], v[1], v[2], g[0], g[1], g[2],
                         tp[0], tp[1], tp[2], tel.yaw_rad, tel.battery_frac))
