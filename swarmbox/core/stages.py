"""The mission lifecycle shared by the ground node and every agent: one transition table over the
API's :class:`~swarmbox.api.Stage` enum."""

from __future__ import annotations

from swarmbox.api.types import Stage

__all__ = ["TERMINAL", "TRANSITIONS", "IllegalTransition", "Stage", "check_transition", "path_to"]


#: Legal transitions. Every stage but the two terminal ones may go to ABORT.
TRANSITIONS: dict[Stage, frozenset[Stage]] = {
    Stage.ICEBREAK: frozenset({Stage.PREPARATION, Stage.ABORT}),
    Stage.PREPARATION: frozenset({Stage.EXECUTION, Stage.ABORT}),
    Stage.EXECUTION: frozenset({Stage.LANDING, Stage.ABORT}),
    Stage.LANDING: frozenset({Stage.TERMINATION, Stage.ABORT}),
    Stage.TERMINATION: frozenset(),
    Stage.ABORT: frozenset(),
}

TERMINAL = frozenset({Stage.TERMINATION, Stage.ABORT})


class IllegalTransition(RuntimeError):
    """A node was asked to move between two stages the lifecycle does not connect."""

    def __init__(self, src: Stage, dst: Stage) -> None:
        super().__init__(f"illegal stage transition {src.name} -> {dst.name}")
        self.src, self.dst = src, dst


def check_transition(src: Stage, dst: Stage) -> None:
    if dst not in TRANSITIONS[src]:
        raise IllegalTransition(src, dst)


def path_to(src: Stage, dst: Stage) -> list[Stage]:
    """The stages a node passes through, in order, to go from ``src`` to ``dst``.

    An agent that hears a stage more than one step ahead (it joined late, or Heartbeats were lost)
    walks through every intermediate stage so that each stage's entry actions still run.
    """
    if dst is Stage.ABORT:
        return [Stage.ABORT]
    if src in TERMINAL or dst < src:
        raise IllegalTransition(src, dst)
    return [Stage(code) for code in range(src + 1, dst + 1)]
