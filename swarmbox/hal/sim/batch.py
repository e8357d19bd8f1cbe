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

import math
from itertools import chain
from typing import Any

import numpy as np

from swarmbox.api import FlightMode, Setpoint, SetpointKind, SetpointVerdict, Telemetry
from swarmbox.hal.safety import SafetyLimits, reach_m
from swarmbox.hal.sim.control import CascadedController
from swarmbox.hal.sim.params import GRAVITY_M_S2, SimParams

_POSITION = SetpointKind.POSITION
_OFFBOARD, _LAND = FlightMode.OFFBOARD, FlightMode.LAND
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

    #: supervise the common cases over arrays (False: each vehicle on its own) ...
    batch_supervise = True
    #: ... from this many such vehicles on (fewer: a few dozen numpy calls cost more than they save)
    batch_supervise_from = 64
    t_s: float
    params: SimParams
    ctrl: CascadedController
    airborne: np.ndarray

    def _supervise_each(self, order: list[int]) -> list[int]:
        """``SimVehicle.supervise`` of each vehicle of ``order``; returns those that are done."""
        vehicles, t_s = self.vehicles, self.t_s
        return [i for i in order if not vehicles[i].supervise(t_s)]

    def supervise_many(self, order: list[int]) -> list[int]:
        """_supervise_each, with two common cases over arrays, after the others: an armed vehicle
        flying OFFBOARD (waiting to lift off, or climbing on its takeoff ramp) and one landing in
        LAND after a flight (waiting to touch down, then to disarm). Their supervision touches only
        their own vehicle and emits nothing; one about to disarm (an event) is supervised in its
        turn by its own ``supervise``, as before."""
        vehicles, t_s, p = self.vehicles, self.t_s, self.params
        ids = [i for i in order if _batched(vehicles[i])]
        if len(ids) < self.batch_supervise_from:
            ids = []
        if ids:
            arm = np.array([vehicles[i]._arm_t_s for i in ids])
            been = np.array([vehicles[i]._been_airborne for i in ids], dtype=bool)
            landing = np.array([vehicles[i].mode is _LAND for i in ids], dtype=bool)
            since = [vehicles[i]._ground_since_s for i in ids]
            down = np.array([math.nan if s is None else s for s in since])
            landed = self.airborne[ids] == 0.0
            disarms = np.where(landing, landed & (t_s - down >= p.land_disarm_delay_s),
                               ~been & landed & (t_s - arm >= p.preflight_disarm_s))
            keep = ~disarms
            ids = np.asarray(ids)[keep].tolist()
            arm, been, landing, down, landed = arm[keep], been[keep], landing[keep], down[keep], landed[keep]
        own = set(ids)
        done = [i for i in order if i not in own and not vehicles[i].supervise(t_s)]
        if ids:
            self._ramps(ids, arm)
            lifted = ~been & ~landed & ~landing
            touched = landing & landed & np.isnan(down)
            left = landing & ~landed & ~np.isnan(down)
            for i in np.asarray(ids)[lifted].tolist():
                vehicles[i]._been_airborne = True
            for i in np.asarray(ids)[touched].tolist():
                vehicles[i]._ground_since_s = t_s
            for i in np.asarray(ids)[left].tolist():
                vehicles[i]._ground_since_s = None
            ramping = np.isfinite(self.ctrl.tko_up_m_s[ids])
            done.extend(np.asarray(ids)[~landing & (been | lifted) & ~ramping].tolist())
        return done

    def _ramps(self, ids: list[int], arm: np.ndarray) -> None:
        """SimVehicle._ramp_takeoff of armed vehicles ``ids`` (armed at ``arm``), element-wise."""
        p = self.params
        since = self.t_s - arm - p.com_spoolup_time_s
        if p.mpc_tko_ramp_t_s <= 0:
            up = np.full(len(ids), np.inf)
        else:
            start = -GRAVITY_M_S2 / max(p.mpc_z_vel_p_acc, 1e-6)
            frac = np.minimum(np.maximum(since / p.mpc_tko_ramp_t_s, 0.0), 1.0)
            up = np.where(since < p.mpc_tko_ramp_t_s, start + frac * (p.mpc_z_vel_max_up_m_s - start), np.inf)
        self.ctrl.set_takeoff_ramps(ids, up)

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


def _batched(v: Any) -> bool:
    """Whether vehicle ``v``'s supervision is one of :meth:`BatchSetpoints.supervise_many`'s cases."""
    if not v.armed or v.frozen is not None or v._braking:
        return False
    return v.mode is _OFFBOARD or (v.mode is _LAND and v._been_airborne)


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
