"""Tunables of the ``sim`` backend: one frozen dataclass, mirrored key for key by ``conf/backend/sim.yaml``.

Controller names and defaults follow PX4's multicopter parameters (``MPC_*``, ``RTL_*``, ``COM_*``)
so a value can be checked against a PX4 parameter dump.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, fields
from typing import Any

GRAVITY_M_S2 = 9.80665
JIT_CHOICES = ("auto", "always", "never")


@dataclass(frozen=True, slots=True)
class SimParams:
    """Every tunable of :class:`swarmbox.hal.sim.backend.SimBackend`, with its unit in the name."""

    # airframe (x500-like; backend=sim_px4: PX4's SIH quadrotor, SIH_MASS and SIH_KDV)
    mass_kg: float = 1.5
    radius_m: float = 0.3                 # collision radius
    drag_n_s_m: float = 0.3               # linear drag: force = -drag * velocity
    elasticity: float = 0.3               # restitution of drone shapes (pymunk multiplies both shapes')
    friction: float = 0.5
    vertical_separation_m: float = 1.0    # contacts are ignored above this altitude gap
    physics_substeps: int = 1             # pymunk steps per tick (raised automatically against tunnelling)
    # position / velocity control (PX4 MPC_*)
    mpc_xy_p: float = 0.95                # 1/s
    mpc_z_p: float = 1.0                  # 1/s
    mpc_xy_vel_p_acc: float = 1.8         # (m/s^2)/(m/s)
    mpc_xy_vel_i_acc: float = 0.4         # (m/s^2)/m
    mpc_xy_vel_d_acc: float = 0.2         # (m/s^2)/(m/s^2)
    mpc_z_vel_p_acc: float = 4.0          # (m/s^2)/(m/s)
    mpc_z_vel_i_acc: float = 2.0          # (m/s^2)/m
    mpc_z_vel_d_acc: float = 0.0          # (m/s^2)/(m/s^2)
    mpc_xy_vel_max_m_s: float = 12.0
    mpc_z_vel_max_up_m_s: float = 3.0
    mpc_z_vel_max_dn_m_s: float = 1.5
    mpc_acc_hor_max_m_s2: float = 5.0
    mpc_acc_up_max_m_s2: float = 4.0
    mpc_acc_down_max_m_s2: float = 3.0
    mpc_tiltmax_air_deg: float = 45.0
    mpc_yawrauto_max_deg_s: float = 45.0
    mpc_land_speed_m_s: float = 0.7
    mpc_tko_speed_m_s: float = 1.5
    com_spoolup_time_s: float = 1.0       # COM_SPOOLUP_TIME: with a ramp, no lift this long after arming
    mpc_tko_ramp_t_s: float = 0.0         # MPC_TKO_RAMP_T (PX4: 3 s): climb-rate limit ramp; 0: none
    mc_roll_p: float = 0.0                # 1/s, MC_ROLL_P (PX4: 4): tilt time constant 1/P; 0: instant tilt
    vel_drag_ff: float = 1.0              # fraction of the drag fed forward at the velocity setpoint (PX4: 0)
    acc_hor_max_offboard: bool = True     # MPC_ACC_HOR_MAX limits offboard setpoints too (PX4: tilt only)
    land_at_stop_point: bool = False      # LAND at PX4's projected stop point (PX4: true), else in place
    mpc_acc_hor_m_s2: float = 3.0         # MPC_ACC_HOR: the braking acceleration of that projection
    offboard_delay_s: float = 0.0         # offboard position setpoints act this late (link to PX4); 0: now
    # automatic modes
    takeoff_acceptance_m: float = 0.3     # TAKEOFF switches to HOLD within this of the target altitude
    hold_brake_speed_m_s: float = 0.2     # HOLD brakes (velocity 0) until this slow, then holds position
    rtl_alt_m: float = 10.0               # RTL_RETURN_ALT (PX4 default is 30 m)
    rtl_cruise_speed_m_s: float = 5.0     # horizontal speed of the return leg
    rtl_acceptance_m: float = 0.5         # horizontal distance to home that ends the return leg
    land_disarm_delay_s: float = 2.0      # COM_DISARM_LAND: on the ground this long in LAND/RTL -> disarm
    preflight_disarm_s: float = 10.0      # COM_DISARM_PRFLT: armed, never taken off -> disarm
    battery_endurance_s: float = 1200.0   # airborne time from full to empty battery
    # GNSS receiver and position estimator
    gnss_rate_hz: float = 10.0
    gnss_sigma_h_m: float = 0.05          # horizontal noise, per axis (1 sigma)
    gnss_sigma_v_m: float = 0.1           # vertical noise (1 sigma)
    est_gain: float = 0.05                # complementary-filter gain per accepted fix, in (0, 1]
    est_gate_m: float = 3.0               # fixes with a larger horizontal innovation are rejected
    est_reset_timeout_s: float = 5.0      # rejecting this long -> reset the estimate to GNSS
    est_init_s: float = 0.5               # estimator start-up time before ready_to_arm
    # computation (not the model: every choice gives the same numbers, bit for bit)
    jit: str = "auto"                     # compiled per-tick kernel: auto (long runs, numba installed),
    #                                       always (numba required), never (numpy only); kernel.py

    @classmethod
    def from_kwargs(cls, params: Mapping[str, Any]) -> SimParams:
        """Build from config keys; an unknown key raises TypeError naming it."""
        known = {f.name for f in fields(cls)}
        for key in params:
            if key not in known:
                raise TypeError(f"unknown sim backend parameter {key!r} (known: {', '.join(sorted(known))})")
        p = cls(**params)
        p.validate()
        return p

    @classmethod
    def parse(cls, name: str, text: str) -> Any:
        """The value of field ``name`` written as ``text`` (a command-line ``KEY=VALUE``), by the field's
        type: ``str`` as is, ``bool`` from true/false (any case) or 1/0, ``int``, else ``float``. An
        unknown name is parsed as a float and left for :meth:`from_kwargs` to name."""
        kind = _FIELD_TYPES.get(name, "float")
        if kind == "str":
            return text
        if kind == "bool":
            word = text.strip().lower()
            if word not in ("true", "false", "1", "0"):
                raise ValueError(f"sim backend parameter {name!r} must be true or false, got {text!r}")
            return word in ("true", "1")
        return int(text) if kind == "int" else float(text)

    def validate(self) -> None:
        """Raise ValueError naming the first out-of-range field."""
        if self.jit not in JIT_CHOICES:
            raise ValueError(f"sim backend parameter 'jit' must be one of {', '.join(JIT_CHOICES)}, "
                             f"got {self.jit!r}")
        for f in fields(self):
            if _FIELD_TYPES[f.name] == "str":
                continue
            v = getattr(self, f.name)
            if not math.isfinite(v) or v < 0:
                raise ValueError(f"sim backend parameter {f.name!r} must be finite and >= 0, got {v!r}")
        for name in ("mass_kg", "radius_m", "gnss_rate_hz", "est_gain", "battery_endurance_s",
                     "physics_substeps", "mpc_xy_vel_max_m_s", "mpc_z_vel_max_up_m_s",
                     "mpc_z_vel_max_dn_m_s", "mpc_land_speed_m_s", "mpc_tko_speed_m_s"):
            if getattr(self, name) <= 0:
                raise ValueError(f"sim backend parameter {name!r} must be > 0")
        if self.est_gain > 1 or self.mpc_tiltmax_air_deg >= 90 or self.vel_drag_ff > 1:
            raise ValueError("est_gain and vel_drag_ff must be <= 1 and mpc_tiltmax_air_deg < 90")

    @property
    def acc_tilt_limit_m_s2(self) -> float:
        """The tilt limit's g·tan(MPC_TILTMAX_AIR): PX4's only horizontal limit on offboard setpoints."""
        return GRAVITY_M_S2 * math.tan(math.radians(self.mpc_tiltmax_air_deg))

    @property
    def acc_hor_limit_m_s2(self) -> float:
        """Horizontal acceleration limit of the automatic modes: MPC_ACC_HOR_MAX within the tilt limit."""
        return min(self.mpc_acc_hor_max_m_s2, self.acc_tilt_limit_m_s2)


_FIELD_TYPES = {f.name: str(f.type) for f in fields(SimParams)}   # "float", "int", "bool", "str"
