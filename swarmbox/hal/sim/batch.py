"""Many vehicles' setpoints in one call: what :meth:`SimVehicle.setpoint` does for each, in order.

A hovering or cruising swarm sends most vehicles the setpoint they flew last tick, which the safety
monitor passed unchanged then. For those, :meth:`SimVehicle.setpoint` only checks what depends on the
vehicle's state (the jump limit of a position, the envelope's boundary for a velocity or an
acceleration) and answers the verdict it gave then. :meth:`BatchSetpoints.setpoints` makes that check
for every such vehicle in a few array operations; every other vehicle (a new setpoint, one near a
limit, a crashed vehicle) goes through :meth:`SimVehicle.setpoint` itself, in the order given, so that
verdicts, commands and events are the per-vehicle call's.
"""

from __future__ import annotations

from itertools import chain
from typing import Any

import numpy as np

from swarmbox.api import Setpoint, SetpointKind, SetpointVerdict, Telemetry
from swarmbox.hal.safety import SafetyLimits, reach_m

_POSITION = SetpointKind.POSITION
#: The array tests round differently from ``math.dist``/``math.hypot`` in the last bits: a vehicle this
#: close (relative) to a limit is judged by the vehicle's own test.
_MARGIN = 1e-9


class BatchSetpoints:
    """Mixin of :class:`~swarmbox.hal.sim.backend.SimBackend`: the batch entries beside each vehicle's
    ``setpoint`` and ``telemetry``."""

    vehicles: list[Any]
    limits: SafetyLimits
    _est: np.ndarray   # (3, N): the estimated positions the vehicles' checks read
    _known: _Known | None = None
    _readout: Any

    def telemetry_many(self, index: list[int]) -> list[Telemetry]:
        """``vehicles[i].telemetry()`` for every ``i`` of ``index``."""
        return self._readout.telemetry_many(index)

    def setpoints(self, index: list[int], sps: list[Setpoint]) -> list[tuple[int, SetpointVerdict]]:
        """Hand ``sps[j]`` to vehicle ``index[j]`` for every ``j``, as ``vehicles[i].setpoint(sp)`` in
        that order would; returns ``(j, verdict)`` for every setpoint whose verdict is not a plain
        ``ok`` (an ``ok`` without a reason is the usual answer, not listed)."""
        vehicles = self.vehicles
        held = _held(vehicles, index, sps)
        fast = np.zeros(len(sps), dtype=bool)
        if held:
            fast[held] = self._within(np.array([index[j] for j in held], dtype=np.intp),
                                      [sps[j] for j in held])
        for i in np.asarray(index)[fast].tolist():   # what SimVehicle.setpoint does here: marks it fresh
            vehicles[i]._held.fresh = True
        odd = []
        for j in np.flatnonzero(~fast).tolist():   # every other in order, as the vehicle judges it
            verdict = vehicles[index[j]].setpoint(sps[j])
            if verdict.action != "ok" or verdict.reason:
                odd.append((j, verdict))
        return odd

    def _within(self, index: np.ndarray, sps: list[Setpoint]) -> np.ndarray:
        """Whether each vehicle's held setpoint passes again: a position within the jump limit of the
        estimate, a velocity or an acceleration flown clear of the envelope's boundary."""
        if self._known is None:
            self._known = _Known(len(self.vehicles))
        ned, position = self._known.columns(index, sps)
        lim, est = self.limits, self._est[:, index]
        jump = np.sqrt(((ned - est) ** 2).sum(axis=0)) <= lim.max_jump_m * (1.0 - _MARGIN)
        if position.all():
            return jump
        reach = reach_m(lim) * (1.0 + _MARGIN) + _MARGIN * (lim.geofence_radius_m + lim.max_alt_m)
        clear = (lim.geofence_radius_m - np.hypot(est[0], est[1]) > reach) & (lim.max_alt_m + est[2] > reach)
        return np.where(position, jump, clear)


def _held(vehicles: list[Any], index: list[int], sps: list[Setpoint]) -> list[int]:
    """The positions ``j`` whose setpoint is the one vehicle ``index[j]`` passed unchanged last (the
    vehicle not crashed), with a plain ``ok`` then."""
    out = []
    for j, (i, sp) in enumerate(zip(index, sps, strict=True)):
        v = vehicles[i]
        if sp == v._last_ok and v.frozen is None and not v._ok_verdict.reason:
            out.append(j)
    return out


class _Known:
    """The north/east/down and kind of the setpoint each vehicle was last checked with: a vehicle
    holding the same Setpoint object costs an identity test, not a conversion."""

    def __init__(self, n: int) -> None:
        self.ned = np.zeros((3, n))
        self.position = np.zeros(n, dtype=bool)
        self.sps: list[Setpoint | None] = [None] * n

    def columns(self, index: np.ndarray, sps: list[Setpoint]) -> tuple[np.ndarray, np.ndarray]:
        known = self.sps
        new = [j for j, (i, sp) in enumerate(zip(index.tolist(), sps, strict=True)) if sp is not known[i]]
        if new:
            rows = index[new]
            fresh = [sps[j] for j in new]
            self.ned[:, rows] = np.fromiter(chain.from_iterable(sp.ned for sp in fresh), float,
                                            3 * len(new)).reshape(-1, 3).T
            self.position[rows] = [sp.kind is _POSITION for sp in fresh]
            for i, sp in zip(rows.tolist(), fresh, strict=True):
                known[i] = sp
        return self.ned[:, index], self.position[index]
