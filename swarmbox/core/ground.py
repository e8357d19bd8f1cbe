"""The ground node: the global swarm state machine.

Per tick: drain the inbox (Reports, acks) -> Heartbeat out -> proximity alerts -> user hook ->
inferior bookkeeping -> task retries -> stage transition. The ground advances when every *alive*
direct inferior reports complete for the ground's current stage (ICEBREAK also needs the expected
head-count); it aborts with a reason on a stage timeout or when fewer than ``min_alive`` drones
remain, instead of stalling.
"""

from __future__ import annotations

import math

import numpy as np

from swarmbox.api import GroundAlgorithm, GroundContext
from swarmbox.core.messages import GROUND_ID, DescendantState, Heartbeat, ProxAlert, Report, TaskAck
from swarmbox.core.node import Node, call_hook
from swarmbox.core.stages import TERMINAL, Stage

_ZERO3 = (0.0, 0.0, 0.0)


class GroundNode(Node):
    def __init__(self, algorithm: GroundAlgorithm, **kw) -> None:
        super().__init__(GROUND_ID, **kw)
        self.algorithm = algorithm
        self.ctx = GroundContext(self)
        self.reason = ""

    # -- the tick -------------------------------------------------------------------------------
    def tick(self) -> None:
        self.stage_tick += 1
        self._drain_inbox()
        self.net.publish(Heartbeat(self.next_msg_id(), self.clock.now(), GROUND_ID, int(self.stage), (),
                                   _ZERO3, _ZERO3))
        self._proximity_alerts()
        stage = self.stage
        satisfied = True
        if stage is Stage.PREPARATION:
            satisfied = call_hook(self, "prep_loop", self.algorithm.run_stage, stage, self.ctx)
        elif stage is Stage.EXECUTION:
            satisfied = call_hook(self, "exec_loop/exec_complete", self.algorithm.run_stage, stage, self.ctx)
        self.age_inferiors()
        self.retry_tasks()
        self._advance(satisfied)

    def _drain_inbox(self) -> None:
        inbox = self.inbox
        for msg in inbox:
            kind = type(msg)
            if kind is Report:
                if self.on_report(msg):
                    call_hook(self, "on_report", self.algorithm.on_report, self.ctx, msg)
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
        if (stage is not Stage.ICEBREAK and alive < self.timing.min_alive
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
        ready = alive > 0 and satisfied and self.inferiors_complete()
        if stage is Stage.ICEBREAK:
            ready = ready and total >= self.mission.swarm_size
        if ready:
            self.enter(Stage(stage + 1))

    def enter(self, stage: Stage, reason: str = "") -> None:
        self.set_stage(stage, reason)
        if stage is Stage.ABORT:
            self.reason = reason
        call_hook(self, f"{stage.name.lower()} entry", self.algorithm.enter_stage, stage, self.ctx)

    def _check_finished(self) -> None:
        stage = int(self.stage)
        settled = all(r.stage == stage and r.complete for r in self.alive_reports().values())
        if settled or self.stage_timed_out():
            self.finished = True

    # -- views and monitors ---------------------------------------------------------------------
    def swarm_view(self) -> dict[int, DescendantState]:
        return {d.drone_id: d for d in self.descendants()}

    def _proximity_alerts(self) -> None:
        """ProxAlert to every direct inferior with another known drone within ``proximity_m``."""
        view = self.descendants()
        if len(view) < 2:
            return
        near: dict[int, list[DescendantState]] = {}
        for a, b in _close_pairs(view, self.timing.proximity_m):
            near.setdefault(view[a].drone_id, []).append(view[b])
            near.setdefault(view[b].drone_id, []).append(view[a])
        for drone_id, others in near.items():
            if drone_id in self.inferiors and self.inferiors[drone_id].alive:
                self.net.send(ProxAlert(self.next_msg_id(), self.clock.now(), GROUND_ID, drone_id,
                                        tuple(others)), drone_id)


def _close_pairs(view: tuple[DescendantState, ...], limit_m: float) -> list[tuple[int, int]]:
    """Index pairs closer than ``limit_m`` (3-D): direct for small swarms, a k-d tree for large."""
    if len(view) <= 24:
        return [(a, b) for a in range(len(view)) for b in range(a + 1, len(view))
                if math.dist(view[a].pos_ned_m, view[b].pos_ned_m) < limit_m]
    from scipy.spatial import cKDTree  # here, not at the top: an agent process must not load scipy

    pts = np.array([d.pos_ned_m for d in view])
    pairs = cKDTree(pts).query_pairs(limit_m, output_type="ndarray")
    return sorted(map(tuple, pairs.tolist()))
