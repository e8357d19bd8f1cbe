"""mavsim answers like PX4: the commander in-process, then one vehicle process over UDP."""

from __future__ import annotations

import math
import socket
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from swarmbox.api import Setpoint
from swarmbox.hal.mavlink import codec as mc
from swarmbox.hal.mavlink.frames import GeoFrame
from swarmbox.hal.mavsim.commander import Commander
from swarmbox.hal.mavsim.process import VEHICLE_LIMITS, ports_of
from swarmbox.hal.sim.backend import SimBackend
from tests import realtime

ROOT = Path(__file__).resolve().parents[2]
VEHICLE_SPEED = realtime.speed(4.0)   # the vehicle process's pace: 4 on a free machine
DT = 0.01
HOME_ALT = 488.0


def commander(speed: float = 1.0, loss: str = "hold") -> Commander:
    sim = SimBackend(homes_ned_m=[(0.0, 0.0, 0.0)], tick_s=DT, rng=np.random.default_rng(0),
                     limits=VEHICLE_LIMITS)
    return Commander(sim, home_alt_m=HOME_ALT, speed=speed, offboard_loss_action=loss)


def fly(c: Commander, seconds: float, sp: Setpoint | None = None) -> None:
    for _ in range(round(seconds / DT)):
        if sp is not None:
            c.on_setpoint(sp)
        c.step(DT)


def mode(c: Commander, main: int, sub: int = 0) -> int:
    return c.on_command(mc.CMD_SET_MODE, (1.0, main, sub, 0, 0, 0, 0))


ARM = (1.0, 0, 0, 0, 0, 0, 0)


def texts(c: Commander) -> list[str]:
    out = [t for _, t in c.texts]
    c.texts.clear()
    return out


def test_arming_waits_for_the_estimator_then_idles_in_hold():
    c = commander()
    assert not c.ready_to_arm()
    assert c.on_command(mc.CMD_ARM_DISARM, ARM) == mc.RESULT_TEMPORARILY_REJECTED
    assert any(t.startswith("Arming denied") for t in texts(c))
    fly(c, 1.0)
    assert c.ready_to_arm() and c.nav == mc.MODE_HOLD and c.landed_state() == mc.LANDED_ON_GROUND
    assert c.on_command(mc.CMD_ARM_DISARM, ARM) == mc.RESULT_ACCEPTED and c.armed
    assert "Armed by external command" in texts(c)
    assert c.on_command(mc.CMD_ARM_DISARM, ARM) == mc.RESULT_ACCEPTED   # already armed: fine
    fly(c, 11.0)                                                          # COM_DISARM_PRFLT
    assert not c.armed and "Disarmed by auto preflight disarming" in texts(c)


def test_offboard_needs_the_stream_and_falls_back_to_hold_when_it_stops():
    c = commander(speed=2.0)
    fly(c, 1.0)
    assert mode(c, 6) == mc.RESULT_TEMPORARILY_REJECTED                 # no setpoints yet
    sp = Setpoint.position(0.0, 0.0, -3.0)
    c.on_setpoint(sp)
    assert mode(c, 6) == mc.RESULT_ACCEPTED and c.nav == mc.MODE_OFFBOARD
    assert c.on_command(mc.CMD_ARM_DISARM, ARM) == mc.RESULT_ACCEPTED
    fly(c, 8.0, sp)
    tel = c.telemetry()
    assert abs(tel.pos_ned_m[2] + 3.0) < 0.3 and c.landed_state() == mc.LANDED_IN_AIR
    texts(c)
    fly(c, 1.9)                       # loss timeout 1 s x speed 2: not yet
    assert c.nav == mc.MODE_OFFBOARD
    fly(c, 0.3)
    assert c.nav == mc.MODE_HOLD and any("offboard signal lost" in t for t in texts(c))
    fly(c, 3.0)
    assert abs(c.telemetry().pos_ned_m[2] + 3.0) < 0.5    # holds its altitude


def test_takeoff_goes_at_least_to_mis_takeoff_alt_and_ends_in_hold():
    c = commander()
    fly(c, 1.0)
    assert c.on_command(mc.CMD_TAKEOFF, (math.nan,) * 6 + (HOME_ALT + 5,)) == mc.RESULT_DENIED   # disarmed
    c.on_command(mc.CMD_ARM_DISARM, ARM)
    assert c.on_command(mc.CMD_TAKEOFF, (math.nan,) * 6 + (HOME_ALT + 1.0,)) == mc.RESULT_ACCEPTED
    assert any("minimum takeoff altitude" in t for t in texts(c))
    fly(c, 0.5)
    assert c.nav == mc.MODE_TAKEOFF and c.landed_state() == mc.LANDED_TAKEOFF
    fly(c, 6.0)
    assert c.nav == mc.MODE_HOLD and abs(c.telemetry().pos_ned_m[2] + 2.5) < 0.35


