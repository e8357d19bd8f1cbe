"""A vehicle given the same setpoint as last tick skips the safety check only while nothing that
check depends on has changed."""

from __future__ import annotations

import numpy as np

from swarmbox.api import Setpoint
from swarmbox.hal.safety import SafetyLimits
from swarmbox.hal.sim.backend import SimBackend
from swarmbox.testing import Flight


def _airborne(limits=SafetyLimits()):
    b = SimBackend(homes_ned_m=[(0.0, 0.0, 0.0)], tick_s=0.025, rng=np.random.default_rng(1), limits=limits)
    f = Flight(b)
    f.airborne(0, 3.0)
    return b, f, b.vehicles[0]


def test_repeated_setpoint_is_ok_and_keeps_the_flown_setpoint():
    _, f, v = _airborne()
    sp = Setpoint.position(1.0, 0.0, -3.0)
    first = v.setpoint(sp)
    f.run_for(0.1)
    again = v.setpoint(Setpoint.position(1.0, 0.0, -3.0))   # equal, not the same object
    assert first == again and again.action == "ok" and again.flown == sp


def test_repeated_position_setpoint_is_refused_once_the_vehicle_is_too_far_from_it():
    b, f, v = _airborne(SafetyLimits(max_jump_m=5.0))
    sp = Setpoint.position(0.0, 0.0, -7.0)   # 4 m above: within the jump limit
    assert v.setpoint(sp).action == "ok"
    f.run_for(0.1)
    assert v.setpoint(sp).action == "ok"     # the same setpoint again, still in range
    b.gnss_offset_ned_m = [[20.0, 0.0, 0.0]]   # the estimate jumps 20 m north at the next fix
    f.run_until(lambda: f.tel().pos_ned_m[0] > 10.0, 5.0, "estimate jump")
    assert v.setpoint(sp).action == "refused"      # same setpoint, now too far from the estimate


def test_a_clamped_setpoint_is_clamped_every_time():
    _, f, v = _airborne(SafetyLimits(max_speed_m_s=2.0))
    sp = Setpoint.velocity(5.0, 0.0, 0.0)
    for _ in range(3):
        verdict = v.setpoint(sp)
        assert verdict.action == "clamped" and verdict.flown.ned[0] == 2.0
        f.run_for(0.05)
