"""What the simulated fleet reports: every vehicle's telemetry, and the columns of the ``state`` log.

Both are read from the backend's fleet arrays once per step, whatever the number of vehicles: the
telemetry records are built together on first demand (a tick asks for all of them) and the state
columns are written into the recorder's buffers in a few numpy calls. A crashed vehicle reports the
telemetry frozen at its crash.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from functools import partial
from itertools import repeat
from operator import attrgetter
from typing import Any

import numpy as np

from swarmbox.api import Telemetry
from swarmbox.hal.sim.sensors import GnssEstimator

# Telemetry(*fields) built by tuple.__new__ in C: a NamedTuple's own constructor is Python code
_new_telemetry = partial(tuple.__new__, Telemetry)
_ARMED, _MODE = attrgetter("armed"), attrgetter("mode")


class FleetReadout:
    """Telemetry and state columns of a fleet, from arrays that live as long as the backend.

    ``kin`` (9, N) holds estimate, velocity and true position rows; ``yaw_rad`` and ``airborne`` are
    (N,); ``crashed`` (N,) is the crash fault input and ``crash_seen`` the crashes the backend has
    applied; ``battery()`` returns
    this step's battery fractions; the backend keeps ``t_s`` current and calls ``step_done()``.
    """

    def __init__(self, *, kin: np.ndarray, yaw_rad: np.ndarray, airborne: np.ndarray, gnss: GnssEstimator,
                 crashed: np.ndarray, crash_seen: np.ndarray, est_init_s: float,
                 battery: Callable[[], np.ndarray]) -> None:
        self._kin, self._yaw, self._airborne, self._gnss = kin, yaw_rad, airborne, gnss
        self._crashed, self._crash_seen = crashed, crash_seen
        self._est_init_s, self._battery = est_init_s, battery
        self.vehicles: Sequence[Any] = ()   # set by the backend once its vehicles exist
        self.t_s = 0.0
        self._tel: list[Telemetry] | None = None   # every vehicle's, built once per step on demand
        self.n_fixes = 0                            # GNSS fixes taken: the key of the cached lists
        self._fix_key: tuple = ()
        self._fix_lists: tuple[list, list, list] = ([], [], [])   # fix tuples, seq, ready: change only
        #                                                          with a fix, a crash, est_init_s

    def step_done(self) -> None:
        """The step's arrays are final: telemetry is built again on the next demand."""
        self._tel = None

    def estimate_ned(self, i: int) -> tuple[float, float, float]:
        """Vehicle ``i``'s estimated position (n, e, d): this step's telemetry has it, once built."""
        if self._tel is not None:
            return self._tel[i].pos_ned_m
        n, e, d = self._kin[0:3, i].tolist()
        return (n, e, d)

    def telemetry_of(self, i: int) -> Telemetry:
        """Vehicle ``i``'s telemetry; its armed flag and mode are the vehicle's own and may change within
        the step (then read again)."""
        tel = (self._tel or self._build())[i]
        v = self.vehicles[i]
        if tel.armed is not v.armed or tel.mode is not v.mode:
            tel = self._tel[i] = tel._replace(armed=v.armed, mode=v.mode)   # type: ignore[index]
        return tel

    def telemetry_many(self, index: list[int]) -> list[Telemetry]:
        """``telemetry_of`` of each vehicle of ``index``, in one pass (a crashed vehicle's is frozen)."""
        tels = self._tel or self._build()
        out = list(map(tels.__getitem__, index))
        vehicles = self.vehicles
        for j, (i, tel) in enumerate(zip(index, out, strict=True)):
            v = vehicles[i]
            if tel.armed is not v.armed or tel.mode is not v.mode or v.frozen is not None:
                out[j] = v.telemetry()
        return out

    def _build(self) -> list[Telemetry]:
        """Every vehicle's telemetry in one pass: the vectors are made by ``zip`` and the records by
        ``tuple.__new__``, both in C."""
        t, vehicles = self.t_s, self.vehicles
        n = len(vehicles)
        fixes, seq, ready = self._gnss_lists(t)
        en, ee, ed, vn, ve, vd, pn, pe, pd = self._kin.tolist()
        self._tel = list(map(_new_telemetry, zip(
            repeat(t, n), zip(en, ee, ed, strict=True), zip(vn, ve, vd, strict=True),
            self._yaw.tolist(), fixes, seq, list(map(_ARMED, vehicles)),
            (self._airborne == 0.0).tolist(), list(map(_MODE, vehicles)), self._battery().tolist(),
            ready, zip(pn, pe, pd, strict=True), repeat(True, n),
            strict=False)))   # the repeats are as long as the fleet
        return self._tel

    def _gnss_lists(self, t_s: float) -> tuple[list, list, list]:
        """Per vehicle: latest fix (None before the first), fix count, ready flag — cached."""
        g = self._gnss
        key = (self.n_fixes, t_s >= self._est_init_s, int(np.count_nonzero(self._crashed)))
        if key != self._fix_key:
            seq = g.seq.tolist()
            fixes = list(zip(*g.fix_ned_m.tolist(), strict=True))
            if not all(seq):
                fixes = [f if s else None for f, s in zip(fixes, seq, strict=True)]
            self._fix_lists = (fixes, seq, (g.ready(t_s) & ~self._crashed).tolist())
            self._fix_key = key
        return self._fix_lists

    def state_into(self, values: np.ndarray, landed: np.ndarray, index: np.ndarray | None = None) -> None:
        """Write the ``state`` columns of vehicles ``index`` (None: all, in order) into ``values``
        (14, n) — position, velocity, GNSS fix, true position (each n, e, d), yaw, battery — and
        ``landed`` (n,), in a few numpy calls; a crashed vehicle's values are its frozen telemetry's."""
        kin, g = self._kin, self._gnss
        if index is None:
            np.concatenate((kin[0:6], g.fix_ned_m, kin[6:9]), out=values[:12])
            np.copyto(values[12], self._yaw)
            np.copyto(values[13], self._battery())
            np.equal(self._airborne, 0.0, landed)
        else:
            values[:12] = np.concatenate((kin[0:6], g.fix_ned_m, kin[6:9]))[:, index]
            values[12], values[13] = self._yaw[index], self._battery()[index]
            landed[:] = self._airborne[index] == 0.0
        crashed = self._crash_seen if index is None else self._crash_seen[index]
        for j in np.flatnonzero(crashed).tolist():
            tel = self.vehicles[j if index is None else int(index[j])].frozen
            if tel is not None:
                fix = tel.gnss_ned_m or (math.nan,) * 3
                values[:, j] = (*tel.pos_ned_m, *tel.vel_ned_m_s, *fix, *tel.true_pos_ned_m, tel.yaw_rad,
                                tel.battery_frac)
                landed[j] = tel.landed
