"""The ground node: the global swarm state machine.

Per tick: drain the inbox (Reports, acks) -> inferior bookkeeping -> stage transition (entering a
stage runs its ``*_once`` hook) -> Heartbeat out, announcing the stage entered this very tick ->
proximity alerts -> the stage's loop hook -> task retries. So a stage change takes effect and is
announced in the same tick, and its ``*_once`` hook runs before its loop hook, exactly as on a drone.

The ground advances when every *alive* direct inferior reports complete for the ground's current
stage and the ground's own ``*_complete`` hook agreed on the previous tick (ICEBREAK also needs the
expected head-count); it aborts with a reason on a stage timeout or when fewer than ``min_alive``
drones remain, instead of stalling.

A ground process started again during a run (:meth:`GroundNode.rejoin`) does not command ICEBREAK
to a swarm in flight: it listens first, until the whole swarm has reported or ``lost_inferior_ticks``
have passed, then adopts the most advanced stage its drones report (ABORT only if all report it),
walking there stage by stage so that each stage's entry hook runs, as on a drone that joins late.
"""

from __future__ import annotations

from typing import Protocol

from swarmbox.api import DescendantState, GroundAlgorithm, GroundContext
from swarmbox.api.views import read_only, read_only_mission
from swarmbox.core.messages import GROUND_ID, NO_SUBJECT, Heartbeat, ProxAlert, Report, TaskAck
from swarmbox.core.node import STAGE_OF, Node, call_hook, new_inferior_report
from swarmbox.core.proximity import DIRECT_PAIRS_UP_TO, Episode, ProximityTracker, kd_tree
from swarmbox.core.stages import TERMINAL, Stage, path_to

_ZERO3 = (0.0, 0.0, 0.0)
_NO_DRONES: frozenset[int] = frozenset()
# Enum members as globals for the per-tick paths (a class-attribute lookup costs several times more)
_ICEBREAK, _PREPARATION, _EXECUTION = Stage.ICEBREAK, Stage.PREPARATION, Stage.EXECUTION


def _ids(ids: list[int]) -> str:
    return f"drone {ids[0]}" if len(ids) == 1 else f"drones {sorted(ids)}"


class GroundObserver(Protocol):
    """Watches the ground node from outside the swarm logic (e.g. the live monitor).

    Called at the end of every ground tick, on the tick thread: it must return quickly and must not
    change the node.
    """

    def after_tick(self, ground: GroundNode) -> None: ...


