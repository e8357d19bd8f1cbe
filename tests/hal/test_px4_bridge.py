"""The px4 bridge over real UDP sockets on 127.0.0.1, against mavsim vehicles.

The vehicles run at speed 4 while the conformance suite's driver keeps wall-clock time: positions,
velocities and modes do not depend on it, and every check gets done four times sooner.
"""

from __future__ import annotations

import math
import signal
import socket

import numpy as np
import pytest

from swarmbox.api import FlightMode, Setpoint
from swarmbox.hal.mavlink import codec as mc
from swarmbox.hal.mavsim.backend import MavsimBackend
from swarmbox.hal.px4.backend import Px4Backend, Px4Params, boot_clock_fit
from swarmbox.testing import BACKEND_CHECKS, Flight

SPEED = 4.0


def fleet(homes, **kw) -> MavsimBackend:
    kw.setdefault("speed", SPEED)
    return MavsimBackend(homes_ned_m=list(homes), tick_s=0.025, rng=np.random.default_rng(1), **kw)


#: checks that fly for several seconds of wall time: with the end-to-end tests (pytest -m slow)
LONG = {"check_hold_stops", "check_return_to_launch", "check_mission_cycle",
        "check_nonfinite_setpoint_refused", "check_held_velocity_fence"}


@pytest.mark.parametrize("check", [pytest.param(c, marks=pytest.mark.slow) if c.__name__ in LONG else c
                                   for c in BACKEND_CHECKS], ids=lambda c: c.__name__)
def test_conformance(check):
    check(fleet)


@pytest.fixture
def one():
    backend = fleet([(0.0, 0.0, 0.0)], link_timeout_s=2.0, command_retries=1)
    try:
        yield backend
    finally:
        backend.close()


def names(f: Flight, kind: str) -> list[str]:
    return [e.name for e in f.events if e.kind == kind]


@pytest.mark.slow
def test_unexpected_traffic_is_logged_and_survived(one):
    f, v = Flight(one), one.vehicles[0]
    f.run_until(lambda: f.tel().ready_to_arm, 10.0, "ready")
    v.takeoff(3.0)                                  # NACKed while disarmed, asked again, then given up
    f.run_until(lambda: any(e.name == "nack" for e in f.events), 5.0, "nack")
    nack = [e for e in f.events if e.name == "nack"]
    assert nack and nack[0].kind == "command" and nack[0].data["result"] == "denied"
    assert nack[0].data["command"] == "takeoff"
    f.airborne(0)
    intruder = mc.GcsEncoder(system_id=42, component_id=1)
    liar = mc.mavlink.MAVLink(None, srcSystem=42, srcComponent=1)
    wrong = liar.local_position_ned_encode(0, 500.0, 500.0, -80.0, 9.0, 9.0, 9.0).pack(liar)
    port = one.local_ports[0]
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        for k in range(20):
            s.sendto(b"\x00\x01garbage\xfd\x05" + bytes(range(k, k + 30)), ("127.0.0.1", port))
            s.sendto(intruder.heartbeat() + bytes(wrong), ("127.0.0.1", port))
            f.run_for(0.05)
    f.run_for(1.5)
    assert "garbage" in names(f, "link") and "foreign_system" in names(f, "link")
    foreign = [e for e in f.events if e.name == "foreign_system"][0]
    assert foreign.data["system_id"] == 42
    tel = f.tel()
    assert math.dist(tel.pos_ned_m, (0.0, 0.0, -3.0)) < 0.7, "a foreign LOCAL_POSITION_NED leaked in"
    assert not f.events_of(0, "safety") and "lost" not in names(f, "link")
    stats = one.link_stats()[0]
    assert stats["foreign_packets"] >= 40 and stats["garbage_bytes"] > 0
    # still fully commandable
    target = (4.0, 0.0, -3.0)
    f.run_until(lambda: math.dist(f.tel().pos_ned_m, target) < 0.7, 20.0, "fly after the noise",
                lambda: v.setpoint(Setpoint.position(*target)))
    assert f.tel().mode is FlightMode.OFFBOARD
    f.land_and_disarm(0)


