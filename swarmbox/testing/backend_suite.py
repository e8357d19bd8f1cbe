"""Conformance suite every :class:`~swarmbox.hal.vehicle.Backend` must pass.

Each check is a plain function taking a *factory* — ``factory(homes_ned_m, **backend_kw) -> Backend``,
where the fence checks pass ``limits=`` (a :class:`~swarmbox.hal.safety.SafetyLimits`) — builds a
fresh fleet, flies it through one scenario and asserts numeric properties of the telemetry and
events. Use them from pytest::

    from swarmbox.testing import BACKEND_CHECKS

    @pytest.mark.parametrize("check", BACKEND_CHECKS, ids=lambda c: c.__name__)
    def test_my_backend(check):
        check(lambda homes: MyBackend(homes_ned_m=homes, ...))

Scenarios (two vehicles; the second is never commanded and must stay disarmed at home):

- ``check_protocol`` — the objects satisfy the protocols; a fresh vehicle is disarmed and landed.
- ``check_mission_cycle`` — arm → takeoff → position setpoint reached → velocity setpoint followed →
  land → landed and disarmed.
- ``check_return_to_launch`` — RTL flies home without losing height, lands and disarms.
- ``check_nonfinite_setpoint_refused`` — NaN/inf setpoints raise a ``safety`` event and the vehicle
  keeps its previous target.
- ``check_setpoint_verdicts`` — ``setpoint`` returns the safety monitor's verdict (ok, clamped or
  refused, with the reason) for every setpoint: what the framework writes to ``setpoints.parquet``.
- ``check_velocity_fence``, ``check_acceleration_fence`` — a velocity / an acceleration flying out and
  up stays within a 12 m geofence (+1 m) and a 7 m ceiling (+0.5 m); verdicts ``clamped``, events logged.
- ``check_held_velocity_fence`` — the same for a velocity sent for 1 s and then held, never sent again.
- ``check_hold_stops`` — ``hold()`` brakes a moving vehicle and keeps it still.
- ``check_disarmed_setpoint_ignored`` — setpoints to a disarmed vehicle move nothing.

Tolerances follow what PX4 SITL achieves (about 0.5 m on altitude, 0.7 m on positions).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence

from swarmbox.api import FlightMode, Setpoint, SetpointVerdict, Telemetry
from swarmbox.hal.safety import SafetyLimits
from swarmbox.hal.vehicle import Backend, Vehicle, VehicleEvent

Vec3 = tuple[float, float, float]
BackendFactory = Callable[[Sequence[Vec3]], Backend]

HOMES: tuple[Vec3, Vec3] = ((0.0, 0.0, 0.0), (0.0, 6.0, 0.0))
TAKEOFF_ALT_M = 3.0
POS_TOL_M = 0.7
ALT_TOL_M = 0.5
SLOW_M_S = 0.7


class Flight:
    """Drives a backend on its own clock (paced on the wall clock when ``realtime``)."""

    def __init__(self, backend: Backend, tick_s: float = 0.025) -> None:
        self.backend, self.tick_s, self.t_s = backend, tick_s, 0.0
        self.events: list[VehicleEvent] = []
        self._wall0 = time.perf_counter()

    def tel(self, i: int = 0) -> Telemetry:
        return self.backend.vehicles[i].telemetry()

    def step(self, each_tick: Callable[[], None] | None = None) -> None:
        if each_tick is not None:
            each_tick()
        self.backend.step(self.tick_s)
        self.events.extend(self.backend.drain_events())
        self.t_s += self.tick_s
        if self.backend.realtime:
            ahead = self.t_s - (time.perf_counter() - self._wall0)
            if ahead > 0:
                time.sleep(ahead)

    def run_for(self, seconds: float, each_tick: Callable[[], None] | None = None) -> None:
        for _ in range(max(1, round(seconds / self.tick_s))):
            self.step(each_tick)

    def run_until(self, done: Callable[[], bool], timeout_s: float, what: str,
                  each_tick: Callable[[], None] | None = None) -> float:
        """Step until ``done()``; returns the time it took, fails with ``what`` on timeout."""
        start = self.t_s
        while not done():
            assert self.t_s - start < timeout_s, f"{what}: not reached within {timeout_s} s"
            self.step(each_tick)
        return self.t_s - start

    def events_of(self, i: int, kind: str) -> list[VehicleEvent]:
        return [e for e in self.events if e.drone_id == i and e.kind == kind]

    def airborne(self, i: int = 0, alt_m: float = TAKEOFF_ALT_M) -> None:
        """Arm vehicle ``i``, take off to ``alt_m`` and wait until it hovers there."""
        v = self.backend.vehicles[i]
        self.run_until(lambda: self.tel(i).ready_to_arm, 30.0, "ready_to_arm")
        self.run_until(lambda: self.tel(i).armed, 10.0, "armed", v.arm)
        v.takeoff(alt_m)
        self.run_until(lambda: (abs(-self.tel(i).pos_ned_m[2] - alt_m) < ALT_TOL_M
                                and speed(self.tel(i)) < SLOW_M_S and self.tel(i).mode is FlightMode.HOLD),
                       40.0, f"takeoff to {alt_m} m")

    def land_and_disarm(self, i: int = 0, timeout_s: float = 60.0) -> None:
        self.backend.vehicles[i].land()
        self.run_until(lambda: self.tel(i).landed and not self.tel(i).armed, timeout_s, "landed + disarmed")


def speed(tel: Telemetry) -> float:
    return math.hypot(*tel.vel_ned_m_s)


def offset(home: Sequence[float], dn: float, de: float, d: float) -> Vec3:
    return (home[0] + dn, home[1] + de, d)


def _fleet(factory: BackendFactory) -> Backend:
    return factory(list(HOMES))


def _assert_untouched(f: Flight, i: int = 1) -> None:
    tel = f.tel(i)
    assert not tel.armed and tel.landed, f"vehicle {i} was never commanded but is armed or airborne"
    assert math.dist(tel.pos_ned_m[:2], HOMES[i][:2]) < ALT_TOL_M, f"vehicle {i} moved: {tel.pos_ned_m}"


def check_protocol(factory: BackendFactory) -> None:
    """The fleet satisfies the protocols, in home order; a fresh vehicle is disarmed on the ground."""
    backend = _fleet(factory)
    try:
        assert isinstance(backend, Backend) and isinstance(backend.realtime, bool)
        assert len(backend.vehicles) == len(HOMES)
        for i, v in enumerate(backend.vehicles):
            assert isinstance(v, Vehicle) and v.drone_id == i
            assert tuple(v.home_ned_m) == HOMES[i]
            tel = v.telemetry()
            assert isinstance(tel, Telemetry) and not tel.armed and tel.landed
            assert math.dist(tel.pos_ned_m, HOMES[i]) < ALT_TOL_M and speed(tel) < 0.1
        assert isinstance(backend.drain_events(), list)
    finally:
        backend.close()
    backend.close()   # safe twice


def check_mission_cycle(factory: BackendFactory, tick_s: float = 0.025) -> None:
    """arm → takeoff → position setpoint → velocity setpoint → land → landed and disarmed."""
    backend = _fleet(factory)
    f, v, home = Flight(backend, tick_s), backend.vehicles[0], HOMES[0]
    try:
        f.airborne(0)
        target = offset(home, 6.0, 0.0, -TAKEOFF_ALT_M)
        sp = Setpoint.position(*target)
        f.run_until(lambda: math.dist(f.tel().pos_ned_m, target) < POS_TOL_M and speed(f.tel()) < SLOW_M_S,
                    40.0, "position setpoint", lambda: v.setpoint(sp))
        assert f.tel().mode is FlightMode.OFFBOARD
        n0 = f.tel().pos_ned_m[0]
        vel = Setpoint.velocity(1.0, 0.0, 0.0)
        f.run_for(2.0, lambda: v.setpoint(vel))
        samples: list[float] = []
        f.run_for(1.0, lambda: (v.setpoint(vel), samples.append(f.tel().vel_ned_m_s[0])))
        assert abs(sum(samples) / len(samples) - 1.0) < 0.3, f"north speed {sum(samples) / len(samples)}"
        assert f.tel().pos_ned_m[0] - n0 > 2.0, "velocity setpoint did not move the vehicle"
        assert abs(-f.tel().pos_ned_m[2] - TAKEOFF_ALT_M) < ALT_TOL_M, "altitude not held"
        at = f.tel().pos_ned_m
        f.land_and_disarm(0)
        tel = f.tel()
        assert tel.mode is FlightMode.IDLE and -tel.pos_ned_m[2] < ALT_TOL_M
        assert math.dist(tel.pos_ned_m[:2], at[:2]) < 1.5, "drifted while landing"
        assert not f.events_of(0, "safety"), f"nominal commands tripped the safety monitor: {f.events}"
        _assert_untouched(f)
    finally:
        backend.close()


def check_return_to_launch(factory: BackendFactory, tick_s: float = 0.025) -> None:
    """RTL returns home without descending on the way, lands and disarms."""
    backend = _fleet(factory)
    f, v, home = Flight(backend, tick_s), backend.vehicles[0], HOMES[0]
    try:
        f.airborne(0)
        away = offset(home, 10.0, -5.0, -4.0)
        sp = Setpoint.position(*away)
        f.run_until(lambda: math.dist(f.tel().pos_ned_m, away) < POS_TOL_M, 40.0, "fly away",
                    lambda: v.setpoint(sp))
        alt0 = -f.tel().pos_ned_m[2]
        v.return_to_launch()
        low: list[float] = []

        def watch() -> None:
            tel = f.tel()
            if math.dist(tel.pos_ned_m[:2], home[:2]) > 2.0 and -tel.pos_ned_m[2] < alt0 - ALT_TOL_M:
                low.append(-tel.pos_ned_m[2])

        f.run_until(lambda: f.tel().landed and not f.tel().armed, 120.0, "RTL landed + disarmed", watch)
        assert not low, f"descended to {min(low):.2f} m while still away from home"
        tel = f.tel()
        assert math.dist(tel.pos_ned_m[:2], home[:2]) < 1.0, f"landed at {tel.pos_ned_m}, home {home}"
        _assert_untouched(f)
    finally:
        backend.close()


def check_nonfinite_setpoint_refused(factory: BackendFactory, tick_s: float = 0.025) -> None:
    """NaN / inf setpoints are refused with a safety event; the previous target is kept."""
    backend = _fleet(factory)
    f, v, home = Flight(backend, tick_s), backend.vehicles[0], HOMES[0]
    try:
        f.airborne(0)
        target = offset(home, 0.0, 0.0, -TAKEOFF_ALT_M)
        good = Setpoint.position(*target)
        f.run_for(1.0, lambda: v.setpoint(good))
        bad = (Setpoint.position(math.nan, 0.0, -3.0), Setpoint.velocity(math.inf, 0.0, 0.0),
               Setpoint.acceleration(0.0, -math.inf, 0.0), Setpoint.position(*target, yaw_rad=math.nan))
        k = iter(range(10**9))
        f.run_for(3.0, lambda: v.setpoint(bad[next(k) % len(bad)]))
        refused = [e for e in f.events_of(0, "safety") if e.name == "setpoint_refused"]
        assert refused, f"no setpoint_refused safety event: {f.events}"
        tel = f.tel()
        assert all(math.isfinite(x) for x in tel.pos_ned_m + tel.vel_ned_m_s)
        assert math.dist(tel.pos_ned_m, target) < POS_TOL_M, f"left its target: {tel.pos_ned_m}"
        f.land_and_disarm(0)
    finally:
        backend.close()


def check_hold_stops(factory: BackendFactory, tick_s: float = 0.025) -> None:
    """``hold()`` brakes a moving vehicle and then keeps it in place."""
    backend = _fleet(factory)
    f, v = Flight(backend, tick_s), backend.vehicles[0]
    try:
        f.airborne(0)
        vel = Setpoint.velocity(3.0, 0.0, 0.0)
        f.run_for(3.0, lambda: v.setpoint(vel))
        assert speed(f.tel()) > 2.0, "did not pick up speed"
        v.hold()
        f.run_until(lambda: speed(f.tel()) < 0.3, 15.0, "stop after hold()")
        assert f.tel().mode is FlightMode.HOLD
        at = f.tel().pos_ned_m
        f.run_for(3.0)
        assert math.dist(f.tel().pos_ned_m, at) < 0.5, "drifted while holding"
        f.land_and_disarm(0)
    finally:
        backend.close()


def check_disarmed_setpoint_ignored(factory: BackendFactory, tick_s: float = 0.025) -> None:
    """Setpoints sent to a disarmed vehicle do not arm or move it."""
    backend = _fleet(factory)
    f, v, home = Flight(backend, tick_s), backend.vehicles[0], HOMES[0]
    try:
        f.run_until(lambda: f.tel().ready_to_arm, 30.0, "ready_to_arm")
        sp = Setpoint.position(*offset(home, 0.0, 0.0, -TAKEOFF_ALT_M))
        f.run_for(2.0, lambda: v.setpoint(sp))
        tel = f.tel()
        assert not tel.armed and tel.landed and -tel.pos_ned_m[2] < ALT_TOL_M
        assert math.dist(tel.pos_ned_m[:2], home[:2]) < ALT_TOL_M
    finally:
        backend.close()


def check_setpoint_verdicts(factory: BackendFactory, tick_s: float = 0.025) -> None:
    """Every setpoint gets a verdict: ok, clamped (geofence, ceiling, floor, speed, accel) or refused
    (non-finite, absurd jump), each but ok with its reason code."""
    backend = _fleet(factory)
    f, v, home = Flight(backend, tick_s), backend.vehicles[0], HOMES[0]
    try:
        f.airborne(0)
        hold = Setpoint.position(*offset(home, 0.0, 0.0, -TAKEOFF_ALT_M))
        cases = [(hold, "ok", ""),
                 (Setpoint.position(math.nan, 0.0, -3.0), "refused", "nonfinite"),
                 (Setpoint.position(home[0] + 1500.0, home[1], -3.0), "refused", "jump"),
                 (Setpoint.position(home[0], home[1] + 600.0, -3.0), "clamped", "geofence"),
                 (Setpoint.position(home[0], home[1], -200.0), "clamped", "ceiling"),
                 (Setpoint.position(home[0], home[1], 3.0), "clamped", "floor"),
                 (Setpoint.velocity(0.0, 100.0, 0.0), "clamped", "speed"),
                 (Setpoint.acceleration(0.0, 100.0, 0.0), "clamped", "accel")]
        for sp, action, reason in cases:
            verdict = v.setpoint(sp)
            assert isinstance(verdict, SetpointVerdict), f"setpoint returned {verdict!r}, not a verdict"
            assert verdict.action == action and reason in verdict.reason, (sp, verdict)
            assert (verdict.flown is None) == (action == "refused"), verdict
            f.run_for(tick_s, lambda: v.setpoint(hold))
        f.land_and_disarm(0)
    finally:
        backend.close()


#: the envelope the fence checks fly against: small, so that a vehicle reaches it in seconds
FENCE = SafetyLimits(geofence_radius_m=12.0, max_alt_m=7.0)
FENCE_TOL_M, CEILING_TOL_M = 1.0, 0.5


def _check_envelope(factory: BackendFactory, sp: Setpoint, fly_s: float, tick_s: float,
                    send_s: float = math.inf) -> None:
    """Fly ``sp`` (outward and upward) for ``fly_s``, sent every tick for ``send_s`` and then held: the
    vehicle stays within FENCE (+ tolerance), the verdicts turn ``clamped`` naming geofence and
    ceiling, and safety events say so."""
    backend = factory(list(HOMES), limits=FENCE)
    f, v = Flight(backend, tick_s), backend.vehicles[0]
    verdicts: list[SetpointVerdict] = [v.setpoint(sp)] if send_s < math.inf else []
    reach = [0.0, 0.0]   # the largest radius and altitude seen
    start = [-1.0]

    def fly() -> None:
        start[0] = f.t_s if start[0] < 0 else start[0]
        if f.t_s - start[0] < send_s:
            verdicts.append(v.setpoint(sp))
        n, e, d = f.tel().pos_ned_m
        reach[0], reach[1] = max(reach[0], math.hypot(n, e)), max(reach[1], -d)

    try:
        f.airborne(0)
        f.run_for(fly_s, fly)
        assert reach[0] <= FENCE.geofence_radius_m + FENCE_TOL_M, f"flew to radius {reach[0]:.2f} m"
        assert reach[1] <= FENCE.max_alt_m + CEILING_TOL_M, f"climbed to {reach[1]:.2f} m"
        assert reach[0] > FENCE.geofence_radius_m - 2.0 and reach[1] > FENCE.max_alt_m - 1.0, (
            f"never came near the envelope: radius {reach[0]:.2f} m, altitude {reach[1]:.2f} m")
        if send_s == math.inf:   # held at both boundaries: the last second's verdicts say so
            recent = verdicts[-max(1, round(1.0 / tick_s)):]
            codes = {code for v in recent for code in v.reason.split("+")}
            clamped = sum(v.action == "clamped" for v in recent)   # an acceleration may swing back in
            assert 2 * clamped >= len(recent) and {"geofence", "ceiling"} <= codes, recent[-1]
        codes = {e.data.get("reason") for e in f.events_of(0, "safety") if e.name == "setpoint_clamped"}
        assert any("geofence" in c for c in codes) and any("ceiling" in c for c in codes), codes
        f.land_and_disarm(0)
        _assert_untouched(f)
    finally:
        backend.close()


def check_velocity_fence(factory: BackendFactory, tick_s: float = 0.025) -> None:
    """A velocity flying out through the geofence and up through the ceiling is stopped at both."""
    _check_envelope(factory, Setpoint.velocity(5.0, 0.0, -2.0), 10.0, tick_s)


def check_acceleration_fence(factory: BackendFactory, tick_s: float = 0.025) -> None:
    """An acceleration flying out through the geofence and up through the ceiling is stopped at both."""
    _check_envelope(factory, Setpoint.acceleration(2.0, 0.0, -1.0), 12.0, tick_s)


def check_held_velocity_fence(factory: BackendFactory, tick_s: float = 0.025) -> None:
    """A velocity sent for 1 s and then no more (the vehicle keeps flying it) is stopped at both too."""
    _check_envelope(factory, Setpoint.velocity(5.0, 0.0, -2.0), 10.0, tick_s, send_s=1.0)


BACKEND_CHECKS: tuple[Callable[..., None], ...] = (
    check_protocol, check_mission_cycle, check_return_to_launch, check_nonfinite_setpoint_refused,
    check_hold_stops, check_disarmed_setpoint_ignored, check_setpoint_verdicts, check_velocity_fence,
    check_acceleration_fence, check_held_velocity_fence,
)


def run_backend_suite(factory: BackendFactory) -> None:
    """Run every check against ``factory`` (raises AssertionError at the first failure)."""
    for check in BACKEND_CHECKS:
        check(factory)

