"""The two base classes an algorithm subclasses: one per role, template methods over a context."""

from __future__ import annotations

from collections.abc import Sequence
from typing import ClassVar, final

from swarmbox.api.context import DroneContext, GroundContext
from swarmbox.api.types import DescendantState, InferiorReport, Setpoint, Stage, Task

# Enum members as module globals: ``Stage.EXECUTION`` is a class-attribute lookup that costs several
# times a global's, and the drivers below run once per node and tick.
_PREPARATION, _EXECUTION = Stage.PREPARATION, Stage.EXECUTION


class DroneAlgorithm:
    """Base class of a drone's algorithm (one instance per drone).

    Hooks, in lifecycle order (each receives a :class:`DroneContext`):

    - ``prep_once`` — once, on entering PREPARATION.
    - ``prep_loop`` — every tick of PREPARATION.
    - ``prep_complete`` -> bool — every tick of PREPARATION; default: the vehicle is ready to arm.
    - ``exec_once`` — once, on entering EXECUTION (the framework arms the vehicle first).
    - ``exec_loop`` -> Setpoint | None — every tick of EXECUTION once armed; None keeps the last
      setpoint. **Required.**
    - ``exec_complete`` -> bool — every tick of EXECUTION; may flip back. **Required.**
    - ``on_task(ctx, task)`` — for every :class:`Task` delivered, before the tick's loop hook;
      reliable tasks arrive exactly once, in send order, and never before the ``*_once`` hook of
      the stage the sender was in when it sent them.
    - ``on_report(ctx, report)`` — for every :class:`InferiorReport` delivered from a direct inferior.
    - ``on_prox_alert(ctx, neighbours)`` — for every proximity alert from the ground: every tick
      while other drones are within ``run.proximity_m`` (their ids and reported positions), then
      once with none (all clear). ``ctx.proximity`` holds the latest neighbours.
    - ``successors`` -> Sequence[int] — the fallback superiors this drone advertises to its own
      inferiors; default: its own superior.

    Landing, termination, arming, failsafes and messaging are the framework's job.

    ``Params`` may name a dataclass (fields with types and defaults) describing ``ctx.params``: the
    run then refuses, before takeoff, a config whose ``algo.params`` has an unknown key or a value
    of the wrong type. Declare it on the drone class, the ground class, or both (the same class).
    """

    Params: ClassVar[type | None] = None

    def prep_once(self, ctx: DroneContext) -> None:
        """Called once on entering PREPARATION."""

    def prep_loop(self, ctx: DroneContext) -> None:
        """Called every tick of PREPARATION."""

    def prep_complete(self, ctx: DroneContext) -> bool:
        return ctx.state.ready_to_arm

    def exec_once(self, ctx: DroneContext) -> None:
        """Called once on entering EXECUTION."""

    def exec_loop(self, ctx: DroneContext) -> Setpoint | None:
        raise NotImplementedError(f"{type(self).__name__} must implement exec_loop")

    def exec_complete(self, ctx: DroneContext) -> bool:
        raise NotImplementedError(f"{type(self).__name__} must implement exec_complete")

    def on_task(self, ctx: DroneContext, task: Task) -> None:
        """Called for every task delivered to this drone."""

    def on_report(self, ctx: DroneContext, report: InferiorReport) -> None:
        """Called for every Report delivered from a direct inferior."""

    def on_prox_alert(self, ctx: DroneContext, neighbours: tuple[DescendantState, ...]) -> None:
        """Called for every proximity alert delivered (empty ``neighbours``: all clear)."""

    def successors(self, ctx: DroneContext) -> Sequence[int]:
        return (ctx.superior,)

    @final
    def enter_stage(self, stage: Stage, ctx: DroneContext) -> None:
        """Framework driver: run the entry hook of ``stage``."""
        if stage is Stage.PREPARATION:
            self.prep_once(ctx)
        elif stage is Stage.EXECUTION:
            self.exec_once(ctx)

    @final
    def run_stage(self, stage: Stage, ctx: DroneContext) -> tuple[bool, Setpoint | None]:
        """Framework driver: one tick of ``stage``; returns (complete, setpoint)."""
        if stage is _PREPARATION:
            self.prep_loop(ctx)
            return bool(self.prep_complete(ctx)), None
        if stage is _EXECUTION:
            # ctx.state.armed, read from the telemetry: builds no DroneState the algorithm may never ask for
            sp = self.exec_loop(ctx) if ctx._node.telemetry.armed else None
            return bool(self.exec_complete(ctx)), sp
        return True, None


class GroundAlgorithm:
    """Base class of the ground node's algorithm (one instance per run).

    Hooks (each receives a :class:`GroundContext`), in lifecycle order: ``prep_once``,
    ``prep_loop``, ``prep_complete`` -> bool, ``exec_once``, ``exec_loop``, ``exec_complete`` ->
    bool, and ``on_report(ctx, report)`` for every :class:`InferiorReport` delivered. The
    ``*_complete`` hooks default to True: a stage ends when every alive drone reports it complete;
    return False to hold it open. A stage's ``*_once`` hook runs on the tick the ground enters it,
    before that tick's loop hook and before the drones hear of the stage. ``Params``: as for
    :class:`DroneAlgorithm`.
    """

    Params: ClassVar[type | None] = None

    def prep_once(self, ctx: GroundContext) -> None:
        """Called once on entering PREPARATION (e.g. assign tasks)."""

    def prep_loop(self, ctx: GroundContext) -> None:
        """Called every tick of PREPARATION."""

    def prep_complete(self, ctx: GroundContext) -> bool:
        """Every tick of PREPARATION: may the swarm go on to EXECUTION (once the drones are ready)?"""
        return True

    def exec_once(self, ctx: GroundContext) -> None:
        """Called once on entering EXECUTION."""

    def exec_loop(self, ctx: GroundContext) -> None:
        """Called every tick of EXECUTION."""

    def exec_complete(self, ctx: GroundContext) -> bool:
        return True

    def on_report(self, ctx: GroundContext, report: InferiorReport) -> None:
        """Called for every Report delivered from a direct inferior."""

    @final
    def enter_stage(self, stage: Stage, ctx: GroundContext) -> None:
        """Framework driver: run the entry hook of ``stage``."""
        if stage is Stage.PREPARATION:
            self.prep_once(ctx)
        elif stage is Stage.EXECUTION:
            self.exec_once(ctx)

    @final
    def run_stage(self, stage: Stage, ctx: GroundContext) -> bool:
        """Framework driver: one tick of ``stage``; returns whether the ground is satisfied."""
        if stage is _PREPARATION:
            self.prep_loop(ctx)
            return bool(self.prep_complete(ctx))
        if stage is _EXECUTION:
            self.exec_loop(ctx)
            return bool(self.exec_complete(ctx))
        return True
