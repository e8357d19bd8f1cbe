"""Cost of one ``SimBackend.step()`` for fleets of airborne drones, and of a whole backend tick
(step, every vehicle's telemetry, the fleet's state row).

Run with ``python -m pytest tests/bench/test_bench_sim.py --benchmark-enable``; ``extra_info`` holds
µs per step and drone-steps per second (from the mean). Each fleet is built once per size and
shared by the entries (flying it on costs nothing the assertions care about).
"""

from __future__ import annotations

import math
from functools import cache

import numpy as np
import pytest

from swarmbox.api import Setpoint
from swarmbox.hal.sim.backend import SimBackend

TICK_S = 0.025


@cache
def airborne_fleet(n: int, jit: str = "never", spacing_m: float = 3.0, alt_m: float = 5.0) -> SimBackend:
    """``n`` drones on a grid, hovering at ``alt_m`` under OFFBOARD position setpoints; ``jit``: the
    backend's (never: numpy throughout, however many steps the benchmark takes; always: the kernel)."""
    side = math.ceil(math.sqrt(n))
    homes = [(spacing_m * (k // side), spacing_m * (k % side), 0.0) for k in range(n)]
    b = SimBackend(homes_ned_m=homes, tick_s=TICK_S, rng=np.random.default_rng(0), jit=jit)
    for _ in range(round(1.0 / TICK_S)):
        b.step(TICK_S)
    for v in b.vehicles:
        v.arm()
        v.takeoff(alt_m)
    for _ in range(round(8.0 / TICK_S)):
        b.step(TICK_S)
    for v in b.vehicles:
        n_m, e_m, _ = v.home_ned_m
        v.setpoint(Setpoint.position(n_m + 1.0, e_m, -alt_m))
    b.step(TICK_S)
    assert b.airborne.all()
    return b


@pytest.mark.parametrize("jit", ["never", "always"])
@pytest.mark.parametrize("n", [5, 36, 100, 200])
def test_bench_sim_step(benchmark, n, jit):
    b = airborne_fleet(n, jit)
    benchmark(b.step, TICK_S)
    if benchmark.stats is not None:
        mean_s = benchmark.stats.stats.mean
        benchmark.extra_info.update(drones=n, us_per_step=round(mean_s * 1e6, 1),
                                    drone_steps_per_s=round(n / mean_s))
    # the fleet is still flying sanely after all those steps
    assert b.airborne.all()
    assert np.all(np.isfinite(b.true_pos_ned_m))
    assert np.allclose(b.true_pos_ned_m[:, 2], -5.0, atol=0.5)


@pytest.mark.parametrize("jit", ["never", "always"])
@pytest.mark.parametrize("n", [5, 36])
def test_bench_sim_tick(benchmark, n, jit):
    """What the tick loop asks of the backend per tick: every vehicle's telemetry, the state row's
    columns (written into buffers, as the recorder's), one step."""
    b = airborne_fleet(n, jit)
    values, landed = np.empty((14, n)), np.empty(n, dtype=bool)

    def tick() -> None:
        for v in b.vehicles:
            v.telemetry()
        b.state_into(values, landed)
        b.step(TICK_S)

    benchmark(tick)
    if benchmark.stats is not None:
        mean_s = benchmark.stats.stats.mean
        benchmark.extra_info.update(drones=n, us_per_tick=round(mean_s * 1e6, 1),
                                    drone_ticks_per_s=round(n / mean_s))
    b.state_into(values, landed)
    assert b.airborne.all() and not landed.any()
    assert values[3:6].tolist() == b.true_vel_ned_m_s.T.tolist()   # the velocity rows: telemetry's
    assert values[12].tolist() == [v.telemetry().yaw_rad for v in b.vehicles]
