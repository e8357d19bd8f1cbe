"""The ``sim`` backend: a 2.5D multicopter fleet with a PX4-like autopilot per vehicle.

Horizontal rigid-body dynamics, drag and contacts live in pymunk (:mod:`swarmbox.hal.sim.world`);
altitude is integrated alongside in numpy with the same integrator and drag, with the ground at
``d = 0``.
Each vehicle flies on its *estimate* (:mod:`swarmbox.hal.sim.sensors`) through a cascaded controller
(:mod:`swarmbox.hal.sim.control`); commands and modes are :class:`~swarmbox.hal.sim.vehicle.SimVehicle`.
One :meth:`SimBackend.step` advances the whole fleet with a fixed number of numpy and pymunk calls;
on long runs the numpy arithmetic is replaced by three calls of a compiled kernel that computes the
same numbers bit for bit (:mod:`swarmbox.hal.sim.kernel`, ``backend.jit``).
"""

from __future__ import annotations

import logging
import math
from collections.abc import Mapping, Sequence
from types import ModuleType
from typing import Any

import numpy as np

from swarmbox.api import Telemetry
from swarmbox.hal.safety import SafetyLimits, reach_m
from swarmbox.hal.sim import kernel
from swarmbox.hal.sim.batch import BatchSetpoints
from swarmbox.hal.sim.control import CascadedController
from swarmbox.hal.sim.params import SimParams
from swarmbox.hal.sim.readout import FleetReadout
from swarmbox.hal.sim.sensors import GnssEstimator
from swarmbox.hal.sim.vehicle import SimVehicle
from swarmbox.hal.sim.world import PlaneWorld, ned_xy
from swarmbox.hal.vehicle import VehicleEvent

__all__ = ["SimBackend", "SimParams", "SimVehicle"]

log = logging.getLogger(__name__)


def _load_kernel(mode: str) -> ModuleType | None:
    """The compiled kernel; under ``jit: auto`` a failure to load it leaves the run on numpy."""
    try:
        return kernel.compiled()
    except Exception as exc:
        if mode == "always":
            raise RuntimeError(f"backend.jit=always needs numba ({exc}); install it or set "
                               "backend.jit=auto") from exc
        log.warning("the compiled sim kernel did not load (%s); flying on numpy", exc)
        return None


def _check_homes(homes_ned_m: Sequence[Sequence[float]]) -> np.ndarray:
    homes = np.array(homes_ned_m, dtype=float)
    if homes.ndim != 2 or homes.shape[1] != 3 or not len(homes) or not np.all(np.isfinite(homes)):
        raise ValueError(f"homes_ned_m must be a non-empty list of finite (n, e, d), got {homes_ned_m!r}")
    return homes