def test_land_disarms_by_itself_and_land_mode_prevents_arming():
    c = commander()
    fly(c, 1.0)
    c.on_command(mc.CMD_ARM_DISARM, ARM)
    c.on_command(mc.CMD_TAKEOFF, (math.nan,) * 7)
    fly(c, 5.0)
    assert c.on_command(mc.CMD_ARM_DISARM, (0.0,) * 7) == mc.RESULT_DENIED      # not landed
    assert c.on_command(mc.CMD_LAND, (0.0,) * 7) == mc.RESULT_ACCEPTED and c.nav == mc.MODE_LAND
    fly(c, 1.0)
    assert c.landed_state() == mc.LANDED_LANDING
    fly(c, 8.0)
    assert not c.armed and c.nav == mc.MODE_HOLD and "Disarmed by landing" in texts(c)
    assert mode(c, 4, 6) == mc.RESULT_DENIED          # LAND needs an armed vehicle here
    assert mode(c, 4, 5) == mc.RESULT_DENIED


def test_unknown_commands_and_modes():
    c = commander()
    assert c.on_command(mc.mavlink.MAV_CMD_DO_SET_SERVO, (0.0,) * 7) == mc.RESULT_UNSUPPORTED
    assert c.on_command(mc.CMD_SET_MODE, (0.0, 6, 0, 0, 0, 0, 0)) == mc.RESULT_UNSUPPORTED   # no custom flag
    assert mode(c, 8) == mc.RESULT_DENIED
    with pytest.raises(ValueError):
        commander(loss="explode")


def test_port_plans():
    assert ports_of("px4", 3) == (14543, 14583) and ports_of("px4", 12) == (14549, 14592)
    assert ports_of("50123:0", 7) == (50123, 0)
    with pytest.raises(ValueError):
        ports_of("50123", 0)


# ---- one vehicle process, spoken to over UDP ------------------------------------------------------
#: How long a test waits for what the vehicle must send. The checks wait for the vehicle's own
#: progress (its first packet, an ack, its next heartbeat), never for a fixed wall-clock window, so a
#: loaded machine only makes them slower; this bound only ends a test whose vehicle is stuck.
WAIT_S = 60.0


class Gcs:
    """A minimal ground station on a free port of 127.0.0.1."""

    def __init__(self) -> None:
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", 0))
        self.sock.settimeout(0.05)
        self.port = self.sock.getsockname()[1]
        self.peer: tuple[str, int] | None = None
        self.enc = mc.GcsEncoder()
        self.dec = mc.Decoder(set(mc.DECODERS))

    def receive(self) -> list[tuple[mc.Packet, object]]:
        """What one datagram brought (nothing after 50 ms without one)."""
        try:
            data, self.peer = self.sock.recvfrom(65536)
        except TimeoutError:
            return []
        return list(self.dec.decode(data))

    def collect(self, seconds: float) -> list[tuple[mc.Packet, object]]:
        out, end = [], time.monotonic() + seconds
        while time.monotonic() < end:
            out.extend(self.receive())
        return out

    def until(self, done: Callable[[list], bool], what: str) -> list[tuple[mc.Packet, object]]:
        """Everything received until ``done(everything so far)`` holds; fails after WAIT_S."""
        out: list[tuple[mc.Packet, object]] = []
        end = time.monotonic() + WAIT_S
        while not done(out):
            assert time.monotonic() < end, f"no {what} within {WAIT_S:.0f} s"
            out.extend(self.receive())
        return out

    def heartbeats(self, n: int = 1) -> list[mc.HeartbeatMsg]:
        """The next ``n`` heartbeats (sent once a second of the vehicle's own time)."""
        got = self.until(lambda out: len(of_type(out, mc.HeartbeatMsg)) >= n, f"{n} heartbeat(s)")
        return of_type(got, mc.HeartbeatMsg)

    def ready_to_arm(self) -> list[tuple[mc.Packet, object]]:
        """Everything up to the first SYS_STATUS that says the vehicle is ready to arm."""
        return self.until(lambda out: any(v.ready_to_arm for v in of_type(out, mc.SysStatusMsg)),
                          "ready to arm")

    def send(self, data: bytes) -> None:
        assert self.peer is not None
        self.sock.sendto(data, self.peer)

    def command(self, target: int, command: int, *params: float) -> list[mc.CommandAckMsg]:
        """Sends a command; returns every ack received up to the first one for this command."""
        self.send(self.enc.command((target, 1), command, params))
        got = self.until(lambda out: any(a.command == command for a in of_type(out, mc.CommandAckMsg)),
                         f"ack of command {command}")
        return of_type(got, mc.CommandAckMsg)


