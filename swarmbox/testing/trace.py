"""Hook tracing for the algorithm conformance suite: which hook ran, on which node, in which stage.

:meth:`HookTrace.install` wraps the hooks of every node's algorithm *instance* (the ``@final``
drivers look hooks up on the instance, so the class is untouched) before the first tick. A
:class:`~swarmbox.api.FleetAlgorithm`'s hooks are wrapped once and each call counts for every drone
row it was made for, so its lifecycle is checked per drone like a DroneAlgorithm's.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

from swarmbox.api import Setpoint, Stage

#: The stage each stage hook belongs to.
HOOK_STAGE = {"prep_once": Stage.PREPARATION, "prep_loop": Stage.PREPARATION,
              "prep_complete": Stage.PREPARATION, "exec_once": Stage.EXECUTION,
              "exec_loop": Stage.EXECUTION, "exec_complete": Stage.EXECUTION}
ONCE = {Stage.PREPARATION: "prep_once", Stage.EXECUTION: "exec_once"}
DRONE_HOOKS = (*HOOK_STAGE, "on_task", "on_report", "successors")
GROUND_HOOKS = (*HOOK_STAGE, "on_report")


class HookTrace:
    """Calls of every hook, in order: (node, hook, stage the node was in). Bad setpoints aside."""

    def __init__(self) -> None:
        self.calls: list[tuple[str, str, Stage]] = []
        self.setpoints: list[tuple[str, Any]] = []   # exec_loop results that are not a sane Setpoint

    def install(self, swarm: Any) -> None:
        self._wrap("ground", swarm.ground, GROUND_HOOKS)
        driver = getattr(swarm, "fleet_driver", None)
        if driver is not None:   # a FleetAlgorithm: one instance, its calls counted per drone row
            self._wrap_fleet(driver)
            return
        for agent in swarm.agents:
            self._wrap(f"drone_{agent.node_id}", agent, DRONE_HOOKS)

    def _wrap_fleet(self, driver: Any) -> None:
        alg, agents, calls = driver.algorithm, driver.agents, self.calls
        for hook in DRONE_HOOKS:
            fn = getattr(alg, hook)

            def traced(fleet: Any, which: Any, *rest: Any, _hook: str = hook, _fn: Callable = fn) -> Any:
                for i in ([which] if isinstance(which, int) else which.tolist()):   # a row, or rows
                    calls.append((f"drone_{agents[i].node_id}", _hook, agents[i].stage))
                return _fn(fleet, which, *rest)

            setattr(alg, hook, traced)

    def _wrap(self, label: str, node: Any, hooks: tuple[str, ...]) -> None:
        alg = node.algorithm
        for hook in hooks:
            original = getattr(alg, hook, None)
            if original is not None:
                setattr(alg, hook, self._traced(label, node, hook, original))

    def _traced(self, label: str, node: Any, hook: str, fn: Callable) -> Callable:
        calls, bad = self.calls, self.setpoints

        def traced(*args: Any) -> Any:
            calls.append((label, hook, node.stage))
            result = fn(*args)
            if hook == "exec_loop" and result is not None and not _sane(result):
                bad.append((label, result))
            return result

        return traced


def _sane(sp: Any) -> bool:
    return (type(sp) is Setpoint and len(sp.ned) == 3
            and all(type(x) is float and math.isfinite(x) for x in sp.ned)
            and (sp.yaw_rad is None or math.isfinite(sp.yaw_rad)))


def lifecycle_problems(trace: HookTrace, limit: int = 5) -> list[str]:
    """Every breach of the hook order, per node (at most ``limit`` per node)."""
    by_node: dict[str, list[tuple[str, Stage]]] = {}
    for node, hook, stage in trace.calls:
        by_node.setdefault(node, []).append((hook, stage))
    out: list[str] = []
    for node, calls in by_node.items():
        found = _node_problems(node, calls)
        out += found[:limit]
    return out


def _node_problems(node: str, calls: list[tuple[str, Stage]]) -> list[str]:
    done: dict[str, int] = {}
    out = []
    for i, (hook, stage) in enumerate(calls):
        belongs = HOOK_STAGE.get(hook)
        if belongs is not None and stage is not belongs:
            out.append(f"{node}: {hook} ran in {stage.name}, not {belongs.name} (call {i})")
        if hook in ONCE.values():
            if hook in done:
                out.append(f"{node}: {hook} ran twice (calls {done[hook]} and {i})")
            done[hook] = i
        elif belongs is not None and ONCE[belongs] not in done:
            out.append(f"{node}: {hook} ran before {ONCE[belongs]} (call {i})")
        if belongs is Stage.PREPARATION and "exec_once" in done:
            out.append(f"{node}: {hook} ran after exec_once (call {i})")
        if hook == "on_task" and "prep_once" not in done:
            out.append(f"{node}: on_task ran before prep_once, in {stage.name} (call {i})")
    return out
