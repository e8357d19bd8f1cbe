"""The sim backend's per-tick shortcuts give exactly what the plain computations give.

Prepared pymunk batch calls vs ``pymunk.batch``; cached GNSS telemetry fields vs fields rebuilt from
the arrays every tick; one battery computation vs ``np.clip``; state columns written into buffers
vs the formula — all compared bit for bit, through fixes, a GNSS outage, a crash and arming.
"""

from __future__ import annotations

import math

import numpy as np
import pymunk.batch as pb

from swarmbox.api import Setpoint, Telemetry
from swarmbox.hal.sim.backend import SimBackend, SimParams
from swarmbox.hal.sim.world import _GET, _SET, _SET_FORCE, PlaneWorld

TICK_S = 0.025
HOMES = [(0.0, 0.0, 0.0), (4.0, 0.0, 0.0), (0.0, 4.0, 0.0)]


def _world(p: SimParams) -> PlaneWorld:
    homes = np.array(HOMES).T
    n = homes.shape[1]
    return PlaneWorld(homes, p, [{"kind": "circle", "center": [20.0, 0.0], "radius_m": 1.0}],
                      np.full(n, -5.0), np.zeros(n), np.ones(n), lambda *a: None)


def _reference_step(w: PlaneWorld, dt_s: float, substeps: int) -> None:
    """PlaneWorld.step through ``pymunk.batch``'s own functions."""
    pb.set_space_bodies(w.space, _SET, w._set_buf)
    h = dt_s / substeps
    w.space.step(h)
    if substeps > 1:
        w._force_arr[:w.n] = w._set_arr[:w.n, 2:4]
        for _ in range(substeps - 1):
            pb.set_space_bodies(w.space, _SET_FORCE, w._force_buf)
            w.space.step(h)


def _reference_read(w: PlaneWorld) -> np.ndarray:
    buf = pb.Buffer()
    pb.get_space_bodies(w.space, _GET, buf)
    return np.frombuffer(buf.float_buf()).reshape(-1, 4)[:w.n].copy()


def test_prepared_batch_calls_equal_pymunk_batch():
    p = SimParams()
    fast, ref = _world(p), _world(p)
    pos, vel = np.zeros((3, fast.n)), np.zeros((3, fast.n))
    rng = np.random.default_rng(3)
    for k in range(60):
        cmd_v, cmd_f = rng.normal(size=(2, fast.n)), rng.normal(size=(2, fast.n)) * 5.0
        for w in (fast, ref):
            w.cmd_vel_xy[...] = cmd_v
            w.cmd_force_xy[...] = cmd_f
        substeps = 1 + k % 3
        fast.step(TICK_S, substeps)
        _reference_step(ref, TICK_S, substeps)
        fast.read(pos, vel)
        want = _reference_read(ref)
        got = np.concatenate((pos[:2], vel[:2])).T
        assert np.array_equal(got.view(np.int64), want.view(np.int64)), k
        assert fast.bodies[1].position == ref.bodies[1].position


def _reference_telemetry(b: SimBackend, i: int) -> Telemetry:
    """What vehicle ``i``'s telemetry is, straight from the arrays (no caches)."""
    g, v = b._gnss, b.vehicles[i]
    battery = np.clip(1.0 - b._air_s / b.params.battery_endurance_s, 0.0, 1.0)
    seq = int(g.seq[i])
    fix = tuple(g.fix_ned_m[:, i].tolist()) if seq else None
    ready = bool((g.ready(b.t_s) & ~b._crashed)[i])
    return Telemetry(b.t_s, tuple(b._est[:, i].tolist()), tuple(b._vel[:, i].tolist()),
                     float(b.ctrl.yaw_rad[i]), fix, seq, v.armed, bool(b.airborne[i] == 0.0), v.mode,
                     float(battery[i]), ready, tuple(b._pos[:, i].tolist()), True)


def _reference_state(b: SimBackend, index) -> tuple[np.ndarray, np.ndarray]:
    values = np.concatenate((b._est, b._vel, b._gnss.fix_ned_m, b._pos, b.ctrl.yaw_rad[None],
                             np.clip(1.0 - b._air_s / b.params.battery_endurance_s, 0.0, 1.0)[None]))
    landed = b.airborne == 0.0
    if index is not None:
        values, landed = values[:, index], landed[index]
    return values, landed


def _same(a: np.ndarray, b: np.ndarray) -> bool:
    return a.shape == b.shape and np.array_equal(a.view(np.int64), b.view(np.int64))


def test_cached_telemetry_and_state_columns_equal_the_arrays_through_a_flight():
    b = SimBackend(homes_ned_m=HOMES, tick_s=TICK_S, rng=np.random.default_rng(5), battery_endurance_s=20.0,
                   est_init_s=0.51)   # ready between two fixes
    n = b.n
    seen_fix = seen_crash = seen_partial = False
    for k in range(int(30.0 / TICK_S)):
        t = k * TICK_S
        if k == 40:
            for v in b.vehicles:
                v.arm()
                v.takeoff(4.0)
        if k == 400:
            b.gnss_available = [True, False, True]   # an outage: no fix, seq stops, fields unchanged
        if k == 600:
            b.gnss_available = True
        if k == 701:   # between two fixes (10 Hz: every 4th tick)
            b.crashed[2] = True   # ready_to_arm drops at once, before the step applies the crash
        if 300 <= k < 1000 and k % 20 == 0:
            b.vehicles[0].setpoint(Setpoint.position(3.0 * math.sin(t), 2.0, -4.0))
        tels = [v.telemetry() for v in b.vehicles]
        for i in range(n):
            if b.vehicles[i].frozen is None:
                assert tels[i] == _reference_telemetry(b, i), (k, i)
        seen_fix |= tels[0].gnss_ned_m is not None
        seen_crash |= not tels[2].ready_to_arm and bool(b._crashed[2])
        seen_partial |= 0.0 < tels[0].battery_frac < 1.0
        for index in (None, np.array([2, 0])):
            m = n if index is None else len(index)
            values, landed = np.empty((14, m)), np.empty(m, dtype=bool)
            b.state_into(values, landed, index)
            want_v, want_l = _reference_state(b, index)
            crashed = b._crash_seen if index is None else b._crash_seen[index]
            live = ~crashed
            assert _same(values[:, live], want_v[:, live]) and np.array_equal(landed[live], want_l[live]), k
            cols = b.state_columns(index)
            assert _same(np.array(cols[:14]), values) and np.array_equal(cols[14], landed)
        b.step(TICK_S)
    assert seen_fix and seen_crash and seen_partial
    assert b.vehicles[2].frozen is not None
    # a crashed vehicle's state columns are its frozen telemetry
    values, landed = np.empty((14, n)), np.empty(n, dtype=bool)
    b.state_into(values, landed)
    tel = b.vehicles[2].frozen
    assert values[:, 2].tolist() == [*tel.pos_ned_m, *tel.vel_ned_m_s, *tel.gnss_ned_m, *tel.true_pos_ned_m,
                                     tel.yaw_rad, tel.battery_frac]
    assert bool(landed[2]) is tel.landed
    assert b.battery_frac()[0] == 0.0   # drained and clipped, as np.clip does