def of_type(packets: list[tuple[mc.Packet, object]], kind: type) -> list:
    return [v for _, v in packets if isinstance(v, kind)]


@pytest.fixture
def vehicle():
    gcs = Gcs()
    cmd = [sys.executable, "-m", "swarmbox.hal.mavsim.process", "--instance", "2",
           "--home-n", "10", "--home-e", "-5",
           "--port-plan", f"{gcs.port}:0", "--speed", str(VEHICLE_SPEED), "--max-wall-s", "60"]
    proc = subprocess.Popen(cmd, cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    try:
        yield gcs
    finally:
        proc.terminate()
        _, err = proc.communicate(timeout=10)
        gcs.sock.close()
        assert proc.returncode == 0, err.decode()


@pytest.mark.slow
def test_vehicle_speaks_px4(vehicle):
    gcs = vehicle
    first = gcs.ready_to_arm()     # the estimator is ready one second (vehicle time) after start
    assert {p.system_id for p, _ in first} == {3} and {p.component_id for p, _ in first} == {1}
    hb = gcs.heartbeats()
    assert hb[-1].autopilot and hb[-1].custom_mode == mc.MODE_HOLD and not hb[-1].armed
    frame = GeoFrame(47.397742, 8.545594, 488.0)
    glob = of_type(first, mc.GlobalPositionMsg)[-1]
    assert frame.ned_of(glob.lat_deg, glob.lon_deg, glob.alt_m) == pytest.approx((10.0, -5.0, 0.0), abs=0.3)
    assert {p.msg_id for p, _ in first} >= {mc.MSG["LOCAL_POSITION_NED"], mc.MSG["EXTENDED_SYS_STATE"]}

    # message intervals are honoured, in the vehicle's own time (its time_boot stamps), at any pace
    att, lpn = mc.MSG["ATTITUDE"], mc.MSG["LOCAL_POSITION_NED"]
    acks = gcs.command(3, mc.CMD_SET_MESSAGE_INTERVAL, att, -1)
    acks += gcs.command(3, mc.CMD_SET_MESSAGE_INTERVAL, lpn, 1e6 / 5)
    assert [a.result for a in acks] == [mc.RESULT_ACCEPTED] * 2 and {a.target_system for a in acks} == {255}
    gcs.dec.skipped_ids.clear()   # ATTITUDE is not decoded here: counted among the skipped ids
    got = gcs.until(lambda out: len(of_type(out, mc.LocalPositionMsg)) >= 12, "LOCAL_POSITION_NED")
    stamps = [v.time_boot_s for v in of_type(got, mc.LocalPositionMsg)]
    assert 10 / (stamps[11] - stamps[1]) == pytest.approx(5.0, rel=0.05)   # the first: old schedule
    assert gcs.dec.skipped_ids.get(att, 0) == 0
    assert gcs.command(3, mc.CMD_SET_MESSAGE_INTERVAL, 9999, -1)[0].result == mc.RESULT_UNSUPPORTED

    # refusals are NACKs; commands for another system get no answer; garbage is survived
    assert gcs.command(3, mc.CMD_SET_MODE, 1, 6, 0)[0].result == mc.RESULT_TEMPORARILY_REJECTED
    assert gcs.command(3, mc.CMD_TAKEOFF, *(math.nan,) * 6, 500.0)[0].result == mc.RESULT_DENIED
    gcs.send(gcs.enc.command((9, 1), mc.CMD_ARM_DISARM, (1.0,)))
    gcs.send(b"\xfd\x09garbage" + bytes(range(40)))
    # the vehicle reads in order: acks up to the next command's show whether system 9's was answered
    acks = gcs.command(0, mc.CMD_ARM_DISARM, 1.0)                                       # 0: broadcast
    assert [a.result for a in acks] == [mc.RESULT_ACCEPTED]
    assert gcs.heartbeats()[-1].armed


def test_sim_params_on_the_command_line_keep_their_types():
    """``--sim-param KEY=VALUE`` (what the mavsim backend passes for ``backend.sim``) by SimParams' types."""
    from swarmbox.hal.mavsim.process import sim_params_of

    params = sim_params_of(["land_at_stop_point=True", "acc_hor_max_offboard=false", "physics_substeps=2",
                            "mass_kg=2"])
    assert params == {"jit": "never", "land_at_stop_point": True, "acc_hor_max_offboard": False,
                      "physics_substeps": 2, "mass_kg": 2.0}
    assert type(params["physics_substeps"]) is int
    with pytest.raises(ValueError, match="'land_at_stop_point' must be true or false, got 'maybe'"):
        sim_params_of(["land_at_stop_point=maybe"])
