"""The compiled per-step kernel (``swarmbox.hal.sim.kernel``) flies exactly what the numpy code flies.

Every state array of the fleet (controller, dynamics, GNSS estimator, battery) is compared bit for bit
after every step, through takeoff, position, velocity and acceleration setpoints, yaw turns, motor
loss, a GNSS offset past the gate (estimator resets), a GNSS outage, LAND / RTL / HOLD, a crash, and
PX4-like parameters (takeoff ramp, attitude lag, no drag feed-forward, delayed offboard targets), and
under random command sequences; a whole run that switches to the kernel half-way writes the same logs
as one that never does.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from swarmbox.api import Setpoint
from swarmbox.hal.sim import kernel
from swarmbox.hal.sim.backend import SimBackend

pytest.importorskip("numba")

TICK_S = 0.025
PX4_LIKE = {"mc_roll_p": 4.0, "vel_drag_ff": 0.0, "offboard_delay_s": 0.1, "mpc_tko_ramp_t_s": 3.0,
            "land_at_stop_point": True, "acc_hor_max_offboard": False}


def _fly(n: int, jit: str, **params) -> np.ndarray:
    """Every state array after each of 1,800 steps of a scripted flight through every mode."""
    homes = [(3.0 * k, 1.5 * (k % 3), 0.0) for k in range(n)]
    b = SimBackend(homes_ned_m=homes, tick_s=TICK_S, rng=np.random.default_rng(7), jit=jit, **params)
    assert (b._kernel is not None) == (jit == "always")
    vs = b.vehicles
    rows = []
    for k in range(1800):
        if k == 30:
            for v in vs:
                v.arm()
                v.takeoff(4.0 + v.drone_id % 4)
        elif k == 300:
            for v in vs:   # a long leg: saturated speed and acceleration, a yaw turn past +-pi
                v.setpoint(Setpoint.position(40.0 + 2 * v.drone_id, -25.0, -8.0,
                                             yaw_rad=2.9 - 0.1 * v.drone_id))
        elif k == 700:
            for v in vs[0::3]:
                v.setpoint(Setpoint.velocity(3.0, -4.0, -0.5, yaw_rad=-3.0))
            for v in vs[1::3]:
                v.setpoint(Setpoint.acceleration(1.0, -2.0, 0.3))
            b.accel_scale = np.linspace(0.4, 1.0, n)   # motor loss
            b.gnss_offset_ned_m = np.outer(np.arange(n) % 2, [4.0, 0.0, 0.0])   # past the gate: resets
        elif k == 1100:
            for v in vs[0::3]:
                v.land()
            for v in vs[1::3]:
                v.return_to_launch()
            for v in vs[2::3]:
                v.hold()
        elif k == 1600:
            b.crashed = np.arange(n) == n - 1
            b.gnss_available = np.arange(n) % 3 != 0   # an outage
        b.step(TICK_S)
        g = b._gnss
        rows.append(np.concatenate([b._kin.ravel(), b.airborne, b._free_kg, b._world.cmd_vel_xy.ravel(),
                                    b.ctrl.acc_ned_m_s2.ravel(), b.ctrl.integ_m_s2.ravel(),
                                    b.ctrl._att_acc.ravel(), b.ctrl.yaw_rad, [b.ctrl._yaw_busy],
                                    b._air_s, b.battery_frac(), g.err_ned_m.ravel(), g.fix_ned_m.ravel(),
                                    g.seq, g.resets, g._last_accept_s]))
    assert b.estimator_resets.any()   # the GNSS offset forced resets
    return np.array(rows)


@pytest.mark.parametrize("params", [{}, PX4_LIKE], ids=["sim", "px4_like"])
@pytest.mark.parametrize("n", [5, 40])   # 40: past the controller's small-fleet list path (_turn)
def test_kernel_equals_numpy_bit_for_bit(n, params):
    ref, fast = _fly(n, "never", **params), _fly(n, "always", **params)
    assert np.isfinite(ref[:, :9 * n]).all()   # the kinematics (GNSS fixes are NaN before the first)
    diff = np.flatnonzero(((ref != fast) & ~(np.isnan(ref) & np.isnan(fast))).any(axis=1))
    assert not len(diff), f"first differing step: {diff[0]}"


def test_auto_switches_half_way_and_writes_the_same_logs(run, monkeypatch):
    monkeypatch.setattr(kernel, "JIT_AFTER_STEPS", 300)
    monkeypatch.setattr(kernel, "_numpy_steps", 0)
    monkeypatch.setattr(kernel, "_kernel", None)
    never, d_never = run("backend.jit=never", "seed=2")
    assert kernel.loaded() is None
    auto, d_auto = run("backend.jit=auto", "seed=2")
    assert kernel.loaded() is not None and auto["ticks"] > 300   # switched during the run
    files = sorted(p.relative_to(d_never) for p in (d_never / "logs").rglob("*.parquet"))
    assert files == sorted(p.relative_to(d_auto) for p in (d_auto / "logs").rglob("*.parquet"))
    for f in files:
        pd.testing.assert_frame_equal(pd.read_parquet(d_never / f), pd.read_parquet(d_auto / f), obj=str(f))
    # a later backend in the same process starts on the kernel
    b = SimBackend(homes_ned_m=[(0.0, 0.0, 0.0)], tick_s=TICK_S, rng=np.random.default_rng(0))
    assert b._kernel is kernel.loaded()


def test_bad_jit_value_is_refused_with_its_name():
    with pytest.raises(ValueError, match="'jit' must be one of auto, always, never, got 'fast'"):
        SimBackend(homes_ned_m=[(0.0, 0.0, 0.0)], tick_s=TICK_S, rng=np.random.default_rng(0), jit="fast")


def test_without_numba_always_fails_clearly_and_auto_stays_on_numpy(monkeypatch, tmp_path: Path):
    def missing() -> None:
        raise ImportError("No module named 'numba'")

    monkeypatch.setattr(kernel, "compiled", missing)
    monkeypatch.setattr(kernel, "_kernel", None)
    with pytest.raises(RuntimeError, match="backend.jit=always needs numba"):
        SimBackend(homes_ned_m=[(0.0, 0.0, 0.0)], tick_s=TICK_S, rng=np.random.default_rng(0), jit="always")
    monkeypatch.setattr(kernel, "installed", lambda: False)
    b = SimBackend(homes_ned_m=[(0.0, 0.0, 0.0)], tick_s=TICK_S, rng=np.random.default_rng(0))
    monkeypatch.setattr(kernel, "_numpy_steps", kernel.JIT_AFTER_STEPS)
    b.step(TICK_S)
    assert b._kernel is None and not b._jit_wanted


def test_mavsim_vehicles_stay_on_numpy_unless_asked():
    """A paced mavsim vehicle must not stall mid-flight to load the kernel."""
    from swarmbox.hal.mavsim.process import sim_params_of

    assert sim_params_of(["mass_kg=2"]) == {"jit": "never", "mass_kg": 2.0}
    assert sim_params_of(["jit=always"])["jit"] == "always"
    with pytest.raises(ValueError, match="'jit' must be one of"):
        sim_params_of(["jit=fast"])


_vec = st.tuples(*[st.floats(-60.0, 60.0)] * 3)
_command = st.tuples(
    st.integers(0, 400),                                        # at step
    st.integers(0, 5),                                          # drone (modulo the fleet)
    st.sampled_from(["position", "velocity", "acceleration", "land", "rtl", "hold", "scale"]),
    _vec,
    st.one_of(st.none(), st.floats(-4.0, 4.0)),                 # yaw target
)


@settings(max_examples=25, deadline=None)
@given(n=st.integers(1, 6), px4_like=st.booleans(), commands=st.lists(_command, max_size=12))
def test_kernel_equals_numpy_for_any_command_sequence(n, px4_like, commands):
    params = PX4_LIKE if px4_like else {}
    homes = [(4.0 * k, 0.0, 0.0) for k in range(n)]
    fleets = [SimBackend(homes_ned_m=homes, tick_s=TICK_S, rng=np.random.default_rng(1), jit=jit, **params)
              for jit in ("never", "always")]
    plan: dict[int, list] = {}
    for cmd in commands:
        plan.setdefault(cmd[0], []).append(cmd[1:])
    for k in range(420):
        for b in fleets:
            if k == 20:
                for v in b.vehicles:
                    v.arm()
                    v.takeoff(5.0)
            for i, kind, (x, y, z), yaw in plan.get(k, ()):
                v = b.vehicles[i % n]
                if kind == "position":
                    v.setpoint(Setpoint.position(x, y, -abs(z) / 4 - 1.0, yaw_rad=yaw))
                elif kind == "velocity":
                    v.setpoint(Setpoint.velocity(x / 4, y / 4, z / 20, yaw_rad=yaw))
                elif kind == "acceleration":
                    v.setpoint(Setpoint.acceleration(x / 6, y / 6, z / 30, yaw_rad=yaw))
                elif kind == "scale":
                    scale = b.accel_scale.copy()
                    scale[i % n] = abs(x) / 60.0
                    b.accel_scale = scale
                else:
                    {"land": v.land, "rtl": v.return_to_launch, "hold": v.hold}[kind]()
            b.step(TICK_S)
        ref, fast = fleets
        for a, c in ((ref._kin, fast._kin), (ref.ctrl.integ_m_s2, fast.ctrl.integ_m_s2),
                     (ref.ctrl.yaw_rad, fast.ctrl.yaw_rad), (ref._gnss.err_ned_m, fast._gnss.err_ned_m),
                     (ref.battery_frac(), fast.battery_frac())):
            assert np.array_equal(a, c), f"step {k}"


@pytest.mark.slow
def test_bench_hover_cli_flies_on_the_kernel_when_asked():
    """``python -m swarmbox.bench.hover N --jit always`` (what ``python -m swarmbox.bench --jit always``
    runs), a real subprocess."""
    cmd = [sys.executable, "-m", "swarmbox.bench.hover", "4", "--hover-s", "1", "--jit", "always"]
    out = subprocess.run(cmd, capture_output=True, text=True, timeout=120, check=False)
    assert out.returncode == 0, out.stderr[-2000:]
    row = json.loads(out.stdout.strip().splitlines()[-1])
    assert row["status"] == "ok" and row["n"] == 4 and row["agent_steps_per_s"] > 0
