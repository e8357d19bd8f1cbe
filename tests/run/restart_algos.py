"""Algorithms for the restart tests: reliable tasks all through EXECUTION, each send and each delivery
marked with a run-unique ``data`` so a test can match them across processes."""

from __future__ import annotations

import time

from swarmbox.algorithms.hover import HoverDrone
from swarmbox.api import DroneContext, GroundAlgorithm, GroundContext, Task

PERIOD_S = 0.4


def send_round(ctx, targets, state: dict) -> None:
    """One reliable task to each of ``targets`` every PERIOD_S of EXECUTION, marked as sent."""
    if ctx.stage_time_s < state.get("next_s", 0.0):
        return
    state["next_s"] = ctx.stage_time_s + PERIOD_S
    for dst in sorted(targets):
        state["k"] = state.get("k", 0) + 1
        data = f"{getattr(ctx, 'id', -1)}/{time.time_ns()}/{state['k']}"   # unique across processes
        ctx.mark("task_sent", dst=dst, data=data)
        ctx.send_task(dst, code=state["k"] % 100, data=data)


class TaskingGround(GroundAlgorithm):
    """Tasks its direct inferiors all through EXECUTION; done after ``hover_s`` of it."""

    def exec_once(self, ctx: GroundContext) -> None:
        self.state: dict = {}

    def exec_loop(self, ctx: GroundContext) -> None:
        send_round(ctx, ctx.reports, self.state)

    def exec_complete(self, ctx: GroundContext) -> bool:
        return ctx.stage_time_s >= float(ctx.params["hover_s"])


class TaskingDrone(HoverDrone):
    """Hovers (``HoverDrone``), marks every task it gets and tasks its inferiors (a leader's followers)."""

    def exec_once(self, ctx: DroneContext) -> None:
        super().exec_once(ctx)
        self.state: dict = {}

    def exec_loop(self, ctx: DroneContext):
        if ctx.inferiors:
            send_round(ctx, ctx.inferiors, self.state)
        return super().exec_loop(ctx)

    def on_task(self, ctx: DroneContext, task: Task) -> None:
        ctx.mark("task_got", src=task.src, seq=task.seq, data=task.data)
