"""What every fault model shares: targets, timing, seeded randomness, ground-truth events.

A fault model is a subclass of :class:`Fault` with a parameter schema (a :class:`FaultParams`
dataclass, which is also its config schema) and three hooks:

- ``check(env)`` — at install time: can the run's backend, medium and nodes express this fault?
  Raise :class:`FaultConfigError` naming the fault and the backend when not;
- ``start(env)`` — at the onset (the first tick at or after ``onset_s``);
- ``stop(env)`` — at ``onset_s + duration_s`` (never, when ``duration_s`` is None).

The driver (:meth:`Fault.install`) validates the common fields, schedules both on the swarm's tick
loop and writes one ``fault`` event per target at each of them into the ground's event log (the
analyzer's reference clock): name ``<fault>_start`` / ``<fault>_end``, subject = the target drone
(-1 the ground; for a link, its drone end), data = the target, the timing and every parameter.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import asdict, dataclass, field
from typing import Any, ClassVar, NamedTuple, NoReturn, Optional, final

import numpy as np

GROUND = -1


class FaultConfigError(ValueError):
    """A fault config the run cannot honour; the message names the fault and the key or backend."""


@dataclass
class FaultParams:
    """Fields every fault model has (its config schema extends this)."""

    # Drone ids; -1 the ground (network and clock faults); [src, dst] a directed link (network
    # faults); "all" every drone. A single id is accepted too (handy in sweeps: fault.targets=0,1,2).
    targets: Any = field(default_factory=list)
    onset_s: float = 0.0                 # s of run time (since ICEBREAK) at which the fault begins
    duration_s: Optional[float] = None   # s; None: until the end of the run  # noqa: UP045 (OmegaConf)


class Target(NamedTuple):
    """A resolved target: a node (``link`` None) or a directed link ``(src, dst)``."""

    node: int
    link: tuple[int, int] | None = None

    @property
    def subject(self) -> int:
        """The drone the fault is about (for a link: its drone end, the destination if both are)."""
        if self.link is None:
            return self.node
        src, dst = self.link
        return dst if dst != GROUND else src

    @property
    def key(self) -> str:
        """The target in random-stream names: the node id, or ``src>dst`` for a link."""
        return str(self.node) if self.link is None else f"{self.link[0]}>{self.link[1]}"

    def event_data(self) -> dict[str, Any]:
        if self.link is None:
            return {"target": self.node}
        return {"target": self.subject, "link": list(self.link)}


@dataclass
class FaultEnv:
    """What a fault may act on: the run's swarm (nodes, medium, tick loop) and its backend."""

    swarm: Any
    backend: Any
    backend_name: str
    drone_ids: list[int]
    max_sim_time_s: float
    tick_s: float
    rng_for: Callable[[str], np.random.Generator]

    def index(self, drone: int) -> int:
        """Position of ``drone`` in the backend's fault-input arrays and the swarm's agent list."""
        return self.drone_ids.index(drone)

    def agent(self, drone: int) -> Any:
        return self.swarm.agents[self.index(drone)]

    def clock(self, node: int) -> Any:
        return self.swarm.ground.clock if node == GROUND else self.agent(node).clock

    def now_s(self) -> float:
        return float(self.swarm.time.t_s)

    def at(self, t_s: float, action: Callable[[], None]) -> None:
        """Run ``action()`` at the first tick at or after run time ``t_s``."""
        self.swarm.schedule(t_s, _Action(action))

    def backend_label(self) -> str:
        cls = type(self.backend)
        return f"'{self.backend_name}' ({cls.__module__}.{cls.__qualname__})"

    def require_backend(self, fault: str, attrs: Sequence[str], what: str) -> None:
        """Fail unless the backend has every attribute of ``attrs`` (its fault inputs)."""
        missing = [a for a in attrs if not hasattr(self.backend, a)]
        if missing:
            raise FaultConfigError(
                f"fault {fault} cannot run on backend {self.backend_label()}: it needs {what} "
                f"({', '.join(missing)}), which this backend does not provide")


