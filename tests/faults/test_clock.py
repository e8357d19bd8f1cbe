"""NodeClock: the skew a clock fault applies, and the resynchronisation at its end."""

import pytest

from swarmbox.core.clock import ClockSpec, NodeClock, TimeSource


def test_skew_jumps_and_changes_rate_from_the_instant_on():
    src = TimeSource()
    clock = NodeClock(src, ClockSpec(offset_s=0.2, drift_ppm=100.0))
    src.t_s = 10.0
    before = clock.now()
    clock.skew(10.0, step_s=0.5, drift_ppm=1000.0)
    assert clock.now() == pytest.approx(before + 0.5)
    src.t_s = 20.0
    assert clock.now() - (before + 0.5) == pytest.approx(10.0 * (1 + 100e-6) * (1 + 1000e-6))
    assert clock.at(20.0) == clock.now()
    assert clock.drift_ppm == pytest.approx((1.0001 * 1.001 - 1) * 1e6)
    clock.resync()
    assert clock.now() == pytest.approx(20.0 * 1.0001 + 0.2)


def test_skew_refuses_a_clock_that_would_stop():
    clock = NodeClock(TimeSource())
    with pytest.raises(ValueError, match="stop or reverse"):
        clock.skew(0.0, drift_ppm=-1e6)