class SimBackend(BatchSetpoints):
    """A simulated fleet (implements :class:`swarmbox.hal.vehicle.Backend`).

    Constructed by the runner as ``SimBackend(homes_ned_m=..., tick_s=..., rng=..., obstacles=...,
    limits=..., **params)`` where ``params`` are the keys of ``conf/backend/sim.yaml`` (see
    :class:`SimParams`; an unknown key raises TypeError). ``obstacles`` are mappings
    ``{kind: segment, a: [n, e], b: [n, e], radius_m}``, ``{kind: box, center: [n, e], size: [dn, de]}``
    or ``{kind: circle, center: [n, e], radius_m}``, of infinite height.

    Fault inputs — public arrays of length N, neutral by default, read at every step:

    - ``gnss_offset_ned_m`` (N,3): added to every GNSS fix (a ramp is a drift);
    - ``gnss_noise_scale`` (N,): multiplies the GNSS noise;
    - ``gnss_available`` (N,) bool: False stops the fixes;
    - ``accel_scale`` (N,): multiplies the horizontal and upward acceleration limits (motor loss);
    - ``crashed`` (N,) bool: set True to crash a vehicle — motors off, it falls, ignores commands and
      its telemetry freezes (permanent).

    Read-only views for tests and analysis: ``estimator_resets`` (N,) counts estimator position
    resets; ``true_pos_ned_m`` / ``true_vel_ned_m_s`` (N,3) are ground truth, ``est_pos_ned_m`` (N,3)
    the estimates; ``airborne`` (N,) is 1.0 for a vehicle in the air, 0.0 on the ground.

    Each vehicle starts on the ground (``d = 0``) at the north/east of its home.
    """

    realtime = False

    def __init__(self, *, homes_ned_m: Sequence[Sequence[float]], tick_s: float, rng: np.random.Generator,
                 obstacles: Sequence[Mapping[str, Any]] = (), limits: SafetyLimits = SafetyLimits(),
                 **params: Any) -> None:
        self.params = p = SimParams.from_kwargs(params)
        homes = _check_homes(homes_ned_m)
        if not tick_s > 0:
            raise ValueError(f"tick_s must be > 0, got {tick_s!r}")
        n = self.n = len(homes)
        self.tick_s, self.limits, self.t_s = float(tick_s), limits, 0.0
        self._init_state(homes)
        self.ctrl = CascadedController(n, p)
        self._acc = self.ctrl.acc_ned_m_s2
        self._acc_d, self._acc_xy, self._vel_xy = self._acc[2], ned_xy(self._acc), ned_xy(self._vel)
        self._gnss = GnssEstimator(n, p, rng)
        self._events: list[VehicleEvent] = []
        self._event_t_s = 0.0
        self._world = PlaneWorld(homes.T, p, obstacles, self._pos_d, self._vel_d, self.airborne,
                                 self._emit_collision)
        self._world.read(self._pos, self._vel)
        self._dt_s, self._substeps, self._t0_s, self._k = -1.0, 1, 0.0, 0
        self._vert_k = (np.zeros(()), np.zeros(()))
        self._battery, self._battery_ok = np.zeros(n), False   # battery fractions, once per step
        # the compiled per-step kernel (kernel.py): the same numbers as the numpy code, faster
        self._kernel = (_load_kernel(p.jit) if p.jit == "always" else kernel.loaded() if p.jit == "auto"
                        else None)
        self._jit_wanted = p.jit == "auto" and self._kernel is None and kernel.installed()
        self._vertical: tuple = ()
        self._supervised: set[int] = set()
        self._supervise_order: list[int] | None = []   # sorted(self._supervised); None: to be sorted again
        self._watched: set[int] = set()   # vehicles flying a velocity/acceleration in OFFBOARD
        self._watch_order: np.ndarray | None = None
        self._closed = False
        self._readout = FleetReadout(kin=self._kin, yaw_rad=self.ctrl.yaw_rad, airborne=self.airborne,
                                     gnss=self._gnss, crashed=self._crashed, crash_seen=self._crash_seen,
                                     est_init_s=p.est_init_s, battery=self.battery_frac)
        self.vehicles = [SimVehicle(self, i, (h[0], h[1], h[2]), ctrl=self.ctrl, params=p, limits=limits)
                         for i, h in enumerate(homes.tolist())]
        self._readout.vehicles = self.vehicles
        if self._kernel is not None:
            self._warm(self._kernel)

    def _init_state(self, homes: np.ndarray) -> None:
        """Truth, estimate and scratch arrays; every vehicle on the ground at its home."""
        n = len(homes)
        # state is axis-first (3, N); the public (N, 3) names are transposed views of it
        # estimate, velocity and truth are row blocks of one array: telemetry reads them in one call
        self._kin = np.zeros((9, n))
        self._est, self._vel, self._pos = self._kin[0:3], self._kin[3:6], self._kin[6:9]
        ned_xy(self._pos)[...] = ned_xy(homes.T)              # d = 0: on the ground
        self._est[...] = self._pos
        self.true_pos_ned_m, self.true_vel_ned_m_s, self.est_pos_ned_m = self._pos.T, self._vel.T, self._est.T
        self._pos_d, self._vel_d = self._pos[2], self._vel[2]
        self.airborne = np.zeros(n)                           # 1.0 flying, 0.0 on the ground
        self._free, self._free_kg = np.zeros(n), np.zeros(n)  # may move horizontally this tick (× mass)
        self._mass_kg, self._zeros, self._tmp = np.full(n, self.params.mass_kg), np.zeros(n), np.zeros(n)
        self._air_s = np.zeros(n)
        self._accel_scale, self._crashed = np.ones(n), np.zeros(n, dtype=bool)
        self._crash_seen, self._n_crashed = np.zeros(n, dtype=bool), 0

    # ---- fault inputs (assigning copies into the live arrays) ---------------------------------
    @property
    def gnss_offset_ned_m(self) -> np.ndarray:
        return self._gnss.offset_ned_m

    @gnss_offset_ned_m.setter
    def gnss_offset_ned_m(self, value: Any) -> None:
        self._gnss.offset_ned_m[...] = value

    @property
    def gnss_noise_scale(self) -> np.ndarray:
        return self._gnss.noise_scale

    @gnss_noise_scale.setter
    def gnss_noise_scale(self, value: Any) -> None:
        self._gnss.noise_scale[...] = value

    @property
    def gnss_available(self) -> np.ndarray:
        return self._gnss.available

    @gnss_available.setter
    def gnss_available(self, value: Any) -> None:
        self._gnss.available[...] = value

    @property
    def accel_scale(self) -> np.ndarray:
        return self._accel_scale

    @accel_scale.setter
    def accel_scale(self, value: Any) -> None:
        self._accel_scale[...] = value

    @property
    def crashed(self) -> np.ndarray:
        return self._crashed

    @crashed.setter
    def crashed(self, value: Any) -> None:
        self._crashed[...] = value

    @property
    def estimator_resets(self) -> np.ndarray:
        return self._gnss.resets

    # ---- Backend protocol ---------------------------------------------------------------------
    def step(self, dt_s: float) -> None:
        """Advance every vehicle by ``dt_s`` (normally ``tick_s``)."""
        if dt_s != self._dt_s:
            self._set_dt(dt_s)
        if np.count_nonzero(self._crashed) != self._n_crashed:
            self._apply_crashes()
        w, jit = self._world, self._kernel
        if jit is not None:
            self.ctrl.update_compiled(jit.fleet_update, self._est, self._vel, self._accel_scale, dt_s,
                                      self._vertical)
        else:
            self.ctrl.update(self._est, self._vel, self._accel_scale, dt_s)
            self._integrate_vertical()
            np.multiply(self._acc_xy, self._free_kg, w.cmd_force_xy)
            np.multiply(self._vel_xy, self._free, w.cmd_vel_xy)
            if self._jit_wanted and kernel.count_numpy_step():
                self._kernel, self._jit_wanted = _load_kernel(self.params.jit), False
        self._k += 1
        self._event_t_s = t_next = self._t0_s + self._k * dt_s   # no round-off creep over long runs
        w.step(dt_s, self._substeps)
        w.read(self._pos, self._vel)
        self.t_s = self._readout.t_s = t_next
        g = self._gnss
        if g.due(self.t_s):
            self._gnss_fix(jit)
        if jit is not None:   # with the battery fractions, which are otherwise computed on demand
            jit.after_step(*self._after_args(dt_s))
        else:
            np.add(self._pos, g.err_ned_m, self._est)
            np.multiply(self.airborne, self._vert_k[1], self._tmp)
            self._air_s += self._tmp
        if self._supervised:
            self._supervise()
        self._readout.step_done()
        self._battery_ok = jit is not None
        if self._watched:
            self._judge_held()

    def _after_args(self, dt_s: float) -> tuple:
        return (self._pos, self._gnss.err_ned_m, self._est, self.airborne, dt_s, self._air_s,
                self.params.battery_endurance_s, self._battery)

    def _damping(self, dt_s: float) -> float:
        """The velocity factor of linear drag over ``dt_s``, as pymunk's."""
        return math.exp(-self.params.drag_n_s_m / self.params.mass_kg * dt_s)

    def _vertical_args(self, dt_s: float) -> tuple:
        w = self._world
        return (self._pos_d, self._vel_d, self.airborne, self._free, self._free_kg, self._mass_kg,
                self._damping(dt_s), dt_s, w.cmd_force_xy, w.cmd_vel_xy)

    def _warm(self, jit: ModuleType) -> None:
        """Have numba load the kernel's code for this fleet's argument types now: it would otherwise do
        it on the first call, inside the tick loop (a quarter of a second; the first time ever, a compile)."""
        from numba import typeof

        c = self.ctrl
        update = c.kernel_args(c.tgt_pos_ned_m, self._est, self._vel, c.amax_d_m_s2) + \
            self._vertical_args(self.tick_s)
        for func, args in ((jit.fleet_update, update),
                           (jit.gnss_correct, self._gnss.kernel_args(self.t_s, self._pos)),
                           (jit.after_step, self._after_args(self.tick_s))):
            func.compile(tuple(map(typeof, args)))

    def drain_events(self) -> list[VehicleEvent]:
        out, self._events = self._events, []
        return out

    def close(self) -> None:
        self._closed = True
        self._dt_s = -1.0

    # ---- dynamics -----------------------------------------------------------------------------
    def _set_dt(self, dt_s: float) -> None:
        """Cache the vertical-update coefficients and the substep count for ``dt_s``."""
        if self._closed:
            raise RuntimeError("SimBackend.step() after close()")
        if not (dt_s > 0 and math.isfinite(dt_s)):
            raise ValueError(f"dt_s must be finite and > 0, got {dt_s!r}")
        self._dt_s, self._t0_s, self._k = dt_s, self.t_s, 0
        self._vert_k = (np.array(self._damping(dt_s)), np.array(dt_s))   # 0-d arrays: cheaper operands
        self._vertical = self._vertical_args(dt_s)           # the compiled kernel's
        # two drones closing at twice the speed limit must not pass through each other in one step
        need = math.ceil(dt_s * self.params.mpc_xy_vel_max_m_s / self.params.radius_m - 1e-9)
        self._substeps = max(self.params.physics_substeps, need)

    def _integrate_vertical(self) -> None:
        """Altitude: semi-implicit Euler with the same linear drag as pymunk's damping; ground."""
        damping, dt = self._vert_k
        pos_d, vel_d, acc_d, tmp = self._pos_d, self._vel_d, self._acc_d, self._tmp
        # on the ground with thrust at or below hover, a vehicle stays put (horizontally too)
        np.less(acc_d, self._zeros, self._free)
        np.maximum(self._free, self.airborne, out=self._free)
        np.multiply(self._free, self._mass_kg, self._free_kg)
        vel_d *= damping
        np.multiply(acc_d, dt, tmp)
        vel_d += tmp
        np.multiply(vel_d, dt, tmp)
        pos_d += tmp
        np.minimum(pos_d, self._zeros, out=pos_d)
        np.less(pos_d, self._zeros, self.airborne)
        vel_d *= self.airborne

    def _apply_crashes(self) -> None:
        new = np.flatnonzero(self._crashed & ~self._crash_seen).tolist()
        self._crash_seen |= self._crashed
        self._n_crashed = int(np.count_nonzero(self._crashed))
        for i in new:
            v = self.vehicles[i]
            if v.frozen is None:
                v.crash(v.telemetry())
                self.emit(i, "fault", "crash", {"alt_m": -float(self._pos_d[i])})

    def on_ground(self, i: int) -> bool:
        """Whether vehicle ``i`` is resting on the ground."""
        return bool(self.airborne[i] == 0.0)

    def _gnss_fix(self, jit: ModuleType | None) -> None:
        self._readout.n_fixes += 1
        for i, count, jump_m in self._gnss.fix(self.t_s, self._pos, jit):
            self.emit(i, "estimator", "position_reset", {"count": count, "jump_m": jump_m})

    def _supervise(self) -> None:
        order = self._supervise_order
        if order is None:
            order = self._supervise_order = sorted(self._supervised)
        for i in self.supervise_many(order) if self.batch_supervise else self._supervise_each(order):
            self._supervised.discard(i)
            self._supervise_order = None

    def _judge_held(self) -> None:
        """Held velocities and accelerations near the envelope are judged again (one array test for all)."""
        order = self._watch_order
        if order is None:
            order = self._watch_order = np.array(sorted(self._watched), dtype=np.intp)
        lim, est = self.limits, self._est[:, order]   # (3, n): north, east, down rows
        reach = reach_m(lim)
        near = (lim.geofence_radius_m - np.hypot(est[0], est[1]) <= reach) | (lim.max_alt_m + est[2] <= reach)
        if near.any():
            for i in order[near].tolist():
                self.vehicles[i].judge_held()

    # ---- services for SimVehicle (the SimFleet protocol) ------------------------------------------
    def watch(self, i: int, on: bool) -> None:
        """Judge vehicle ``i``'s held velocity or acceleration near the envelope at every step, or not."""
        if on:
            self._watched.add(i)
        else:
            self._watched.discard(i)
        self._watch_order = None

    def supervise(self, i: int) -> None:
        """Have the supervisor watch vehicle ``i`` from the next step on."""
        if i not in self._supervised:
            self._supervised.add(i)
            self._supervise_order = None

    def emit(self, i: int, kind: str, name: str, data: dict[str, Any]) -> None:
        self._events.append(VehicleEvent(self._event_t_s, i, kind, name, data))

    def _emit_collision(self, i: int, name: str, data: dict[str, Any]) -> None:
        self.emit(i, "collision", name, data)

    def arm_blocker(self, i: int) -> str:
        """Why vehicle ``i`` cannot arm now ("" if it can)."""
        if not self._gnss.ready(self.t_s)[i]:
            return "no GNSS fix yet" if self._gnss.seq[i] == 0 else "estimator initialising"
        return ""

    def estimate_ned(self, i: int) -> tuple[float, float, float]:
        """Vehicle ``i``'s estimated position (n, e, d)."""
        return self._readout.estimate_ned(i)

    def speed_m_s(self, i: int) -> float:
        """Vehicle ``i``'s true 3-D speed."""
        n, e, d = self._vel[:, i].tolist()
        return math.sqrt(n * n + e * e + d * d)

    def battery_frac(self) -> np.ndarray:
        """Every vehicle's battery fraction now (computed once per step; do not modify)."""
        if not self._battery_ok:
            b = self._battery
            np.divide(self._air_s, self.params.battery_endurance_s, b)
            np.subtract(1.0, b, b)
            np.maximum(b, 0.0, out=b)   # = np.clip(b, 0, 1): the time in the air is >= 0, so b <= 1
            self._battery_ok = True
        return self._battery

    # ---- what the fleet reports (swarmbox.hal.sim.readout) ------------------------------------------
    def telemetry_of(self, i: int) -> Telemetry:
        """Vehicle ``i``'s telemetry (the whole fleet's is built once per step, on first demand)."""
        return self._readout.telemetry_of(i)

    def state_columns(self, index: np.ndarray | None = None) -> list[np.ndarray]:
        """The numeric columns of the ``state`` log rows of vehicles ``index`` (None: all, in order),
        as telemetry reports them now: estimated position and velocity, latest GNSS fix (NaN before
        the first), true position (each n, e, d), yaw, battery fraction, landed. Copies (see
        :meth:`state_into`)."""
        n = self.n if index is None else len(index)
        values, landed = np.empty((14, n)), np.empty(n, dtype=bool)
        self.state_into(values, landed, index)
        return [*values, landed]

    def state_into(self, values: np.ndarray, landed: np.ndarray, index: np.ndarray | None = None) -> None:
        """The ``state`` columns written into the recorder's buffers (:meth:`FleetReadout.state_into`)."""
        self._readout.state_into(values, landed, index)
