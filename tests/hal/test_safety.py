"""The setpoint safety monitor's clamps and refusals, checked number by number."""

import math

import pytest

from swarmbox.api import FlightMode, Setpoint, Telemetry
from swarmbox.hal.safety import SafetyLimits, check_setpoint

LIMITS = SafetyLimits(max_speed_m_s=12.0, max_accel_m_s2=5.0, geofence_radius_m=500.0, max_alt_m=120.0,
                      max_jump_m=1000.0)


def at(n=0.0, e=0.0, d=-3.0, vel=(0.0, 0.0, 0.0)) -> Telemetry:
    return Telemetry(0.0, (n, e, d), vel, 0.0, None, 0, True, False, FlightMode.OFFBOARD, 1.0, True, None)


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
    assert jump.action == "refused" and jump.setpoint is None and jump.reason == "jump"
    for sp in (Setpoint.position(math.nan, 0, -3), Setpoint.velocity(0, math.inf, 0),
               Setpoint.position(0, 0, -3, yaw_rad=math.nan)):
        v = check_setpoint(sp, at(), LIMITS)
        assert v.action == "refused" and v.reason == "nonfinite"


def test_speed_and_acceleration_are_scaled_to_their_limits():
    v = check_setpoint(Setpoint.velocity(30.0, 40.0, 0.0), at(), LIMITS)
    assert v.action == "clamped" and v.setpoint.ned == pytest.approx((7.2, 9.6, 0.0))
    a = check_setpoint(Setpoint.acceleration(0.0, 0.0, 10.0), at(), LIMITS)
    assert a.action == "clamped" and a.setpoint.ned == pytest.approx((0.0, 0.0, 5.0))
    assert (v.reason, a.reason) == ("speed", "accel")


def test_a_position_below_ground_is_raised_to_the_floor():
    v = check_setpoint(Setpoint.position(10.0, 20.0, 3.0), at(), LIMITS)
    assert v.action == "clamped" and v.reason == "floor"
    assert v.setpoint.ned == pytest.approx((10.0, 20.0, 0.0))
    assert check_setpoint(Setpoint.position(10.0, 20.0, 0.0), at(), LIMITS).action == "ok"


def test_far_from_the_envelope_velocity_and_acceleration_pass_unchanged():
    for sp in (Setpoint.velocity(11.0, 0.0, -3.0), Setpoint.acceleration(0.0, 5.0, 0.0)):
        v = check_setpoint(sp, at(100.0, 0.0, -20.0, vel=(12.0, 0.0, -3.0)), LIMITS)
        assert v.action == "ok" and v.setpoint == sp


def braking_speed(gap_m: float, lim: SafetyLimits = LIMITS) -> float:
    """The outward speed that reacts within response_s and brakes at brake_m_s2 over gap_m."""
    bt = lim.brake_m_s2 * lim.response_s
    return math.sqrt(bt * bt + 2 * lim.brake_m_s2 * gap_m) - bt


def test_near_the_fence_the_outward_speed_leaves_room_to_brake_and_the_sideways_part_is_kept():
    # 8 m inside the fence, on the east axis, asked for 10 m/s outward (east) and 4 m/s north
    v = check_setpoint(Setpoint.velocity(4.0, 10.0, 0.0), at(0.0, 492.0), LIMITS)
    assert v.action == "clamped" and v.reason == "geofence"
    assert v.setpoint.ned == pytest.approx((4.0, braking_speed(8.0), 0.0))
    assert braking_speed(8.0) * LIMITS.response_s + braking_speed(8.0) ** 2 / (2 * LIMITS.brake_m_s2) \
        == pytest.approx(8.0)
    inward = check_setpoint(Setpoint.velocity(0.0, -10.0, 0.0), at(0.0, 499.0), LIMITS)
    assert inward.action == "ok"   # away from the fence: nothing to limit


def test_at_or_past_a_boundary_nothing_outward_is_left_and_past_it_the_way_back_is_commanded():
    on = check_setpoint(Setpoint.velocity(3.0, 0.0, 0.0), at(500.0, 0.0), LIMITS)
    assert on.setpoint.ned == pytest.approx((0.0, 0.0, 0.0)) and on.reason == "geofence"
    past = check_setpoint(Setpoint.velocity(3.0, 0.0, 0.0), at(0.0, -500.4), LIMITS)   # 0.4 m out, west
    assert past.setpoint.ned == pytest.approx((3.0, 0.4, 0.0))   # 0.4 m/s back east, north kept
    far_out = check_setpoint(Setpoint.velocity(0.0, 0.0, -2.0), at(0.0, 0.0, -130.0), LIMITS)
    assert far_out.reason == "ceiling" and far_out.setpoint.ned == pytest.approx((0.0, 0.0, 1.0))


def test_near_the_ceiling_an_acceleration_brakes_the_climb():
    # climbing at 4 m/s, 2 m under the ceiling: the profile allows less, so the vehicle is told to brake
    v = check_setpoint(Setpoint.acceleration(0.0, 0.0, -2.0), at(0.0, 0.0, -118.0, vel=(0, 0, -4.0)), LIMITS)
    assert v.action == "clamped" and v.reason == "ceiling"
    assert v.setpoint.ned[2] > 0.0   # downward: braking the climb
    assert math.hypot(*v.setpoint.ned) <= LIMITS.max_accel_m_s2 + 1e-9
    slow = check_setpoint(Setpoint.acceleration(0.0, 0.0, -2.0), at(0.0, 0.0, -100.0, vel=(0, 0, -0.5)),
                          LIMITS)
    assert slow.action == "ok"   # 20 m below at 0.5 m/s: nothing to brake yet


def test_px4_geofence_sits_just_outside_the_envelope_measured_from_each_home():
    from swarmbox.hal.px4.sitl import SitlOptions, instance_env
    from swarmbox.hal.safety import PX4_CEILING_MARGIN_M, PX4_FENCE_MARGIN_M, px4_geofence

    lim = SafetyLimits(geofence_radius_m=50.0, max_alt_m=10.0)
    gf = px4_geofence(lim, (30.0, 40.0, 0.0))   # 50 m from the origin: 100 m of fence beyond it
    assert gf == {"GF_MAX_HOR_DIST": 100.0 + PX4_FENCE_MARGIN_M,
                  "GF_MAX_VER_DIST": 10.0 + PX4_CEILING_MARGIN_M, "GF_ACTION": 3, "GF_PREDICT": 0}
    assert px4_geofence(lim, (0.0, 0.0, -4.0))["GF_MAX_VER_DIST"] == 6.0 + PX4_CEILING_MARGIN_M
    env = instance_env((47.0, 8.0, 488.0), SitlOptions(params={"GF_ACTION": 2}), 1.0, {}, gf)
    assert env["PX4_PARAM_GF_MAX_HOR_DIST"] == "105.0" and env["PX4_PARAM_GF_ACTION"] == "2"   # user's wins
