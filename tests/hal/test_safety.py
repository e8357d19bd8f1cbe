"""The setpoint safety monitor's clamps and refusals, checked number by number."""

import math

import pytest

from swarmbox.api import FlightMode, Setpoint, Telemetry
from swarmbox.hal.safety import SafetyLimits, check_setpoint

LIMITS = SafetyLimits(max_speed_m_s=12.0, max_accel_m_s2=5.0, geofence_radius_m=500.0, max_alt_m=120.0,
                      max_jump_m=1000.0)


def at(n=0.0, e=0.0, d=-3.0) -> Telemetry:
    return Telemetry(0.0, (n, e, d), (0.0, 0.0, 0.0), 0.0, None, 0, True, False, FlightMode.OFFBOARD, 1.0,
                     True, None)


def test_inside_the_limits_passes_unchanged():
    sp = Setpoint.position(100.0, -200.0, -50.0)
    v = check_setpoint(sp, at(), LIMITS)
    assert v.action == "ok" and v.setpoint == sp and v.reason == ""


def test_geofence_scales_the_horizontal_target_back_onto_the_fence():
    v = check_setpoint(Setpoint.position(600.0, 800.0, -3.0), at(500.0, 500.0), LIMITS)
    assert v.action == "clamped" and v.reason == "geofence"
    n, e, d = v.setpoint.ned
    assert (n, e, d) == pytest.approx((300.0, 400.0, -3.0))
    assert math.hypot(n, e) == pytest.approx(500.0)


def test_ceiling_clamps_altitude_only():
    v = check_setpoint(Setpoint.position(10.0, 20.0, -150.0), at(), LIMITS)
    assert v.action == "clamped" and v.reason == "ceiling"
    assert v.setpoint.ned == pytest.approx((10.0, 20.0, -120.0))


def test_geofence_and_ceiling_together_name_both():
    v = check_setpoint(Setpoint.position(0.0, 700.0, -130.0), at(0.0, 400.0), LIMITS)
    assert v.action == "clamped" and v.reason == "geofence+ceiling"
    assert v.setpoint.ned == pytest.approx((0.0, 500.0, -120.0))


def test_absurd_jumps_and_non_finite_values_are_refused():
    jump = check_setpoint(Setpoint.position(1001.0, 0.0, -3.0), at(0.0, 0.0, -3.0), LIMITS)
    assert jump.action == "refused" and jump.setpoint is None and "1000" in jump.reason
    for sp in (Setpoint.position(math.nan, 0, -3), Setpoint.velocity(0, math.inf, 0),
               Setpoint.position(0, 0, -3, yaw_rad=math.nan)):
        v = check_setpoint(sp, at(), LIMITS)
        assert v.action == "refused" and v.reason == "non-finite setpoint"


def test_speed_and_acceleration_are_scaled_to_their_limits():
    v = check_setpoint(Setpoint.velocity(30.0, 40.0, 0.0), at(), LIMITS)
    assert v.action == "clamped" and v.setpoint.ned == pytest.approx((7.2, 9.6, 0.0))
    a = check_setpoint(Setpoint.acceleration(0.0, 0.0, 10.0), at(), LIMITS)
    assert a.action == "clamped" and a.setpoint.ned == pytest.approx((0.0, 0.0, 5.0))
