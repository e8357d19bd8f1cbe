"""The fleet core's setpoint batch (``swarmbox.core.fleet.setpoints``, the sim backend's ``setpoints``)
writes the object core's logs at its edges: setpoints refused and clamped, a velocity held into the
fence's reach, a vehicle disarmed while its drone's hooks run, hooks that return None on some ticks,
several kinds in one tick, a new Setpoint equal to the last and setpoints that change every tick.

Each case flies both cores with the same seed and compares every table exactly (``assert_same_run``),
then checks in the logs that its edge really happened.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from swarmbox.api import DroneAlgorithm, Setpoint
from swarmbox.bench.hover import grid
from swarmbox.core.fleet.setpoints import SetpointBatch
from swarmbox.hal.safety import SafetyLimits
from swarmbox.hal.sim.backend import SimBackend
from swarmbox.testing import Flight
from tests.conftest import table
from tests.core.test_fleet_identity import assert_same_run

#: 40 m fence, jumps over 50 m refused, 4 m/s top speed (a velocity is judged near the fence within
#: 10 m of it); a vehicle armed on the ground disarms after 3 s
LIMITS = ["run.safety.geofence_radius_m=40", "run.safety.max_jump_m=50", "run.safety.max_speed_m_s=4",
          "backend.preflight_disarm_s=3"]
EDGES = ["algo=hover", "mission=hover", "algo.drone._target_=tests.core.test_fleet_setpoints.EdgeDrone",
         *LIMITS]


class EdgeDrone(DroneAlgorithm):
    """Each drone (by id modulo 6) probes one edge of the setpoint path from its 40th execution tick:

    0. holds a point, asks for one 60 m away (refused: jump), then sends a new Setpoint equal to the
       held one every tick for a second, then the held object again;
    1. asks for a point 48 m out, beyond the fence (clamped: geofence), the same object every tick;
    2. flies a velocity towards the fence (passes clear of it, then clamped near it);
    3. returns None on every third tick, an acceleration on every seventh, a velocity otherwise;
    4. a position that changes every tick;
    5. no setpoint for 8 s (armed on the ground, the vehicle disarms: no takeoff; the drone's arming
       retry arms it again), then the held point.
    """

    def exec_once(self, ctx):
        n, e, _ = ctx.home_ned_m
        self.home = (n, e)
        self.role = ctx.id % 6
        self.hold = Setpoint.position(n, e, -3.0)
        self.far = Setpoint.position(n + 60.0, e, -3.0)
        self.out = Setpoint.position(n, e - 48.0, -3.0)
        self.vel = Setpoint.velocity(0.0, -3.0, 0.0)
        self.side = Setpoint.velocity(0.0, 0.5, 0.0)
        self.brake = Setpoint.acceleration(0.0, -0.2, 0.0)

    def exec_loop(self, ctx):
        k, (n, e) = ctx.tick, self.home
        if self.role == 5:
            return None if k < 320 else self.hold
        if k < 40:
            return self.hold
        if self.role == 0:
            if k in (60, 61):
                return self.far
            return Setpoint.position(n, e, -3.0) if 80 <= k < 120 else self.hold
        if self.role == 1:
            return self.out
        if self.role == 2:
            return self.vel
        if self.role == 3:
            return None if k % 3 == 0 else self.brake if k % 7 == 0 else self.side
        return Setpoint.position(n + 2.0 * math.sin(k / 20.0), e, -3.0)

    def exec_complete(self, ctx):
        return ctx.stage_time_s > 16.0


class FailingDrone(EdgeDrone):
    """EdgeDrone whose drone 3 raises in its 100th execution tick: the run fails there."""

    def exec_loop(self, ctx):
        if ctx.id == 3 and ctx.tick == 100:
            raise RuntimeError("drone 3 gives up")
        return super().exec_loop(ctx)


def _events(run_dir: Path, drone: int):
    return table(run_dir, f"drone_{drone}", "events")


def _setpoints(run_dir: Path, drone: int):
    return table(run_dir, f"drone_{drone}", "setpoints")


@pytest.fixture(params=[1, SetpointBatch.SMALL], ids=["arrays", "per-drone"])
def batch_from(request, monkeypatch):
    """From how many setpoints in a tick the fleet hands them over as arrays (1: always)."""
    monkeypatch.setattr(SetpointBatch, "SMALL", request.param)
    return request.param


@pytest.mark.parametrize("network", [[], ["network=wifi", "network.loss_prob=0.1"],
                                     ["fault=clock_skew", "fault.targets=[1,4]", "fault.onset_s=2"]])
def test_setpoint_edges_log_equal_on_both_cores(tmp_path, network, batch_from):
    """With wifi, Heartbeats and Reports arrive late and out of order: drones tick whole some ticks
    (their setpoint handed over in their own tick) and join the batch on others. With a clock fault
    each row carries its own drone's clock."""
    assert_same_run(tmp_path, [*EDGES, "seed=3", *network], grid(6))
    run = tmp_path / "object"
    refused = _setpoints(run, 0)
    assert ((refused["verdict"] == "refused") & (refused["reason"] == "jump")).sum() == 2
    assert (refused["verdict"] == "ok").sum() > 400   # the held point, and the equal ones
    fenced = _setpoints(run, 1)
    assert ((fenced["verdict"] == "clamped") & (fenced["reason"] == "geofence")).sum() > 400
    velocity = _setpoints(run, 2)
    kinds = velocity[velocity["kind"] == "velocity"]
    assert (kinds["verdict"] == "ok").sum() > 100 and (kinds["verdict"] == "clamped").sum() > 20
    assert set(kinds.loc[kinds["verdict"] == "clamped", "reason"]) == {"geofence"}
    mixed = _setpoints(run, 3)
    assert {"position", "velocity", "acceleration"} <= set(mixed["kind"])
    ticks = set(mixed["tick"])
    assert len(ticks) < max(ticks) - min(ticks) + 1   # some ticks without a setpoint
    moving = _setpoints(run, 4)
    assert moving["n"].nunique() > 300
    ev = _events(run, 5)
    disarmed = ev[(ev["name"] == "disarmed") & ev["data"].str.contains("no takeoff")]
    assert len(disarmed) >= 1
    assert len(disarmed) >= 2   # armed again by the drone's retry, and disarmed again
    late = _setpoints(run, 5)
    assert late["tick"].min() > int(disarmed["tick"].iloc[0])   # its first setpoint after the disarm