class Fault:
    """Base of the fault models (template method: the framework owns :meth:`install`).

    Subclasses set ``name``, ``Params`` and ``target_kinds`` (a subset of ``{"drone", "ground",
    "link"}``) and implement ``start`` (and ``stop`` unless the fault is permanent, ``permanent =
    True``). ``validate`` may add parameter checks (call :meth:`fail` with a clear message).
    """

    name: ClassVar[str] = ""
    Params: ClassVar[type[FaultParams]] = FaultParams
    target_kinds: ClassVar[frozenset[str]] = frozenset({"drone"})
    permanent: ClassVar[bool] = False

    def __init__(self, params: FaultParams, env: FaultEnv) -> None:
        self.p = params
        self.env = env
        self.targets = self._resolve_targets(params.targets)
        self.rngs = [env.rng_for(f"fault/{self.name}/{t.key}") for t in self.targets]
        self.active = False
        self._validate_timing()
        self.validate()

    # -- hooks ----------------------------------------------------------------------------------
    def validate(self) -> None:
        """Check the model's own parameters (raise through :meth:`fail`)."""

    def check(self, env: FaultEnv) -> None:
        """Check that the backend / medium / nodes can express this fault."""

    def start(self, env: FaultEnv) -> None:
        raise NotImplementedError

    def stop(self, env: FaultEnv) -> None:
        """Undo the fault (not called for permanent faults)."""

    # -- driver ---------------------------------------------------------------------------------
    @final
    def install(self) -> None:
        """Check the environment, then schedule the onset (and the end) on the tick loop."""
        self.check(self.env)
        self.env.at(self.p.onset_s, self._begin)
        if self.p.duration_s is not None:
            self.env.at(self.p.onset_s + self.p.duration_s, self._end)

    def _begin(self) -> None:
        self.active = True
        self._log("start")
        self.start(self.env)

    def _end(self) -> None:
        if not self.active:
            return
        self.active = False
        self.stop(self.env)
        self._log("end")

    def _log(self, phase: str) -> None:
        ground = self.env.swarm.ground
        params = self.parameters()
        for target in self.targets:
            ground.event("fault", f"{self.name}_{phase}", target.subject, fault=self.name,
                         **target.event_data(), **params)

    def parameters(self) -> dict[str, Any]:
        """The model's parameters and timing, for the event data (targets excluded)."""
        out = {k: v for k, v in asdict(self.p).items() if k != "targets"}
        return {k: (list(v) if isinstance(v, tuple) else v) for k, v in out.items()}

    def fail(self, message: str) -> NoReturn:
        raise FaultConfigError(f"fault {self.name}: {message}")

    # -- helpers for subclasses -------------------------------------------------------------------
    def drones(self) -> list[int]:
        """The drone targets (node targets that are not the ground)."""
        return [t.node for t in self.targets if t.link is None and t.node != GROUND]

    def require_range(self, key: str, value: float, lo: float, hi: float = math.inf, unit: str = "") -> None:
        if not (isinstance(value, int | float) and math.isfinite(value) and lo <= value <= hi):
            bound = f">= {lo:g}" if hi == math.inf else f"within [{lo:g}, {hi:g}]"
            self.fail(f"{key} must be {bound}{' ' + unit if unit else ''}, got {value!r}")

    def vector3(self, key: str, value: Sequence[float]) -> tuple[float, float, float]:
        try:
            vec = tuple(float(x) for x in value)
        except (TypeError, ValueError):
            vec = ()
        if len(vec) != 3 or not all(math.isfinite(x) for x in vec):
            self.fail(f"{key} must be three finite numbers [n, e, d], got {value!r}")
        return vec  # type: ignore[return-value]

    # -- validation of the common fields ----------------------------------------------------------
    def _validate_timing(self) -> None:
        p, end = self.p, self.env.max_sim_time_s
        self.require_range("onset_s", p.onset_s, 0.0, unit="s")
        if p.onset_s >= end:
            self.fail(f"onset_s {p.onset_s:g} s is after the mission's end "
                      f"(mission.max_sim_time_s = {end:g} s)")
        if p.duration_s is not None:
            if not (math.isfinite(p.duration_s) and p.duration_s > 0):
                self.fail(f"duration_s must be > 0 s (or null: until the end), got {p.duration_s!r}")
            if self.permanent:
                self.fail("the fault is permanent: duration_s must be null")

    def _resolve_targets(self, raw: Any) -> list[Target]:
        known = self.env.drone_ids
        items = _as_list(raw)
        if not items:
            self.fail("no targets (set e.g. fault.targets=[0])")
        out: list[Target] = []
        for item in items:
            if isinstance(item, str) and item == "all":
                out.extend(Target(d) for d in known)
            elif isinstance(item, Sequence) and not isinstance(item, str):
                out.append(self._link(item))
            else:
                out.append(self._node(item))
        if len(set(out)) != len(out):
            self.fail(f"a target is listed twice in {raw!r}")
        return out

    def _node(self, item: Any, *, in_link: bool = False) -> Target:
        known = self.env.drone_ids
        if isinstance(item, bool) or not isinstance(item, int | np.integer):
            self.fail(f"target {item!r} is not a drone id (an integer), [src, dst] or 'all'")
        node = int(item)
        if node == GROUND and ("ground" in self.target_kinds or in_link):
            return Target(node)
        if node not in known:
            also = ", -1 (the ground)" if "ground" in self.target_kinds or in_link else ""
            self.fail(f"unknown drone {node} in targets (drones: {known}{also})")
        if "drone" not in self.target_kinds and not in_link:
            self.fail(f"targets must be links [src, dst], got drone {node}")
        return Target(node)

    def _link(self, item: Sequence[Any]) -> Target:
        if "link" not in self.target_kinds:
            self.fail(f"targets are drones for this fault, not links: got {list(item)!r}")
        if len(item) != 2:
            self.fail(f"a link target is [src, dst], got {list(item)!r}")
        src, dst = (self._node(x, in_link=True).node for x in item)
        if src == dst:
            self.fail(f"link target {list(item)!r} joins a node to itself")
        return Target(src, (src, dst))


class _Action:
    """A scheduled callback that never orders before or after another one.

    The tick loop's schedule is a heap of ``(time, sequence, action)``; should two entries tie on
    both, the heap would compare the actions themselves, which plain functions do not support.
    """

    __slots__ = ("fn",)

    def __init__(self, fn: Callable[[], None]) -> None:
        self.fn = fn

    def __call__(self, _swarm: Any) -> None:
        self.fn()

    def __lt__(self, other: object) -> bool:
        return False

    def __gt__(self, other: object) -> bool:
        return False


def _as_list(raw: Any) -> list[Any]:
    if raw is None:
        return []
    if isinstance(raw, str) or not isinstance(raw, Sequence | Mapping):
        return [raw]
    if isinstance(raw, Mapping):
        return [raw]
    return list(raw)
