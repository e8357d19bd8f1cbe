"""Time sources and per-node clocks.

The run loop owns one :class:`TimeSource` (virtual in simulation, the wall clock on hardware); each
node reads it through its own :class:`NodeClock`, which may be offset and drift like a real
unsynchronised computer clock. Every log record carries its node's local time.
"""

from __future__ import annotations

from dataclasses import dataclass


class TimeSource:
    """The run's true time (seconds since start) and tick counter. The run loop advances both."""

    __slots__ = ("t_s", "tick")

    def __init__(self) -> None:
        self.t_s = 0.0
        self.tick = 0


@dataclass(frozen=True, slots=True)
class ClockSpec:
    offset_s: float = 0.0    # local = true * (1 + drift_ppm * 1e-6) + offset_s
    drift_ppm: float = 0.0


class NodeClock:
    """A node's local clock over the shared time source."""

    __slots__ = ("_src", "_scale", "_offset_s")

    def __init__(self, src: TimeSource, spec: ClockSpec = ClockSpec()) -> None:
        self._src = src
        self._scale = 1.0 + spec.drift_ppm * 1e-6
        self._offset_s = spec.offset_s

    def now(self) -> float:
        return self._src.t_s * self._scale + self._offset_s

    def at(self, true_t_s: float) -> float:
        """The local reading at true time ``true_t_s`` (used to stamp message arrivals)."""
        return true_t_s * self._scale + self._offset_s
