"""MAV_CMD_INJECT_FAILURE on a mavsim vehicle: what it accepts and what each failure does."""

from __future__ import annotations

import math

from swarmbox.api import Setpoint
from swarmbox.hal.mavlink import codec as mc
from swarmbox.hal.mavlink.failure import FailureRequest
from tests.hal.test_mavsim import ARM, HOME_ALT, commander, fly, mode, texts

OFFBOARD = (6,)        # PX4 main mode OFFBOARD


def inject(c, unit: str, kind: str) -> int:
    return c.on_command(mc.CMD_INJECT_FAILURE, FailureRequest(unit, kind).params + (0.0,) * 4)


def airborne():
    c = commander()
    fly(c, 1.0)
    c.on_command(mc.CMD_ARM_DISARM, ARM)
    c.on_command(mc.CMD_TAKEOFF, (math.nan,) * 6 + (HOME_ALT + 5.0,))
    fly(c, 8.0)
    return c


def test_gps_off_stops_fixes_and_ok_brings_them_back():
    c = airborne()
    seq = c.telemetry().gnss_seq
    assert inject(c, "gps", "off") == mc.RESULT_ACCEPTED
    assert "failure injected: gps off" in texts(c)
    fly(c, 2.0)
    assert c.telemetry().gnss_seq == seq
    assert inject(c, "gps", "ok") == mc.RESULT_ACCEPTED
    fly(c, 2.0)
    assert c.telemetry().gnss_seq > seq


def test_gps_stuck_repeats_one_fix_while_the_vehicle_moves():
    c = airborne()
    assert inject(c, "gps", "stuck") == mc.RESULT_ACCEPTED
    go = Setpoint.velocity(2.0, 0.0, 0.0)
    fly(c, 0.5, go)
    stuck = c.telemetry().gnss_ned_m
    assert mode(c, *OFFBOARD) == mc.RESULT_ACCEPTED
    fly(c, 4.0, go)
    tel = c.telemetry()
    # one physics step of motion (2 m/s x 10 ms) between the offset update and the fix
    assert all(math.isclose(a, b, abs_tol=0.05) for a, b in zip(tel.gnss_ned_m, stuck, strict=True))
    assert tel.true_pos_ned_m[0] - stuck[0] > 3.0


def test_gps_wrong_offsets_fixes_by_20_m_north():
    c = airborne()
    assert inject(c, "gps", "wrong") == mc.RESULT_ACCEPTED
    fly(c, 1.0)
    tel = c.telemetry()
    assert 18.0 < tel.gnss_ned_m[0] - tel.true_pos_ned_m[0] < 22.0


def test_motor_off_crashes_and_cannot_be_undone_unmodelled_units_are_unsupported():
    c = airborne()
    assert inject(c, "baro", "off") == mc.RESULT_UNSUPPORTED
    assert inject(c, "gps", "intermittent") == mc.RESULT_UNSUPPORTED
    assert inject(c, "motor", "off") == mc.RESULT_ACCEPTED
    fly(c, 0.5)
    assert c.v.frozen is not None and bool(c.sim.crashed[0])   # the sim backend's crash: motors cut for good
    assert inject(c, "motor", "ok") == mc.RESULT_DENIED