class GroundNode(Node):
    def __init__(self, algorithm: GroundAlgorithm, **kw) -> None:
        super().__init__(GROUND_ID, **kw)
        # its own frozen copies: a hook that writes them fails, and no other node sees a change
        self.params, self.mission = read_only(self.params), read_only_mission(self.mission)
        self.tasks_refused = 0   # send_task calls refused (the destination not an alive direct inferior)
        self.algorithm = algorithm
        self.ctx = GroundContext(self)
        self.reason = ""
        self._satisfied = True   # the ground algorithm's *_complete verdict on its latest loop tick
        self.proximity = ProximityTracker(self.timing.proximity_m, self.timing.proximity_window_s)
        self.prox_pairs: dict[tuple[int, int], float] = {}   # alerted pair -> distance, this tick
        self.observer: GroundObserver | None = None
        self._orphaned_since: int | None = None   # tick since which every direct inferior aborted
        self._adopt_until: int | None = None   # a restarted ground listens until this tick (rejoin)
        # the base class's on_report does nothing: not calling it saves a call per Report
        self._wants_reports = type(algorithm).on_report is not GroundAlgorithm.on_report
        if self.mission.swarm_size > DIRECT_PAIRS_UP_TO:
            kd_tree()   # load scipy now, not inside the first timed tick

    # -- the tick -------------------------------------------------------------------------------
    def tick(self) -> None:
        self.stage_tick += 1
        self._drain_inbox()
        self.age_inferiors()
        if self._adopt_until is not None and not self._adopt_stage():
            return   # still listening: no Heartbeat that could contradict the swarm's stage
        self._advance(self._satisfied)
        self.net.publish(Heartbeat(self.next_msg_id(), self.clock.now(), GROUND_ID, self.stage_code, (),
                                   _ZERO3, _ZERO3))
        self._proximity_alerts()
        stage = self.stage
        if stage is _PREPARATION:
            self._satisfied = call_hook(self, "prep_loop/prep_complete", self.algorithm.run_stage, stage,
                                        self.ctx)
        elif stage is _EXECUTION:
            self._satisfied = call_hook(self, "exec_loop/exec_complete", self.algorithm.run_stage, stage,
                                        self.ctx)
        self.retry_tasks()
        if self.observer is not None:
            self.observer.after_tick(self)

    def _drain_inbox(self) -> None:
        inbox = self.inbox
        now = self.clock.now()   # one reading for the whole inbox: the clock stands still within a tick
        inferiors, alive, wants = self.inferiors, self._alive, self._wants_reports
        for msg in inbox:
            kind = type(msg)
            if kind is Report:
                # the fields in one unpacking (Report's order): cheaper than six attribute reads
                _, _, src, _, stage, complete, _, _, pos, vel, _, data, _ = msg
                inf = inferiors.get(src)
                if inf is not None and inf.alive and not wants:   # Node.on_report's usual case, inline
                    inf.report, inf.silent_ticks = msg, 0
                    inf.received += 1
                    alive[src] = new_inferior_report((src, STAGE_OF[stage], complete, pos, vel, data, now))
                elif self.on_report(msg, now) and wants:
                    call_hook(self, "on_report", self.algorithm.on_report, self.ctx,
                              self._alive[msg.src])
            elif kind is TaskAck:
                self.on_ack(msg)
        inbox.clear()

    # -- stage logic ----------------------------------------------------------------------------
    def _advance(self, satisfied: bool) -> None:
        stage = self.stage
        if stage in TERMINAL:
            self._check_finished()
            return
        total, alive = self.head_count()
        if (stage is not _ICEBREAK and alive < self.timing.min_alive
                and self.time.tick > self.regroup_until_tick):
            self.enter(Stage.ABORT, f"only {alive} of {self.mission.swarm_size} drones alive "
                                    f"(min_alive {self.timing.min_alive})")
            return
        if self.stage_timed_out():
            done = sum(1 for r in self.alive_reports().values() if r.complete and r.stage == stage)
            self.enter(Stage.ABORT, f"{stage.name} timed out after "
                                    f"{self.timing.timeouts_s[stage.name]:g} s: {done} of "
                                    f"{len(self.alive_reports())} alive inferiors complete, "
                                    f"{total} of {self.mission.swarm_size} drones joined")
            return
        if stage is not _ICEBREAK and self._commands_none():
            return
        ready = alive > 0 and satisfied and self.inferiors_complete()
        if stage is _ICEBREAK:
            ready = ready and total >= self.mission.swarm_size
        if ready:
            self.enter(Stage(stage + 1))

    def _commands_none(self) -> bool:
        """Whether the ground must not advance: before LANDING, every drone it commands directly has
        aborted (under leader_follower: the leader). Their inferiors hand over to their successors —
        the ground, for a leader's followers — so the ground holds the stage for as long as a
        handover takes (``lost_superior_ticks + lost_inferior_ticks``) and the mission goes on under
        it; if no drone has joined by then, nothing is left to complete the mission and the ground
        aborts. Counting the aborted drones as done would land the swarm early with the run ``ok``."""
        direct = [i for i, inf in self.inferiors.items() if inf.alive]
        if (self.stage is Stage.LANDING or not direct
                or any(self.inferiors[i].report.stage != Stage.ABORT for i in direct)):
            self._orphaned_since = None
            return False
        tick = self.time.tick
        if self._orphaned_since is None:
            self._orphaned_since = tick
        if tick - self._orphaned_since <= self.timing.lost_superior_ticks + self.timing.lost_inferior_ticks:
            return True
        self.enter(Stage.ABORT, f"every drone the ground commands aborted ({_ids(direct)}) and none "
                                f"took over: the {self.stage.name} was cut short")
        return True

    def rejoin(self) -> None:
        """This process restarts the ground of a run under way: adopt the swarm's stage from the
        drones' Reports instead of starting the mission over."""
        self._adopt_until = self.time.tick + self.timing.lost_inferior_ticks

    def _adopt_stage(self) -> bool:
        """True once the stage is adopted (the swarm reported, or the listening time is over)."""
        total, _ = self.head_count()
        if total < self.mission.swarm_size and self.time.tick < self._adopt_until:
            return False
        self._adopt_until = None
        reported = {i: r.stage for i, r in sorted(self.alive_reports().items())}
        flying = [s for s in reported.values() if s is not Stage.ABORT]
        target = max(flying) if flying else (Stage.ABORT if reported else Stage.ICEBREAK)
        self.event("topology", "stage_adopted", NO_SUBJECT, stage=target.name, drones=total,
                   reported={str(i): s.name for i, s in reported.items()})
        if target is not Stage.ICEBREAK:
            for stage in path_to(Stage.ICEBREAK, target):
                self.enter(stage, "adopted from the drones' reports after a restart")
        return True

    def enter(self, stage: Stage, reason: str = "") -> None:
        self.set_stage(stage, reason)
        # a stage with ground hooks waits for its *_complete to be asked at least once
        self._satisfied = stage not in (Stage.PREPARATION, Stage.EXECUTION)
        if stage is Stage.ABORT:
            self.reason = reason
        call_hook(self, f"{stage.name.lower()} entry", self.algorithm.enter_stage, stage, self.ctx)

    def _check_finished(self) -> None:
        """Finished once every alive inferior has settled: reports this stage complete, or aborted
        on its own and is down (an aborted drone never reports TERMINATION, so waiting for it would
        only run out the timeout)."""
        stage = self.stage
        settled = all(r.complete and (r.stage is stage or r.stage is Stage.ABORT)
                      for r in self.alive_reports().values())
        if settled or self.stage_timed_out():
            self.finished = True
            for ep in self.proximity.active.values():   # still close when the mission ends
                self._log_episode("prox_end", ep)
            self.proximity.active.clear()

    # -- views and monitors ---------------------------------------------------------------------
    def swarm_view(self) -> dict[int, DescendantState]:
        return {d.drone_id: d for d in self.descendants()}

    def _proximity_alerts(self) -> None:
        """ProxAlert to both drones of every alerted pair; episodes logged as events.

        A drone whose last pair ended gets one empty ProxAlert (all clear). Drones below a direct
        inferior (trees, leader-follower) are addressed directly, not relayed: every medium delivers
        to any node id (as the reference's per-drone alert topic did), and a relay would add a tick
        per level and fail with any drone on the way.
        """
        view = self.descendants()
        before = {d for pair in self.prox_pairs for d in pair} if self.prox_pairs else _NO_DRONES
        self.prox_pairs, started, ended = self.proximity.update(self.clock.now(), view)
        for ep in started:
            self._log_episode("prox_start", ep)
        for ep in ended:
            self._log_episode("prox_end", ep)
        if not self.prox_pairs and not before:
            return
        by_id = {d.drone_id: d for d in view}
        near: dict[int, list[DescendantState]] = {}
        for a, b in self.prox_pairs:
            near.setdefault(a, []).append(by_id[b])
            near.setdefault(b, []).append(by_id[a])
        for drone_id in sorted(near.keys() | before):
            if drone_id in by_id:   # alive, directly or through its superior's Report
                self.net.send(ProxAlert(self.next_msg_id(), self.clock.now(), GROUND_ID, drone_id,
                                        tuple(near.get(drone_id, ()))), drone_id)

    def _log_episode(self, name: str, ep: Episode) -> None:
        a, b = ep.pair
        fields = dict(pair=[a, b], start_t_s=ep.start_t_s, predicted=ep.predicted,
                      distance_m=round(ep.start_distance_m, 3))
        if name == "prox_end":
            fields.update(min_distance_m=round(ep.min_distance_m, 3), breached=ep.breached,
                          breach_t_s=ep.breach_t_s, duration_s=round(self.clock.now() - ep.start_t_s, 6))
        self.event("proximity", name, a, **fields)