def test_a_failing_hook_leaves_the_logs_of_the_drones_before_it_as_on_the_object_core(tmp_path, batch_from):
    """The object core ticks drone by drone: when drone 3's hook raises, the ground and drones 0-2
    have sent (and the network routed) that tick's messages and Reports, and drones 0-2 have flown
    and logged their setpoints; drones 4-5 have not. Every table of the failed run must be equal."""
    failing = [*EDGES, "algo.drone._target_=tests.core.test_fleet_setpoints.FailingDrone", "seed=2",
               "network=wifi"]
    obj = assert_same_run(tmp_path, failing, grid(6))
    assert obj["status"] == "failed" and "drone 3 gives up" in obj["reason"]
    last = {i: int(_setpoints(tmp_path / "object", i)["tick"].max()) for i in (0, 2, 4)}
    assert last[0] == last[2] == last[4] + 1
    sent = table(tmp_path / "object", "drone_2", "messages")
    reports = sent[(sent["kind"] == "send") & (sent["type"] == "report")]
    after = table(tmp_path / "object", "drone_4", "messages")
    after = after[(after["kind"] == "send") & (after["type"] == "report")]
    assert int(reports["tick"].max()) == int(after["tick"].max()) + 1   # drone 2 reported in the failing tick


def test_setpoint_edges_of_a_batch_of_36_log_equal_on_both_cores(tmp_path, batch_from):
    """Six drones of each role in one tick: the batch's array tests over many vehicles at once."""
    assert_same_run(tmp_path, [*EDGES, "seed=1"], grid(36))
    run = tmp_path / "object"
    assert (_setpoints(run, 8)["verdict"] == "clamped").sum() > 20   # drone 8: role 2, the velocity
    assert (_setpoints(run, 30)["reason"] == "jump").sum() == 2    # drone 30: role 0


# -- the sim backend's batch entry against its vehicles' own setpoint ------------------------------
TWIN_LIMITS = SafetyLimits(max_speed_m_s=4.0, geofence_radius_m=24.0, max_jump_m=12.0)


