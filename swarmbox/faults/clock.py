"""Node clock faults: a jump (offset) and/or a rate error (drift) from the onset.

The target node's :class:`~swarmbox.core.clock.NodeClock` is skewed in place, so everything that
node stamps — its log rows, the send times its messages carry, the arrival times of what it
receives — follows the faulty clock. At the end the clock resynchronises to its configured
offset and drift. Targets: drone ids, or -1 for the ground (the analyzer's reference clock: a
ground clock fault shifts the unified timeline itself).
"""

from __future__ import annotations

from dataclasses import dataclass

from swarmbox.faults.base import Fault, FaultEnv, FaultParams


@dataclass
class ClockSkewParams(FaultParams):
    offset_s: float = 0.0    # s, jump of the clock reading at the onset
    drift_ppm: float = 0.0   # ppm, rate error from the onset (local runs 1 + drift_ppm*1e-6 times as fast)


class ClockSkew(Fault):
    """The node's clock jumps by ``offset_s`` and runs ``drift_ppm`` fast from the onset."""

    name = "clock_skew"
    Params = ClockSkewParams
    target_kinds = frozenset({"drone", "ground"})

    def validate(self) -> None:
        self.require_range("offset_s", self.p.offset_s, -1e9, 1e9, "s")
        self.require_range("drift_ppm", self.p.drift_ppm, -1e5, 1e5, "ppm")

    def check(self, env: FaultEnv) -> None:
        for t in self.targets:
            if not hasattr(env.clock(t.node), "skew"):
                self.fail(f"node {t.node}'s clock cannot be skewed (backend {env.backend_label()})")

    def _nodes(self) -> list[int]:
        return [t.node for t in self.targets]

    def start(self, env: FaultEnv) -> None:
        at_s = env.now_s()
        for node in self._nodes():
            env.clock(node).skew(at_s, step_s=self.p.offset_s, drift_ppm=self.p.drift_ppm)
        _clocks_changed(env)

    def stop(self, env: FaultEnv) -> None:
        for node in self._nodes():
            env.clock(node).resync()
        _clocks_changed(env)


def _clocks_changed(env: FaultEnv) -> None:
    """Tell a network that keeps the clocks' lines as arrays (the fleet core's) to read them again."""
    refresh = getattr(env.swarm.medium, "refresh_clocks", None)
    if refresh is not None:
        refresh()
