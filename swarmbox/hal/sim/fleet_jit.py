"""The compiled half of :mod:`swarmbox.hal.sim.kernel` (imports numba: load it through
``kernel.compiled()``, never at start-up)."""

from __future__ import annotations

import math

import numpy as np
from numba import njit
from numba.extending import register_jitable

_PI, _TWO_PI = math.pi, 2 * math.pi


@njit(cache=True, error_model="numpy")
def fleet_update(tgt: np.ndarray, pos: np.ndarray, vel: np.ndarray, kp: np.ndarray, vel_ff: np.ndarray,
                 acc_ff: np.ndarray, vmax_h: np.ndarray, vmin_d: np.ndarray, vmax_d: np.ndarray,
                 tko_up: np.ndarray, amax_d: np.ndarray, ramping: bool,
                 drag_v: np.ndarray, kp_v: np.ndarray, kd_dt_v: np.ndarray, ki_dt_v: np.ndarray,
                 arw: np.ndarray, lim_h: np.ndarray, lim_up: np.ndarray,
                 integ: np.ndarray, prev_vel: np.ndarray, acc: np.ndarray, att: np.ndarray, att_alpha: float,
                 yaw: np.ndarray, yaw_tgt: np.ndarray, yaw_step: float, turning: bool,
                 true_d: np.ndarray, vel_d: np.ndarray, airborne: np.ndarray, free: np.ndarray,
                 free_kg: np.ndarray, mass: np.ndarray, damping: float, dt: float,
                 force_xy: np.ndarray, vel_cmd_xy: np.ndarray) -> bool:
    """``CascadedController.update`` then ``SimBackend._integrate_vertical`` and the horizontal
    commands, for every drone; returns whether some heading is still turning.

    Arrays are the controller's and the backend's own (axis-first), updated in place: ``acc``,
    ``integ``, ``prev_vel``, ``att``, ``yaw``; ``true_d``, ``vel_d``, ``airborne``, ``free``,
    ``free_kg``; ``force_xy``, ``vel_cmd_xy``. ``vel_d`` is ``vel[2]`` (read by the controller first).
    ``amax_d`` is the downward limit already lowered for ramping columns.
    """
    busy = False
    for i in range(pos.shape[1]):
        # position P + velocity feed-forward, saturated (_velocity_setpoint)
        sn = (tgt[0, i] - pos[0, i]) * kp[0, i] + vel_ff[0, i]
        se = (tgt[1, i] - pos[1, i]) * kp[1, i] + vel_ff[1, i]
        sd = (tgt[2, i] - pos[2, i]) * kp[2, i] + vel_ff[2, i]
        sn, se = _saturate_h(sn, se, vmax_h[i])
        sd = _max(sd, vmin_d[i])
        sd = _min(sd, vmax_d[i])
        if ramping:
            sd = _max(sd, -tko_up[i])
        # drag feed-forward + velocity PID (_velocity_pid); e* the velocity errors, u* the unsaturated
        vn, ve, vd = vel[0, i], vel[1, i], vel[2, i]
        en, ee, ed = sn - vn, se - ve, sd - vd
        un = (sn * drag_v[0, i] + en * kp_v[0, i] + integ[0, i] - (vn - prev_vel[0, i]) * kd_dt_v[0, i]
              + acc_ff[0, i])
        ue = (se * drag_v[1, i] + ee * kp_v[1, i] + integ[1, i] - (ve - prev_vel[1, i]) * kd_dt_v[1, i]
              + acc_ff[1, i])
        ud = (sd * drag_v[2, i] + ed * kp_v[2, i] + integ[2, i] - (vd - prev_vel[2, i]) * kd_dt_v[2, i]
              + acc_ff[2, i])
        prev_vel[0, i], prev_vel[1, i], prev_vel[2, i] = vn, ve, vd
        # limits and anti-reset windup, integrator (_limit_and_integrate)
        an, ae = _saturate_h(un, ue, lim_h[i])
        ad = _max(ud, lim_up[i])
        ad = _min(ad, amax_d[i])
        en = en - (un - an) * arw[0, i]
        ee = ee - (ue - ae) * arw[1, i]
        ed = (ed - (ud - ad) * arw[2, i]) * (1.0 if ud == ad else 0.0)
        integ[0, i] += en * ki_dt_v[0, i]
        integ[1, i] += ee * ki_dt_v[1, i]
        integ[2, i] += ed * ki_dt_v[2, i]
        if att_alpha < 1.0:   # _attitude_lag
            att[0, i] += (an - att[0, i]) * att_alpha
            att[1, i] += (ae - att[1, i]) * att_alpha
            an, ae = att[0, i], att[1, i]
        acc[0, i], acc[1, i], acc[2, i] = an, ae, ad
        if turning:           # _turn
            err = _wrap(yaw_tgt[i] - yaw[i])
            err = _min(_max(err, -yaw_step), yaw_step)
            yaw[i] = _wrap(yaw[i] + err)
            busy = busy or err >= yaw_step or -err >= yaw_step
        # altitude (SimBackend._integrate_vertical) and the horizontal commands
        f = _max(1.0 if ad < 0.0 else 0.0, airborne[i])
        free[i], free_kg[i] = f, f * mass[i]
        v = vel_d[i] * damping + ad * dt
        d = _min(true_d[i] + v * dt, 0.0)
        air = 1.0 if d < 0.0 else 0.0
        true_d[i], vel_d[i], airborne[i] = d, v * air, air
        force_xy[0, i], force_xy[1, i] = an * free_kg[i], ae * free_kg[i]
        vel_cmd_xy[0, i], vel_cmd_xy[1, i] = vn * f, ve * f
    return busy