def _fleet_in_the_air(n: int) -> SimBackend:
    homes = [(5.0 * (i % 4), 5.0 * (i // 4), 0.0) for i in range(n)]
    b = SimBackend(homes_ned_m=homes, tick_s=0.025, rng=np.random.default_rng(7), limits=TWIN_LIMITS)
    f = Flight(b)
    f.run_until(lambda: all(f.tel(i).ready_to_arm for i in range(n)), 30.0, "ready_to_arm")
    for v in b.vehicles:
        v.arm()
        v.takeoff(3.0)
    f.run_for(6.0)
    return b


def _script(b: SimBackend, held: dict, tick: int) -> list[tuple[int, Setpoint]]:
    """What each vehicle is sent this tick (vehicles left out get nothing): held positions, a new
    equal Setpoint, far points, NaN, velocities that fly into the fence's reach. ``held``: the Setpoint
    objects sent again and again, by key."""
    out = []
    for i, v in enumerate(b.vehicles):
        n, e, _ = v.home_ned_m
        role = i % 6
        if role == 0:
            sp = held.setdefault(i, Setpoint.position(n + 2.0, e, -3.0))
        elif role == 1:   # the same values, a new object, every tick; a 20 m point now and then
            sp = Setpoint.position(n + 20.0, e, -3.0) if tick % 50 == 7 else Setpoint.position(n, e, -4.0)
        elif role == 2:   # out towards the fence, held: fast while clear, judged near it; then back,
            if 290 <= tick < 330:   # silent while it leaves the fence's reach, then the same again
                continue
            away = tick < 170
            sign = 1.0 if away else -1.0
            sp = held.setdefault((i, away), Setpoint.velocity(3.0 * sign, 2.0 * sign, 0.0))
        elif role == 3:   # nothing every other tick; an acceleration otherwise, a NaN once
            if tick % 2:
                continue
            nan = float("nan")
            sp = Setpoint.position(nan, e, -3.0) if tick == 40 else Setpoint.acceleration(0.0, 1.0, 0.0)
        elif role == 4:   # follows a moving point that leaves the jump limit behind
            sp = held.setdefault((i, tick // 30), Setpoint.position(n + 0.5 * tick, e, -3.0))
        else:
            sp = held.setdefault((i, tick > 100), Setpoint.position(n, e + 11.0 if tick > 100 else e, -3.0))
        out.append((i, sp))
    return out


def _autopilot(b: SimBackend) -> list[tuple]:
    """What each vehicle's setpoint handling keeps between calls (its mode, the setpoint flown, the
    last one passed unchanged, the velocity held and whether it came since the last step)."""
    return [(v.mode, v._last_sp, v._last_ok, v._held.requested, v._held.fresh) for v in b.vehicles]


def test_batch_setpoints_do_what_each_vehicles_setpoint_does():
    """Twin fleets: one is sent its setpoints through ``setpoints``, the other vehicle by vehicle; the
    verdicts, the events and the flight (every state array, bit for bit) must stay the same."""
    batch, each = _fleet_in_the_air(12), _fleet_in_the_air(12)
    fast, seen, held, odd_jumps = 0, set(), {}, [0] * 12
    for tick in range(360):
        for fleet in (batch, each):
            if tick == 20:   # vehicle 6's estimate jumps 20 m: its held point is past the jump limit
                fleet.gnss_offset_ned_m[6] = (20.0, 0.0, 0.0)
            if tick == 150:   # vehicle 0 crashes: its held point is ignored from now on
                fleet.crashed[0] = True
        script = _script(batch, held, tick)   # the same objects for both fleets
        index, sps = [i for i, _ in script], [sp for _, sp in script]
        plain = [batch.vehicles[i]._last_ok == sp for i, sp in script]
        odd = dict(batch.setpoints(index, sps))
        verdicts = [each.vehicles[i].setpoint(sp) for i, sp in script]
        expected = {j: v for j, v in enumerate(verdicts) if v.action != "ok" or v.reason}
        assert odd == expected, tick
        assert _autopilot(batch) == _autopilot(each), tick
        seen |= {(v.action, v.reason, v.flown and v.flown.kind.name) for v in expected.values()}
        for j, v in expected.items():
            odd_jumps[index[j]] += v.reason == "jump"
        fast += sum(plain)
        batch.step(0.025)
        each.step(0.025)
        assert batch.drain_events() == each.drain_events(), tick
        np.testing.assert_array_equal(batch.state_columns()[0], each.state_columns()[0])
    for a, b in zip(batch.state_columns(), each.state_columns(), strict=True):
        np.testing.assert_array_equal(a, b)
    assert fast > 1000   # most setpoints took the batch's array test
    assert {("refused", "jump", None), ("refused", "nonfinite", None), ("clamped", "geofence", "POSITION"),
            ("clamped", "geofence", "VELOCITY"), ("ignored", "disarmed", None)} <= seen, seen
    assert odd_jumps[6] > 10, odd_jumps   # vehicle 6's held point, refused once the estimate jumped


@pytest.mark.parametrize("ramp_s", [0.0, 3.0])
def test_batch_supervision_flies_as_each_vehicles_own(ramp_s):
    """Twin fleets take off, one supervised over arrays, the other vehicle by vehicle
    (``batch_supervise``): every state array, ramp limit, event and supervised vehicle stays the
    same. Some vehicles climb OFFBOARD (waiting to lift off, then on their takeoff ramp), some in
    TAKEOFF mode, some press down on the ground until the autopilot disarms them."""
    fleets = []
    homes = [(5.0 * (i % 4), 5.0 * (i // 4), 0.0) for i in range(12)]
    for batch in (True, False):
        b = SimBackend(homes_ned_m=homes, tick_s=0.025, rng=np.random.default_rng(3), limits=TWIN_LIMITS,
                       mpc_tko_ramp_t_s=ramp_s, preflight_disarm_s=5.0)
        b.batch_supervise, b.batch_supervise_from = batch, 1
        f = Flight(b)
        f.run_until(lambda f=f: all(f.tel(i).ready_to_arm for i in range(12)), 30.0, "ready_to_arm")
        fleets.append(b)
    climbs = [Setpoint.position(n, e, -5.0) for n, e, _ in homes]
    down = Setpoint.velocity(0.0, 0.0, 1.0)
    seen, events = {"waiting": 0, "ramp": 0, "land": 0}, []
    for tick in range(700):
        for b in fleets:
            for i, v in enumerate(b.vehicles):
                if tick == 10 * (i % 4):   # armed at different times: ramps at different stages
                    v.arm()
                    if i % 3 == 0:
                        v.takeoff(4.0)   # TAKEOFF mode: supervised vehicle by vehicle
                elif tick == 250 + 5 * (i % 4) and i not in (2, 7):
                    v.land()   # LAND: waits to touch down, then to disarm
                elif 10 * (i % 4) < tick < 250 and i % 3:
                    v.setpoint(down if i in (2, 7) else climbs[i])
            b.step(0.025)
        a, each = fleets
        for x, y in zip(a.state_columns(), each.state_columns(), strict=True):
            np.testing.assert_array_equal(x, y)
        np.testing.assert_array_equal(a.ctrl.tko_up_m_s, each.ctrl.tko_up_m_s)
        assert a.ctrl.ramping == each.ctrl.ramping and a._supervised == each._supervised, tick
        mine = a.drain_events()
        assert mine == each.drain_events(), tick
        events.extend(mine)
        assert [v._been_airborne for v in a.vehicles] == [v._been_airborne for v in each.vehicles]
        for i, v in enumerate(a.vehicles):
            if v.mode.value == "offboard" and v.armed and i in a._supervised:
                seen["ramp" if v._been_airborne else "waiting"] += 1
            seen["land"] += v.mode.value == "land" and v.armed
    assert seen["waiting"] > 100 and (seen["ramp"] > 100) == (ramp_s > 0), seen   # the array path ran
    assert seen["land"] > 1000, seen
    assert not a._supervised and not any(v.armed for v in a.vehicles)   # all landed and disarmed
    disarms = [e.data["reason"] for e in events if e.name == "disarmed"]
    assert sorted(disarms) == ["landed"] * 10 + ["no takeoff"] * 2, disarms
