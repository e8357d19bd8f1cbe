"""A PX4-like cascaded multicopter controller, vectorized over a fleet.

position P → velocity setpoint (saturated horizontally and vertically) → velocity PID with PX4's
anti-reset windup → acceleration setpoint (saturated by the acceleration and tilt limits). Where it
may differ from PX4 (``conf/backend/sim.yaml`` vs ``sim_px4.yaml``, docs/fidelity.md):

- ``vel_drag_ff``: the default feeds the airframe's linear drag forward at the velocity setpoint, so
  the vehicle settles on a saturated velocity setpoint without overshooting the speed limits; PX4
  (0) leaves drag to the velocity integrator, so on a moving setpoint the vehicle trails by the
  position loop's 1/MPC_XY_P plus what drag costs while the integrator catches up (the RQ2 lag);
- ``mc_roll_p``: PX4's tilt follows its setpoint with time constant 1/MC_ROLL_P (0: at once);
- ``acc_hor_max_offboard``: PX4 limits offboard setpoints by the tilt only, MPC_ACC_HOR_MAX acts in
  its automatic modes;
- ``offboard_delay_s``: an offboard position setpoint reaches PX4's position controller late (a
  SwarmBox tick, the MAVLink hop, PX4's offboard and estimator output rates); the automatic modes
  run on the vehicle and are not delayed.

Every kind
of target is one column of the same arrays, so one :meth:`CascadedController.update` serves the whole
fleet with no per-drone Python:

- a position target has position gains ``kp`` and no feed-forward;
- a velocity target has ``kp = 0`` and the velocity as feed-forward (it bypasses the position loop);
- an acceleration target has zero velocity-loop gains and the acceleration as feed-forward (it
  bypasses both loops);
- "thrust off" (disarmed, crashed) feeds gravity forward with the loops off: the vehicle falls.

Accelerations are *commanded* accelerations relative to hover (NED, down positive): the vehicle
compensates gravity itself, so 0 means "hover".

Layout: every array is axis-first, ``(3, N)`` (rows n, e, d) or ``(N,)``, so each row is contiguous
and the hot loop is made of same-shape ufunc calls (broadcasting costs more than the arithmetic at
fleet sizes of a few drones). Ufuncs get their output array positionally (``np.add(a, b, out)``): the
``out=`` keyword costs a fifth of a five-element call (numpy 2); only ``maximum`` and ``minimum``
take it by keyword.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence

import numpy as np

from swarmbox.hal.sim.params import GRAVITY_M_S2, SimParams


class CascadedController:
    """Targets, integrators and limits of N vehicles; :meth:`update` computes their accelerations.

    Per-drone columns are written by the ``set_*`` methods (on commands, not every tick).
    """

    def __init__(self, n: int, p: SimParams) -> None:
        self.p = p
        col = lambda *v: np.array(v, dtype=float)[:, None] * np.ones(n)  # noqa: E731  (3, N) constant
        self._kp_pos = np.array([p.mpc_xy_p, p.mpc_xy_p, p.mpc_z_p])
        self._kp_vel = col(p.mpc_xy_vel_p_acc, p.mpc_xy_vel_p_acc, p.mpc_z_vel_p_acc)
        self._ki_vel = col(p.mpc_xy_vel_i_acc, p.mpc_xy_vel_i_acc, p.mpc_z_vel_i_acc)
        self._kd_vel = col(p.mpc_xy_vel_d_acc, p.mpc_xy_vel_d_acc, p.mpc_z_vel_d_acc)
        self._arw_gain = 2.0 / np.maximum(self._kp_vel, 1e-6)   # PX4: 2 / kP, horizontal only
        self._arw_gain[2] = 0.0
        self._ah_max = np.full(n, p.acc_hor_limit_m_s2)
        self._neg_up_max = np.full(n, -p.mpc_acc_up_max_m_s2)
        self._tiny = np.full(n, 1e-9)
        z3 = lambda: np.zeros((3, n))  # noqa: E731
        self.tgt_pos_ned_m, self.vel_ff_ned_m_s, self.acc_ff_ned_m_s2 = z3(), z3(), z3()
        self.kp, self.loop_on = z3(), np.zeros(n)       # position gains; velocity loop on (1) / off (0)
        self.vmax_h_m_s = np.full(n, p.mpc_xy_vel_max_m_s)
        self.vmin_d_m_s = np.full(n, -p.mpc_z_vel_max_up_m_s)   # most negative vertical velocity (up)
        self.vmax_d_m_s = np.full(n, p.mpc_z_vel_max_dn_m_s)
        # takeoff ramp: climb-rate limit on top of vmin_d (inf: none; negative: a descent rate is forced,
        # zero thrust on the ground)
        self.tko_up_m_s = np.full(n, np.inf)
        self.ramping = False                    # any column with a finite takeoff-ramp limit
        self._ramp_ids: set[int] = set()        # ... which ones (set per drone and tick: no array scan)
        self.amax_d_m_s2 = np.full(n, p.mpc_acc_down_max_m_s2)  # gravity for thrust-off columns
        self.integ_m_s2, self._prev_vel = z3(), z3()
        self.yaw_rad, self.yaw_tgt_rad = np.zeros(n), np.zeros(n)
        self._yaw_busy = False
        self._yaw_err = np.zeros_like(self.yaw_rad)
        self._yaw_step = (np.zeros(()), np.zeros(()))   # (step, -step) per tick, set with the gains
        self._yaw_step_f = 0.0
        self.acc_ned_m_s2 = z3()
        self._att_acc = np.zeros((2, n))   # horizontal acceleration the attitude has reached so far
        self._att_alpha = 1.0
        self._vsp, self._tmp, self._h, self._lim_h, self._lim_up = z3(), z3(), *(np.zeros(n) for _ in "abc")
        self._limits_key: bytes | None = None   # accel_scale the limits were computed for
        self._dt_s = -1.0
        self._offboard = np.zeros(n, dtype=bool)   # columns whose position target comes over the link
        self._tgt_hist: np.ndarray | None = None   # ring of past targets (offboard_delay_s > 0 only)
        self._hist_k = 0
        self._kp_v, self._ki_dt_v, self._kd_dt_v = z3(), z3(), z3()   # gains × loop_on (× dt terms)
        self._drag_v = z3()                                           # ff × drag / mass × loop_on
        # row views, made once: slicing costs as much as a small ufunc
        self._vsp_rows, self._acc_rows = tuple(self._vsp), tuple(self.acc_ned_m_s2)
        self.set_thrust_off(slice(None))

    # ---- per-drone commands -------------------------------------------------------------------
    def set_position(self, i: int, pos_ned_m: Sequence[float], vmax_h_m_s: float | None = None,
                     vmax_up_m_s: float | None = None, hold_d: bool = True) -> None:
        """Fly to ``pos_ned_m``; ``hold_d`` False leaves the vertical axis to the feed-forward."""
        p = self.p
        self.tgt_pos_ned_m[:, i] = pos_ned_m
        self.kp[:, i] = self._kp_pos if hold_d else (p.mpc_xy_p, p.mpc_xy_p, 0.0)
        self.vel_ff_ned_m_s[:, i] = 0.0
        self._loop(i, True)
        self.vmax_h_m_s[i] = p.mpc_xy_vel_max_m_s if vmax_h_m_s is None else vmax_h_m_s
        self.vmin_d_m_s[i] = -(p.mpc_z_vel_max_up_m_s if vmax_up_m_s is None else vmax_up_m_s)
        self.vmax_d_m_s[i] = p.mpc_z_vel_max_dn_m_s

    def set_descent(self, i: int, n_m: float, e_m: float, speed_m_s: float) -> None:
        """Hold (n, e) and sink at ``speed_m_s`` (LAND)."""
        self.set_position(i, (n_m, e_m, 0.0), hold_d=False)
        self.vel_ff_ned_m_s[:, i] = (0.0, 0.0, speed_m_s)

    def set_velocity(self, i: int, vel_ned_m_s: Sequence[float]) -> None:
        """Follow a velocity (feed-forward, position loop bypassed)."""
        self.set_position(i, (0.0, 0.0, 0.0))
        self.kp[:, i] = 0.0
        self.vel_ff_ned_m_s[:, i] = vel_ned_m_s

    def set_acceleration(self, i: int, acc_ned_m_s2: Sequence[float]) -> None:
        """Command an acceleration directly (both loops bypassed)."""
        self.kp[:, i] = 0.0
        self.vel_ff_ned_m_s[:, i] = 0.0
        self._loop(i, False)
        self.acc_ff_ned_m_s2[:, i] = acc_ned_m_s2

    def set_thrust_off(self, i: int | slice) -> None:
        """Motors off: no control, the vehicle falls (or rests on the ground)."""
        self.kp[:, i] = 0.0
        self.vel_ff_ned_m_s[:, i] = 0.0
        self._loop(i, False)
        self.acc_ff_ned_m_s2[2, i] = GRAVITY_M_S2
        self.amax_d_m_s2[i] = GRAVITY_M_S2

    def set_offboard_limits(self, i: int, offboard: bool) -> None:
        """Horizontal acceleration limit: the tilt limit alone on offboard setpoints (PX4's
        PositionControl), MPC_ACC_HOR_MAX as well in the automatic modes."""
        tilt_only = offboard and not self.p.acc_hor_max_offboard
        self._offboard[i] = offboard
        self._ah_max[i] = self.p.acc_tilt_limit_m_s2 if tilt_only else self.p.acc_hor_limit_m_s2
        self._limits_key = None

    def set_takeoff_ramp(self, i: int, up_m_s: float) -> None:
        """Limit drone ``i``'s climb rate to ``up_m_s`` (the takeoff ramp); ``inf`` lifts the limit."""
        self.tko_up_m_s[i] = up_m_s
        if math.isfinite(up_m_s):
            self._ramp_ids.add(i)
        else:
            self._ramp_ids.discard(i)
        self.ramping = bool(self._ramp_ids)

    def set_takeoff_ramps(self, ids: list[int], up_m_s: np.ndarray) -> None:
        """``set_takeoff_ramp(i, up)`` for every ``i`` of ``ids`` and ``up`` of ``up_m_s``."""
        self.tko_up_m_s[ids] = up_m_s
        finite = np.isfinite(up_m_s).tolist()
        self._ramp_ids.update(i for i, f in zip(ids, finite, strict=True) if f)
        self._ramp_ids.difference_update(i for i, f in zip(ids, finite, strict=True) if not f)
        self.ramping = bool(self._ramp_ids)

    def reset_integrator(self, i: int) -> None:
        self.integ_m_s2[:, i] = 0.0

    def set_yaw_target(self, i: int, yaw_rad: float | None) -> None:
        """Turn toward ``yaw_rad`` at the yaw-rate limit; None keeps the current heading."""
        tgt = self.yaw_rad[i] if yaw_rad is None else yaw_rad
        self.yaw_tgt_rad[i] = tgt
        if tgt != self.yaw_rad[i]:
            self._yaw_busy = True

    def _loop(self, i: int | slice, on: bool) -> None:
        self.loop_on[i] = 1.0 if on else 0.0
        self.acc_ff_ned_m_s2[:, i] = 0.0
        self.amax_d_m_s2[i] = self.p.mpc_acc_down_max_m_s2
        if not on:
            self.integ_m_s2[:, i] = 0.0
        self._dt_s = -1.0   # refresh the per-column gains on the next update

    # ---- the fleet-wide update ----------------------------------------------------------------
    def _refresh_gains(self, dt_s: float) -> None:
        self._dt_s = dt_s
        # attitude loop: the tilt (so the horizontal acceleration) follows its setpoint with time
        # constant 1/MC_ROLL_P (PX4's attitude P gain; the rate loop is much faster)
        rate = self.p.mc_roll_p
        self._att_alpha = 1.0 if rate <= 0 else -math.expm1(-dt_s * rate)
        step = math.radians(self.p.mpc_yawrauto_max_deg_s) * dt_s   # yaw-rate limit per tick
        self._yaw_step, self._yaw_step_f = (np.array(step), np.array(-step)), step
        delay_ticks = round(self.p.offboard_delay_s / dt_s)
        if delay_ticks and (self._tgt_hist is None or len(self._tgt_hist) != delay_ticks):
            self._tgt_hist = np.repeat(self.tgt_pos_ned_m[None], delay_ticks, axis=0)
            self._hist_k = 0
        np.multiply(self._kp_vel, self.loop_on, out=self._kp_v)
        np.multiply(self.p.vel_drag_ff * self.p.drag_n_s_m / self.p.mass_kg, self.loop_on, out=self._drag_v)
        np.multiply(self._ki_vel * dt_s, self.loop_on, out=self._ki_dt_v)
        np.multiply(self._kd_vel / dt_s, self.loop_on, out=self._kd_dt_v)

    def update(self, pos_ned_m: np.ndarray, vel_ned_m_s: np.ndarray, accel_scale: np.ndarray,
               dt_s: float) -> np.ndarray:
        """Acceleration setpoints (3, N) for the estimated states (3, N); the array is reused.

        ``accel_scale`` (N,) multiplies the horizontal and upward acceleration limits (motor loss).
        """
        if dt_s != self._dt_s:
            self._refresh_gains(dt_s)
        self._velocity_setpoint(pos_ned_m)
        self._velocity_pid(vel_ned_m_s)
        self._limit_and_integrate(accel_scale)
        self._attitude_lag()
        if self._yaw_busy:
            self._turn()
        return self.acc_ned_m_s2

    def _velocity_setpoint(self, pos_ned_m: np.ndarray) -> None:
        """Position P + velocity feed-forward, saturated horizontally and vertically, into _vsp."""
        vsp, tmp = self._vsp, self._tmp
        vn, ve, vd = self._vsp_rows
        np.subtract(self._delayed_target() if self._tgt_hist is not None else self.tgt_pos_ned_m,
                    pos_ned_m, tmp)
        np.multiply(tmp, self.kp, vsp)
        vsp += self.vel_ff_ned_m_s
        _saturate_h(vn, ve, self.vmax_h_m_s, self._h)
        np.maximum(vd, self.vmin_d_m_s, out=vd)
        np.minimum(vd, self.vmax_d_m_s, out=vd)
        if self.ramping:   # last, as PX4's constrain(vz, -up, down): a negative ramp limit forces descent
            np.maximum(vd, -self.tko_up_m_s, out=vd)

    def _delayed_target(self) -> np.ndarray:
        """Position targets with the offboard columns as they were offboard_delay_s ago (a ring of
        per-tick snapshots; a column that is not offboard uses its current target)."""
        hist, k = self._tgt_hist, self._hist_k
        old = hist[k].copy()
        np.copyto(hist[k], self.tgt_pos_ned_m)
        self._hist_k = (k + 1) % len(hist)
        return np.where(self._offboard, old, self.tgt_pos_ned_m)

    def _velocity_pid(self, vel_ned_m_s: np.ndarray) -> None:
        """Drag feed-forward + velocity PID (derivative on the measurement, as PX4) into acc.

        Leaves the velocity error in _vsp and the unsaturated acceleration in _tmp.
        """
        vsp, tmp, acc = self._vsp, self._tmp, self.acc_ned_m_s2
        np.multiply(vsp, self._drag_v, acc)
        np.subtract(vsp, vel_ned_m_s, vsp)
        np.multiply(vsp, self._kp_v, tmp)
        acc += tmp
        acc += self.integ_m_s2
        np.subtract(vel_ned_m_s, self._prev_vel, tmp)
        tmp *= self._kd_dt_v
        acc -= tmp
        np.copyto(self._prev_vel, vel_ned_m_s)
        acc += self.acc_ff_ned_m_s2
        np.copyto(tmp, acc)

    def _limit_and_integrate(self, accel_scale: np.ndarray) -> None:
        """Acceleration and tilt limits (scaled by motor health), then the integrator update.

        PX4's anti-reset windup: horizontally, the integrated error loses what the saturation cut
        (times 2/kP); vertically, integration stops while the acceleration is saturated.
        """
        vsp, tmp, acc, h = self._vsp, self._tmp, self.acc_ned_m_s2, self._h
        an, ae, ad = self._acc_rows
        self._refresh_limits(accel_scale)
        _saturate_h(an, ae, self._lim_h, h)
        np.maximum(ad, self._lim_up, out=ad)
        np.minimum(ad, self._ramp_down_limit() if self.ramping else self.amax_d_m_s2, out=ad)
        np.equal(tmp[2], ad, h)
        tmp -= acc
        tmp *= self._arw_gain
        vsp -= tmp
        np.multiply(self._vsp_rows[2], h, self._vsp_rows[2])
        vsp *= self._ki_dt_v
        self.integ_m_s2 += vsp

    def _refresh_limits(self, accel_scale: np.ndarray) -> None:
        scale_key = accel_scale.tobytes()   # the limits change only with the motor health (or the mode)
        if scale_key != self._limits_key:
            np.multiply(accel_scale, self._ah_max, out=self._lim_h)
            np.maximum(self._lim_h, self._tiny, out=self._lim_h)
            np.multiply(accel_scale, self._neg_up_max, out=self._lim_up)
            self._limits_key = scale_key

    def update_compiled(self, kernel: Callable[..., bool], pos_ned_m: np.ndarray, vel_ned_m_s: np.ndarray,
                        accel_scale: np.ndarray, dt_s: float, vertical: tuple) -> None:
        """:meth:`update`, then the backend's vertical integration (``vertical``: the trailing
        arguments of ``fleet_jit.fleet_update``), in one call of the compiled ``kernel``
        (:mod:`swarmbox.hal.sim.kernel`); the same results, bit for bit."""
        if dt_s != self._dt_s:
            self._refresh_gains(dt_s)
        self._refresh_limits(accel_scale)
        tgt = self._delayed_target() if self._tgt_hist is not None else self.tgt_pos_ned_m
        amax_d = self._ramp_down_limit() if self.ramping else self.amax_d_m_s2
        self._yaw_busy = kernel(*self.kernel_args(tgt, pos_ned_m, vel_ned_m_s, amax_d), *vertical)

    def kernel_args(self, tgt: np.ndarray, pos_ned_m: np.ndarray, vel_ned_m_s: np.ndarray,
                    amax_d: np.ndarray) -> tuple:
        """The controller's arguments of ``fleet_jit.fleet_update`` (no side effect)."""
        return (tgt, pos_ned_m, vel_ned_m_s, self.kp, self.vel_ff_ned_m_s, self.acc_ff_ned_m_s2,
                self.vmax_h_m_s, self.vmin_d_m_s, self.vmax_d_m_s, self.tko_up_m_s, amax_d, self.ramping,
                self._drag_v, self._kp_v, self._kd_dt_v, self._ki_dt_v, self._arw_gain, self._lim_h,
                self._lim_up, self.integ_m_s2, self._prev_vel, self.acc_ned_m_s2, self._att_acc,
                self._att_alpha, self.yaw_rad, self.yaw_tgt_rad, self._yaw_step_f, self._yaw_busy)

    def _ramp_down_limit(self) -> np.ndarray:
        """Downward acceleration limits with the ramping columns at g: PX4 bounds the thrust, not the
        acceleration, and from zero until the vehicle flies, so its takeoff ramp starts at zero thrust
        and the vertical integrator winds down while the vehicle still sits on the ground."""
        return np.where(np.isfinite(self.tko_up_m_s), GRAVITY_M_S2, self.amax_d_m_s2)

    def _attitude_lag(self) -> None:
        """The horizontal rows of acc become the first-order lagged tilt (controller state is untouched)."""
        if self._att_alpha >= 1.0:
            return
        att, acc_h = self._att_acc, self.acc_ned_m_s2[:2]
        acc_h -= att
        acc_h *= self._att_alpha
        att += acc_h
        np.copyto(acc_h, att)

    def _turn(self) -> None:
        """Every heading one yaw-rate step toward its target, wrapped to [-pi, pi) (in place: the same
        arithmetic as ``clip`` and ``(x + pi) % 2pi - pi``, in fewer numpy calls)."""
        yaw, err = self.yaw_rad, self._yaw_err
        np.subtract(self.yaw_tgt_rad, yaw, err)
        _wrap(err)
        step, neg_step = self._yaw_step
        np.maximum(err, neg_step, out=err)
        np.minimum(err, step, out=err)
        yaw += err
        _wrap(yaw)
        # busy while some heading is a whole step (or more) away: the largest |error| decides (a small
        # fleet's errors as a list: two builtin reductions cost a quarter of numpy's abs + reduce)
        if len(err) <= _LIST_UP_TO:
            errs, step_f = err.tolist(), self._yaw_step_f
            self._yaw_busy = max(errs) >= step_f or -min(errs) >= step_f
        else:
            self._yaw_busy = bool(np.maximum.reduce(np.abs(err, out=err)) >= step)


_PI, _TWO_PI = np.array(math.pi), np.array(2 * math.pi)   # 0-d arrays: cheaper ufunc operands than floats
_LIST_UP_TO = 32   # fleets up to this size reduce small arrays as Python lists


def _wrap(angle_rad: np.ndarray) -> None:
    """Wrap angles to [-pi, pi), in place."""
    angle_rad += _PI
    angle_rad %= _TWO_PI
    angle_rad -= _PI


def _saturate_h(x_n: np.ndarray, x_e: np.ndarray, vmax: np.ndarray, h: np.ndarray) -> None:
    """Scale the horizontal vectors (x_n, x_e) (N,) to a norm of at most ``vmax`` (> 0), in place."""
    np.hypot(x_n, x_e, h)
    np.maximum(h, vmax, out=h)   # (maximum and minimum take their output by keyword only)
    np.divide(vmax, h, h)
    x_n *= h
    x_e *= h
