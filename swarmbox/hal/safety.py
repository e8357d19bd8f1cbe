"""The setpoint safety monitor every bridge runs before a setpoint reaches an autopilot.

It keeps every setpoint kind inside one envelope: the geofence (a horizontal radius around the
mission origin), the ceiling (``d >= -max_alt_m``) and the floor (``d <= floor_d_m``, the ground).

- **Position** setpoints are moved onto the boundary: the horizontal target is scaled back onto the
  fence, the altitude clamped to the ceiling and the floor.
- **Velocity and acceleration** setpoints are judged against the vehicle's state (its estimated
  position and velocity): the component pointing out of the envelope is limited so the vehicle can
  still react (``response_s``) and brake at ``brake_m_s2`` before the boundary; at or
  past the boundary nothing outward is left and a vehicle outside is sent back in (at most
  ``return_m_s``). The tangential part is untouched: a swarm flying into the fence slides along it.
  An acceleration is limited so the outward velocity follows that same braking profile.

Reasons are fixed codes (``nonfinite``, ``jump``, ``speed``, ``accel``, ``geofence``, ``ceiling``,
``floor``, joined with ``+`` in that order), never text with numbers in it: the numbers go into the
``safety`` event's fields.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from swarmbox.api import Setpoint, SetpointKind, Telemetry

#: every reason code the monitor gives, in the order a combined reason lists them
REASONS = ("nonfinite", "jump", "speed", "accel", "geofence", "ceiling", "floor")
_POSITION, _VELOCITY = SetpointKind.POSITION, SetpointKind.VELOCITY
RETURN_GAIN_1_S = 1.0     # a vehicle past a boundary is sent back at this gain (m/s per m) ...
# An acceleration steers the outward velocity onto its limit at this gain: high enough to beat an
# autopilot's thrust bias (PX4 SIH climbed on 0.6 m/s² of commanded descent at a gain of 2).
VELOCITY_GAIN_1_S = 4.0


@dataclass(frozen=True, slots=True)
class SafetyLimits:
    max_speed_m_s: float = 12.0          # velocity setpoints are scaled down to this
    max_accel_m_s2: float = 5.0          # acceleration setpoints are scaled down to this
    geofence_radius_m: float = 500.0     # horizontal distance from the mission origin
    max_alt_m: float = 120.0             # altitude ceiling (d >= -max_alt_m)
    max_jump_m: float = 1000.0           # position setpoints farther than this from the drone are refused
    floor_d_m: float = 0.0               # the ground: position setpoints below it (d > floor) are raised
    brake_m_s2: float = 2.0              # deceleration the fence and ceiling leave room for
    return_m_s: float = 1.0              # ... up to this speed
    response_s: float = 0.5              # how long the vehicle takes to follow a new velocity (s)


@dataclass(frozen=True, slots=True)
class Verdict:
    setpoint: Setpoint | None   # what to fly (None: refused)
    action: str                 # "ok", "clamped" or "refused"
    reason: str = ""            # "+"-joined codes of REASONS


_OK = "ok"


def check_setpoint(sp: Setpoint, tel: Telemetry, limits: SafetyLimits) -> Verdict:
    """Refuse non-finite or absurd setpoints; keep the rest inside speed, acceleration and the envelope."""
    n, e, d = sp.ned
    if not (math.isfinite(n) and math.isfinite(e) and math.isfinite(d)) or (
            sp.yaw_rad is not None and not math.isfinite(sp.yaw_rad)):
        return Verdict(None, "refused", "nonfinite")
    if sp.kind is _POSITION:
        return _position(sp, tel, limits)
    velocity = sp.kind is _VELOCITY
    limit = limits.max_speed_m_s if velocity else limits.max_accel_m_s2
    reasons = []
    norm = math.sqrt(n * n + e * e + d * d)
    if norm > limit:
        k = limit / norm
        n, e, d = n * k, e * k, d * k
        reasons.append("speed" if velocity else "accel")
    fenced = _fence(velocity, (n, e, d), tel, limits)
    if fenced is not None:
        (n, e, d), codes = fenced
        reasons.extend(codes)
        norm = math.sqrt(n * n + e * e + d * d)
        if norm > limit:   # a braking acceleration added to a sideways one: keep the limit
            k = limit / norm
            n, e, d = n * k, e * k, d * k
    if reasons:
        return Verdict(Setpoint(sp.kind, (n, e, d), sp.yaw_rad), "clamped", "+".join(reasons))
    return Verdict(sp, _OK)


def _position(sp: Setpoint, tel: Telemetry, limits: SafetyLimits) -> Verdict:
    n, e, d = sp.ned
    if math.dist(sp.ned, tel.pos_ned_m) > limits.max_jump_m:
        return Verdict(None, "refused", "jump")
    reasons = []
    r = math.hypot(n, e)
    if r > limits.geofence_radius_m:
        k = limits.geofence_radius_m / r
        n, e = n * k, e * k
        reasons.append("geofence")
    if d < -limits.max_alt_m:
        d = -limits.max_alt_m
        reasons.append("ceiling")
    elif d > limits.floor_d_m:
        d = limits.floor_d_m
        reasons.append("floor")
    if reasons:
        return Verdict(Setpoint(sp.kind, (n, e, d), sp.yaw_rad), "clamped", "+".join(reasons))
    return Verdict(sp, _OK)


def reach_m(limits: SafetyLimits) -> float:
    """How near a boundary a velocity or acceleration can be limited: the stopping distance of the
    fastest allowed flight plus a second of it. Farther from both, nothing is (the usual case)."""
    return limits.max_speed_m_s * (limits.max_speed_m_s / (2.0 * limits.brake_m_s2) + limits.response_s + 1.0)


def near_boundary(pos_ned_m: tuple[float, float, float], limits: SafetyLimits) -> bool:
    """Whether a velocity or acceleration setpoint flown at ``pos_ned_m`` may need limiting."""
    reach = reach_m(limits)
    return (limits.geofence_radius_m - math.hypot(pos_ned_m[0], pos_ned_m[1]) <= reach
            or limits.max_alt_m + pos_ned_m[2] <= reach)


def outward_limit(gap_m: float, limits: SafetyLimits) -> float:
    """The largest speed towards a boundary ``gap_m`` ahead (negative past it: the way back)."""
    if gap_m > 0.0:   # v * response + v^2 / 2b = gap: it reacts, then brakes, and stops in time
        bt = limits.brake_m_s2 * limits.response_s
        return math.sqrt(bt * bt + 2.0 * limits.brake_m_s2 * gap_m) - bt
    return -min(RETURN_GAIN_1_S * -gap_m, limits.return_m_s)


def _fence(velocity: bool, cmd: tuple[float, float, float], tel: Telemetry,
           limits: SafetyLimits) -> tuple[tuple[float, float, float], list[str]] | None:
    """``cmd`` (a velocity, or an acceleration) with its outward parts limited; None if unchanged."""
    n, e, d = cmd
    pn, pe, pd = tel.pos_ned_m
    vd = tel.vel_ned_m_s[2]
    reach = reach_m(limits)
    r = math.hypot(pn, pe)
    h_gap, v_gap = limits.geofence_radius_m - r, limits.max_alt_m + pd
    if h_gap > reach and v_gap > reach:
        return None
    codes = []
    if r > 1e-9 and h_gap <= reach:
        fenced = _fence_h(velocity, (n, e), (pn / r, pe / r), r, h_gap, tel, limits)
        if fenced is not None:
            (n, e), _ = fenced, codes.append("geofence")
    if v_gap <= reach:
        allowed = _allowed(velocity, outward_limit(v_gap, limits), -vd, limits)
        if -d > allowed + 1e-9:              # upward is -d
            d = -allowed
            codes.append("ceiling")
    return ((n, e, d), codes) if codes else None


def _fence_h(velocity: bool, cmd: tuple[float, float], out: tuple[float, float], r: float, gap: float,
             tel: Telemetry, limits: SafetyLimits) -> tuple[float, float] | None:
    """The horizontal command near the fence (``out``: the outward unit vector); None if unchanged."""
    n, e = cmd
    un, ue = out
    vn, ve = tel.vel_ned_m_s[0], tel.vel_ned_m_s[1]
    v_out = vn * un + ve * ue
    allowed = _allowed(velocity, outward_limit(gap, limits), v_out, limits)
    tn, te = -ue, un                        # along the fence
    v_side = vn * tn + ve * te
    a_side = n * tn + e * te
    if not velocity:
        # Flying along a curved fence takes v²/r inward, and more than the acceleration limit can
        # give minus the braking reserve is not to be had: a faster sideways flight is slowed down.
        allowed -= v_side * v_side / r
        side_max = math.sqrt(max(limits.max_accel_m_s2 - limits.brake_m_s2, 0.5) * r)
        over = abs(v_side) - side_max
        if over > 0 and a_side * math.copysign(1.0, v_side) > -VELOCITY_GAIN_1_S * over:
            a_side = -math.copysign(VELOCITY_GAIN_1_S * over, v_side)
        else:
            over = 0.0
    a_out = n * un + e * ue
    if a_out <= allowed + 1e-9 and (velocity or over <= 0):
        return None
    a_out = min(a_out, allowed)
    return a_out * un + a_side * tn, a_out * ue + a_side * te


def _allowed(velocity: bool, speed_limit: float, outward_speed: float, limits: SafetyLimits) -> float:
    """The outward component a velocity (the braking profile itself) or an acceleration (steering the
    outward velocity onto that profile, within the acceleration limit) may have."""
    if velocity:
        # A vehicle already moving out faster than the limit (its response lags the command, or a
        # sideways flight along the curved fence carries it out) is asked for that much less.
        return speed_limit - max(outward_speed - max(speed_limit, 0.0), 0.0)
    # Following the braking profile outward at speed v takes about the deceleration b * v / limit
    # (feed-forward); the gain term pulls a velocity off the profile back onto it.
    follow = -limits.brake_m_s2 * min(max(outward_speed / speed_limit, 0.0), 1.0) if speed_limit > 0 else 0.0
    return max(follow + VELOCITY_GAIN_1_S * (speed_limit - outward_speed), -limits.max_accel_m_s2)


def safety_event(sp: Setpoint, verdict: Verdict, tel: Telemetry) -> dict[str, object]:
    """The fields of a ``safety`` event for a setpoint the monitor changed: the reason code, what was
    asked and what is flown, and where the vehicle was (radius from the origin, altitude)."""
    p = tel.pos_ned_m
    flown = verdict.setpoint
    return {"reason": verdict.reason, "kind": sp.kind.name.lower(),
            "requested": [float(x) for x in sp.ned],
            "flown": None if flown is None else [round(float(x), 6) for x in flown.ned],
            "radius_m": round(math.hypot(p[0], p[1]), 3), "alt_m": round(-p[2], 3)}


class HeldSetpoint:
    """The velocity or acceleration a vehicle keeps flying after the algorithm stopped sending it
    (a hook that returns None holds the last setpoint): judged again on the vehicle's state at every
    step without a new one, so that no held command flies through the fence."""

    __slots__ = ("fresh", "requested")

    def __init__(self) -> None:
        self.requested: Setpoint | None = None
        self.fresh = False

    def asked(self, sp: Setpoint | None) -> None:
        """A setpoint was flown (None: the vehicle left OFFBOARD, nothing held)."""
        self.requested = sp if sp is not None and sp.kind is not _POSITION else None
        self.fresh = True

    def stale(self) -> Setpoint | None:
        """The held request when no setpoint came since the last call, else None."""
        if self.fresh:
            self.fresh = False
            return None
        return self.requested


#: PX4's geofence action on a breach (GF_ACTION): 3 = return to launch
PX4_GF_ACTION_RTL = 3
#: PX4's breach prediction (GF_PREDICT) off, whatever the PX4 version's default: it assumes the
#: vehicle still accelerates at the controller's limit (MPC_ACC_*) when it starts braking, which a
#: drone the monitor is slowing down does not. PX4's layer acts on the position it measures.
PX4_GF_PREDICT_OFF = 0
PX4_FENCE_MARGIN_M = 5.0       # PX4's own fence sits this far outside the monitor's (horizontal)
# ... and above its ceiling. PX4 measures altitude above the home it keeps from its global estimate,
# which in SIH wandered 3 m within one flight (GLOBAL_POSITION_INT's home, alt - relative_alt) while
# the local estimate held still: at 2 m PX4 reported a breach at 7.98 m under an 8 m ceiling.
PX4_CEILING_MARGIN_M = 5.0


def px4_geofence(limits: SafetyLimits, home_ned_m: tuple[float, float, float]) -> dict[str, float | int]:
    """PX4 parameters for its own geofence, a second layer just outside the monitor's envelope.

    PX4 measures from the vehicle's home, the monitor from the mission origin: every point inside
    the mission's fence is within ``radius + |home|`` of home, every point under the ceiling within
    ``max_alt + d_home`` above it."""
    n, e, d = home_ned_m
    return {"GF_MAX_HOR_DIST": round(limits.geofence_radius_m + math.hypot(n, e) + PX4_FENCE_MARGIN_M, 3),
            "GF_MAX_VER_DIST": round(limits.max_alt_m + d + PX4_CEILING_MARGIN_M, 3),
            "GF_ACTION": PX4_GF_ACTION_RTL, "GF_PREDICT": PX4_GF_PREDICT_OFF}
