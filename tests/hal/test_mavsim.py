"""mavsim answers like PX4: the commander in-process, then one vehicle process over UDP."""

from __future__ import annotations

import math
import socket
import subprocess
import sys
import time
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

    def collect(self, seconds: float) -> list[tuple[mc.Packet, object]]:
        out, end = [], time.monotonic() + seconds
        while time.monotonic() < end:
            try:
                data, self.peer = self.sock.recvfrom(65536)
            except TimeoutError:
                continue
            out.extend(self.dec.decode(data))
        return out

    def send(self, data: bytes) -> None:
        assert self.peer is not None
        self.sock.sendto(data, self.peer)

    def command(self, target: int, command: int, *params: float) -> list[mc.CommandAckMsg]:
        self.send(self.enc.command((target, 1), command, params))
        return [v for _, v in self.collect(0.3) if isinstance(v, mc.CommandAckMsg)]


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
    first = gcs.collect(2.0 * 4 / VEHICLE_SPEED)      # 2 s at speed 4: the same simulated time
    assert first, "no traffic from mavsim"
    assert {p.system_id for p, _ in first} == {3} and {p.component_id for p, _ in first} == {1}
    hb = [v for _, v in first if isinstance(v, mc.HeartbeatMsg)]
    assert hb and hb[-1].autopilot and hb[-1].custom_mode == mc.MODE_HOLD and not hb[-1].armed
    assert any(v.ready_to_arm for _, v in first if isinstance(v, mc.SysStatusMsg))
    frame = GeoFrame(47.397742, 8.545594, 488.0)
    glob = [v for _, v in first if isinstance(v, mc.GlobalPositionMsg)][-1]
    assert frame.ned_of(glob.lat_deg, glob.lon_deg, glob.alt_m) == pytest.approx((10.0, -5.0, 0.0), abs=0.3)
    assert {p.msg_id for p, _ in first} >= {mc.MSG["LOCAL_POSITION_NED"], mc.MSG["EXTENDED_SYS_STATE"]}

    # message intervals are honoured (rates in simulation time: 5 Hz x speed x 1.5 s wall)
    att, lpn = mc.MSG["ATTITUDE"], mc.MSG["LOCAL_POSITION_NED"]
    acks = gcs.command(3, mc.CMD_SET_MESSAGE_INTERVAL, att, -1)
    acks += gcs.command(3, mc.CMD_SET_MESSAGE_INTERVAL, lpn, 1e6 / 5)
    assert [a.result for a in acks] == [mc.RESULT_ACCEPTED] * 2 and {a.target_system for a in acks} == {255}
    gcs.dec.skipped_ids.clear()
    window = gcs.collect(1.5)
    counts = {m: sum(1 for p, _ in window if p.msg_id == m) for m in (att, lpn)}
    expected = 5 * VEHICLE_SPEED * 1.5
    assert counts[att] == 0 and 0.7 * expected <= counts[lpn] <= 1.3 * expected, counts
    assert gcs.command(3, mc.CMD_SET_MESSAGE_INTERVAL, 9999, -1)[0].result == mc.RESULT_UNSUPPORTED

    # refusals are NACKs; commands for another system get no answer; garbage is survived
    assert gcs.command(3, mc.CMD_SET_MODE, 1, 6, 0)[0].result == mc.RESULT_TEMPORARILY_REJECTED
    assert gcs.command(3, mc.CMD_TAKEOFF, *(math.nan,) * 6, 500.0)[0].result == mc.RESULT_DENIED
    assert gcs.command(9, mc.CMD_ARM_DISARM, 1.0) == []
    gcs.send(b"\xfd\x09garbage" + bytes(range(40)))
    assert gcs.command(0, mc.CMD_ARM_DISARM, 1.0)[0].result == mc.RESULT_ACCEPTED    # 0: broadcast
    assert any(v.armed for _, v in gcs.collect(1.0) if isinstance(v, mc.HeartbeatMsg))


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
