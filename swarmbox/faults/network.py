"""Network faults: latency, Bernoulli loss, Gilbert-Elliott burst loss, link cut, partition.

They act through the medium's send-time hooks (:attr:`swarmbox.net.medium.SimMedium.hooks`): a hook
is added at the onset and removed at the end, so a fault costs nothing outside its window. A drone
(or ground, -1) target means every message to or from that node, in both directions — a faulty
radio — so delays stay symmetric and the analyzer's clock estimation is not fooled; a ``[src, dst]``
target means that directed link only. Drops carry the reason ``fault:<name>`` in the network log.

Randomness: each target draws from its own generator (``fault/<name>/<target>``, target = the node
id or ``src>dst``), only for the messages it matches, in send order — the same config and seed give
the same drops and delays, and adding a target leaves the others' draws unchanged.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from swarmbox.faults.base import Fault, FaultEnv, FaultParams

Verdict = tuple[str, float] | None
_KINDS = frozenset({"drone", "ground", "link"})


@dataclass
class LatencyParams(FaultParams):
    latency_ms: float = 20.0   # ms, added to every matching message
    jitter_ms: float = 0.0     # ms, plus a uniform extra delay in [0, jitter_ms]


@dataclass
class PacketLossParams(FaultParams):
    loss_prob: float = 0.3     # Bernoulli drop probability per message


@dataclass
class BurstLossParams(FaultParams):
    p_enter_burst: float = 0.05    # per message: good -> bad transition probability
    p_leave_burst: float = 0.25    # per message: bad -> good transition probability
    loss_prob_good: float = 0.0    # drop probability in the good state
    loss_prob_bad: float = 1.0     # drop probability in the bad (burst) state


@dataclass
class LinkCutParams(FaultParams):
    pass


@dataclass
class PartitionParams(FaultParams):
    pass


class _HookFault(Fault):
    """A fault that installs one medium hook while active. Subclasses implement ``verdict``."""

    target_kinds = _KINDS

    def check(self, env: FaultEnv) -> None:
        if not isinstance(getattr(env.swarm.medium, "hooks", None), list):
            medium = type(env.swarm.medium).__qualname__
            self.fail(f"cannot run with the network medium {medium} (backend {env.backend_label()}): "
                      "it needs send hooks, which the simulated medium (SimMedium) provides")
        self._nodes = {t.node: k for k, t in enumerate(self.targets) if t.link is None}
        self._links = {t.link: k for k, t in enumerate(self.targets) if t.link is not None}
        self._hook: Callable[[object, int, int, float], Verdict] = self._make_hook()

    def _make_hook(self) -> Callable[[object, int, int, float], Verdict]:
        nodes, links, verdict = self._nodes, self._links, self.verdict

        def hook(msg: object, src: int, dst: int, t_s: float) -> Verdict:
            k = nodes.get(src)
            if k is None:
                k = nodes.get(dst)
                if k is None:
                    k = links.get((src, dst))
                    if k is None:
                        return None
            return verdict(k)

        return hook

    def verdict(self, k: int) -> Verdict:
        """What happens to a message matched by target ``k``: None, or (drop_reason, extra_delay_s)."""
        raise NotImplementedError

    def start(self, env: FaultEnv) -> None:
        env.swarm.medium.hooks.append(self._hook)

    def stop(self, env: FaultEnv) -> None:
        hooks = env.swarm.medium.hooks
        if self._hook in hooks:
            hooks.remove(self._hook)

    def drop_reason(self) -> str:
        return f"fault:{self.name}"


class Latency(_HookFault):
    """Every matching message is delayed by ``latency_ms`` plus uniform jitter in [0, ``jitter_ms``]."""

    name = "latency"
    Params = LatencyParams

    def validate(self) -> None:
        self.require_range("latency_ms", self.p.latency_ms, 0.0, unit="ms")
        self.require_range("jitter_ms", self.p.jitter_ms, 0.0, unit="ms")
        self._delay_s, self._jitter_s = self.p.latency_ms / 1e3, self.p.jitter_ms / 1e3

    def verdict(self, k: int) -> Verdict:
        extra = self._delay_s
        if self._jitter_s:
            extra += self._jitter_s * self.rngs[k].random()
        return ("", extra)


class PacketLoss(_HookFault):
    """Every matching message is dropped with probability ``loss_prob`` (independently)."""

    name = "packet_loss"
    Params = PacketLossParams

    def validate(self) -> None:
        self.require_range("loss_prob", self.p.loss_prob, 0.0, 1.0)

    def verdict(self, k: int) -> Verdict:
        if self.rngs[k].random() < self.p.loss_prob:
            return (self.drop_reason(), 0.0)
        return None


class BurstLoss(_HookFault):
    """Gilbert-Elliott loss: a two-state Markov chain per target, stepped once per matching message.

    Each target starts in the good state. Per message: move good -> bad with ``p_enter_burst`` (or
    bad -> good with ``p_leave_burst``), then drop with the new state's loss probability. The
    long-run loss ratio is ``pi_bad * loss_prob_bad + (1 - pi_bad) * loss_prob_good`` with
    ``pi_bad = p_enter / (p_enter + p_leave)``; mean burst length ``1 / p_leave_burst`` messages.
    """

    name = "burst_loss"
    Params = BurstLossParams

    def validate(self) -> None:
        for key in ("p_enter_burst", "p_leave_burst", "loss_prob_good", "loss_prob_bad"):
            self.require_range(key, getattr(self.p, key), 0.0, 1.0)
        self._bad = [False] * len(self.targets)

    @property
    def stationary_loss(self) -> float:
        p = self.p
        total = p.p_enter_burst + p.p_leave_burst
        pi_bad = p.p_enter_burst / total if total else 0.0
        return pi_bad * p.loss_prob_bad + (1 - pi_bad) * p.loss_prob_good

    def verdict(self, k: int) -> Verdict:
        rng, p = self.rngs[k], self.p
        if self._bad[k]:
            self._bad[k] = rng.random() >= p.p_leave_burst
        else:
            self._bad[k] = rng.random() < p.p_enter_burst
        loss = p.loss_prob_bad if self._bad[k] else p.loss_prob_good
        if rng.random() < loss:
            return (self.drop_reason(), 0.0)
        return None


class LinkCut(_HookFault):
    """Every matching message is dropped: a node's radio cut off, or one directed link down."""

    name = "link_cut"
    Params = LinkCutParams

    def verdict(self, k: int) -> Verdict:
        return (self.drop_reason(), 0.0)


class Partition(_HookFault):
    """The targets form one side of a partition: messages crossing between the sides are dropped."""

    name = "partition"
    Params = PartitionParams
    target_kinds = frozenset({"drone", "ground"})

    def _make_hook(self) -> Callable[[object, int, int, float], Verdict]:
        side = frozenset(t.node for t in self.targets)
        reason = (self.drop_reason(), 0.0)

        def hook(msg: object, src: int, dst: int, t_s: float) -> Verdict:
            return reason if (src in side) != (dst in side) else None

        return hook

    def verdict(self, k: int) -> Verdict:  # the hook above decides on its own
        return None

