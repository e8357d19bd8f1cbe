"""Time sources and per-node clocks.

The run loop owns one :class:`TimeSource` (virtual in simulation, the wall clock on hardware); each
node reads it through its own :class:`NodeClock`, which may be offset and drift like a real
unsynchronised computer clock. Every log record carries its node's local time.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np


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
    """A node's local clock over the shared time source.

    The reading is linear in true time, ``local = true * scale + offset``. :meth:`skew` changes the
    line from a given instant on (a clock fault: a jump and/or a different rate, continuous
    otherwise) and :meth:`resync` puts the configured line back (what a resynchronisation does).
    """

    __slots__ = ("_src", "_scale", "_offset_s", "_spec")

    def __init__(self, src: TimeSource, spec: ClockSpec = ClockSpec()) -> None:
        self._src = src
        self._spec = spec
        self._scale = 1.0 + spec.drift_ppm * 1e-6
        self._offset_s = spec.offset_s

    def now(self) -> float:
        return self._src.t_s * self._scale + self._offset_s

    def at(self, true_t_s: float) -> float:
        """The local reading at true time ``true_t_s`` (used to stamp message arrivals)."""
        return true_t_s * self._scale + self._offset_s

    def skew(self, at_true_s: float, *, step_s: float = 0.0, drift_ppm: float = 0.0) -> None:
        """From true time ``at_true_s`` on, jump by ``step_s`` and run ``drift_ppm`` faster.

        The drift multiplies the clock's current rate (so it adds to a configured drift); apart
        from the jump, the reading stays continuous at ``at_true_s``.
        """
        local_s = self.at(at_true_s) + step_s
        scale = self._scale * (1.0 + drift_ppm * 1e-6)
        if scale <= 0.0:
            raise ValueError(f"clock drift of {drift_ppm} ppm would stop or reverse the clock")
        self._scale = scale
        self._offset_s = local_s - at_true_s * scale

    def resync(self) -> None:
        """Return to the configured offset and drift (undo every :meth:`skew`)."""
        self._scale = 1.0 + self._spec.drift_ppm * 1e-6
        self._offset_s = self._spec.offset_s

    @property
    def drift_ppm(self) -> float:
        """The clock's current rate error, in parts per million."""
        return (self._scale - 1.0) * 1e6


def readings(clocks: Sequence[NodeClock], true_t_s: float, out: np.ndarray | None = None) -> np.ndarray:
    """Every clock's :meth:`NodeClock.now` at true time ``true_t_s`` (the same arithmetic, so the same
    values); written into ``out`` when given. A list comprehension beats gathering the clocks' fields
    into numpy at every fleet size up to a few hundred."""
    values = [true_t_s * c._scale + c._offset_s for c in clocks]
    if out is None:
        return np.array(values, dtype=np.float64)
    out[:] = values
    return out
