"""The setpoint safety monitor every bridge runs before a setpoint reaches an autopilot."""

from __future__ import annotations

import math
from dataclasses import dataclass

from swarmbox.api import Setpoint, SetpointKind, Telemetry


@dataclass(frozen=True, slots=True)
class SafetyLimits:
    max_speed_m_s: float = 12.0          # velocity setpoints are scaled down to this
    max_accel_m_s2: float = 5.0          # acceleration setpoints are scaled down to this
    geofence_radius_m: float = 500.0     # horizontal distance from the mission origin
    max_alt_m: float = 120.0             # altitude ceiling (d >= -max_alt_m)
    max_jump_m: float = 1000.0           # position setpoints farther than this from the drone are refused


@dataclass(frozen=True, slots=True)
class Verdict:
    setpoint: Setpoint | None   # what to fly (None: refused)
    action: str                 # "ok", "clamped" or "refused"
    reason: str = ""


_OK = "ok"


def check_setpoint(sp: Setpoint, tel: Telemetry, limits: SafetyLimits) -> Verdict:
    """Refuse non-finite or absurd setpoints; clamp speed, acceleration, geofence and ceiling."""
    n, e, d = sp.ned
    if not (math.isfinite(n) and math.isfinite(e) and math.isfinite(d)) or (
            sp.yaw_rad is not None and not math.isfinite(sp.yaw_rad)):
        return Verdict(None, "refused", "non-finite setpoint")
    if sp.kind is SetpointKind.POSITION:
        if math.dist(sp.ned, tel.pos_ned_m) > limits.max_jump_m:
            return Verdict(None, "refused", f"position setpoint more than {limits.max_jump_m} m away")
        reasons = []
        r = math.hypot(n, e)
        if r > limits.geofence_radius_m:
            k = limits.geofence_radius_m / r
            n, e = n * k, e * k
            reasons.append("geofence")
        if d < -limits.max_alt_m:
            d = -limits.max_alt_m
            reasons.append("ceiling")
        if reasons:
            return Verdict(Setpoint(sp.kind, (n, e, d), sp.yaw_rad), "clamped", "+".join(reasons))
        return Verdict(sp, _OK)
    limit = limits.max_speed_m_s if sp.kind is SetpointKind.VELOCITY else limits.max_accel_m_s2
    norm = math.sqrt(n * n + e * e + d * d)
    if norm > limit:
        k = limit / norm
        return Verdict(Setpoint(sp.kind, (n * k, e * k, d * k), sp.yaw_rad), "clamped",
                       f"norm {norm:.2f} above {limit}")
    return Verdict(sp, _OK)