@register_jitable
def _max(a: float, b: float) -> float:
    """``np.maximum`` of two floats (NaN wins)."""
    return a if a >= b or a != a else b


@register_jitable
def _min(a: float, b: float) -> float:
    """``np.minimum`` of two floats (NaN wins)."""
    return a if a <= b or a != a else b


@register_jitable
def _saturate_h(x_n: float, x_e: float, vmax: float) -> tuple[float, float]:
    h = vmax / _max(math.hypot(x_n, x_e), vmax)
    return x_n * h, x_e * h


@register_jitable
def _wrap(angle_rad: float) -> float:
    """To [-pi, pi), as ``control._wrap``."""
    return (angle_rad + _PI) % _TWO_PI - _PI


@njit(cache=True, error_model="numpy")
def gnss_correct(noise: np.ndarray, sigma: np.ndarray, noise_scale: np.ndarray, offset: np.ndarray,
                 err: np.ndarray, innov: np.ndarray, gate: float, gain: float, available: np.ndarray,
                 ok: np.ndarray, last_accept_s: np.ndarray, t_s: float, true_pos: np.ndarray,
                 fix_ned: np.ndarray, seq: np.ndarray) -> int:
    """``GnssEstimator.fix`` after the noise draw (``noise`` holds standard normals): scale and offset
    the noise, gate and apply the corrections, record the fixes; ``ok`` gets the accepted receivers.
    Returns how many available receivers were rejected."""
    rejected = 0
    for i in range(err.shape[1]):
        for a in range(3):
            noise[a, i] = noise[a, i] * sigma[a, 0] * noise_scale[i] + offset[i, a]
            innov[a, i] = noise[a, i] - err[a, i]
        good = available[i] and math.hypot(innov[0, i], innov[1, i]) <= gate
        ok[i] = good
        k = gain * (1.0 if good else 0.0)
        for a in range(3):
            err[a, i] += innov[a, i] * k
        if good:
            last_accept_s[i] = t_s
        if available[i]:
            for a in range(3):
                fix_ned[a, i] = true_pos[a, i] + noise[a, i]
            seq[i] += 1
            if not good:
                rejected += 1
    return rejected


@njit(cache=True, error_model="numpy")
def after_step(pos: np.ndarray, err: np.ndarray, est: np.ndarray, airborne: np.ndarray, dt: float,
               air_s: np.ndarray, endurance_s: float, battery: np.ndarray) -> None:
    """The end of ``SimBackend.step``: estimates, airborne time and battery fractions."""
    for i in range(est.shape[1]):
        for a in range(3):
            est[a, i] = pos[a, i] + err[a, i]
        air_s[i] += airborne[i] * dt
        battery[i] = _max(1.0 - air_s[i] / endurance_s, 0.0)