@pytest.mark.slow
def test_silent_vehicle_is_declared_lost_then_regained():
    backend = fleet([(0.0, 0.0, 0.0)], link_timeout_s=2.0, command_timeout_s=0.5, command_retries=1)
    f, v = Flight(backend), backend.vehicles[0]
    try:
        f.airborne(0)
        sp = Setpoint.position(4.0, 0.0, -3.0)
        f.run_for(1.0, lambda: v.setpoint(sp))
        radio = backend.processes[0]
        radio.send_signal(signal.SIGUSR1)                 # its radio goes silent; it flies on
        t_frozen = f.tel().t_s
        f.run_until(lambda: "lost" in names(f, "link"), 6.0, "link lost", lambda: v.setpoint(sp))
        lost = [e for e in f.events if e.name == "lost"][0]
        assert lost.data["silent_s"] >= 2.0 and lost.data["armed"]
        tel = f.tel()
        assert tel.t_s <= t_frozen + 0.5 and not tel.ready_to_arm    # telemetry frozen, marked
        assert not tel.link_ok
        f.run_for(0.2, lambda: v.setpoint(sp))
        assert "setpoint_ignored" in names(f, "command")
        v.return_to_launch()                              # a failsafe's command, into the silence
        f.run_until(lambda: "timeout" in names(f, "command"), 5.0, "command timeout")
        radio.send_signal(signal.SIGUSR1)
        f.run_until(lambda: "regained" in names(f, "link"), 6.0, "link regained")
        f.run_until(lambda: f.tel().mode is FlightMode.RTL, 3.0, "RTL sent again once the link is back")
        f.run_until(lambda: f.tel().landed and not f.tel().armed, 40.0, "RTL landed + disarmed")
        assert math.dist(f.tel().pos_ned_m[:2], (0.0, 0.0)) < 1.0
    finally:
        backend.close()


def test_only_requested_streams_arrive(one):
    f = Flight(one)
    f.run_for(2.0)
    link = one._links[0]
    skipped = dict(link.decoder.skipped_ids)
    assert mc.MSG["ATTITUDE"] in skipped                     # mavsim streams it by default at 100 Hz
    f.run_for(1.0)
    assert link.decoder.skipped_ids[mc.MSG["ATTITUDE"]] - skipped[mc.MSG["ATTITUDE"]] < 5   # silenced
    before = link.decoder.decoded
    f.run_for(1.5)
    per_s = (link.decoder.decoded - before) / 1.5 / SPEED    # per second of vehicle time
    assert 50 < per_s < 60, per_s     # the requested 30 + 10 + 10 + 2 + 2, and a heartbeat


def test_params_fail_early_and_clearly():
    with pytest.raises(TypeError, match="unknown px4 backend parameter 'conection'"):
        Px4Params.from_kwargs({"conection": "udpin:127.0.0.1:14540"})
    with pytest.raises(ValueError, match="setpoint_rate_hz"):
        Px4Params.from_kwargs({"setpoint_rate_hz": 5})
    with pytest.raises(ValueError, match="unknown MAVLink messages"):
        Px4Params.from_kwargs({"message_rates_hz": {"NOT_A_MESSAGE": 1}})
    with pytest.raises(ValueError, match="mavsim backend"):
        fleet([(0.0, 0.0, 0.0)], offboard_loss="explode")
    with pytest.raises(TypeError, match="unknown sim backend parameter"):
        fleet([(0.0, 0.0, 0.0)], sim={"mass": 2.0})


def test_silent_address_times_out_naming_the_vehicle():
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    with pytest.raises(TimeoutError, match=rf"\(0, 'udpin:127.0.0.1:{port}'\)"):
        Px4Backend(homes_ned_m=[(0.0, 0.0, 0.0)], tick_s=0.025, rng=np.random.default_rng(0),
                   connections=[f"udpin:127.0.0.1:{port}"], connect_timeout_s=0.3)


def test_boot_clock_fit_uses_the_least_delayed_arrivals():
    boot = np.arange(0.0, 20.0, 1.0)
    delay = np.where(np.arange(20) % 3 == 0, 0.0, 0.04)
    a, b = boot_clock_fit(list(zip(boot, 5.0 - 0.001 * boot + delay, strict=True)))
    assert b == pytest.approx(0.999, abs=2e-3) and a == pytest.approx(5.0, abs=0.03)
    assert boot_clock_fit([]) == (0.0, 1.0) and boot_clock_fit([(3.0, 2.0)]) == (2.0, 1.0)
