"""MAVLink <-> SwarmBox conversions, framing, and COMMAND_LONG ack/retry: no sockets, no processes."""

from __future__ import annotations

import math

import pytest

from swarmbox.api import FlightMode, Setpoint, SetpointKind
from swarmbox.hal.mavlink import codec as mc
from swarmbox.hal.mavlink.frames import EARTH_RADIUS_M, GeoFrame, VehicleFrame
from swarmbox.hal.mavlink.link import Command, CommandTracker, parse_connection

SPO = mc.MSG["SET_POSITION_TARGET_LOCAL_NED"]


def roundtrip(sp: Setpoint) -> mc.SetpointTargetMsg:
    buf = mc.GcsEncoder().setpoint((3, 1), 1234, sp)
    [(pkt, value)] = list(mc.Decoder({SPO}).decode(buf))
    assert (pkt.system_id, pkt.component_id, pkt.msg_id) == (255, 190, SPO)
    return value


def test_custom_modes_match_px4():
    # the numbers PX4 reports in HEARTBEAT.custom_mode (px4-mavlink-facts.md)
    assert mc.MODE_OFFBOARD == 393216 and mc.MODE_HOLD == 50593792 and mc.MODE_LAND == 100925440
    assert mc.MODE_RTL == 84148224 and mc.MODE_TAKEOFF == 33816576 and mc.MODE_POSCTL == 196608
    assert mc.px4_main_sub(mc.MODE_LAND) == (4, 6)
    assert mc.mode_name(mc.MODE_HOLD) == "AUTO.LOITER" and mc.mode_name(mc.px4_mode(9, 1)) == "9.1"


@pytest.mark.parametrize(("custom", "armed", "landed", "expected"), [
    (mc.MODE_OFFBOARD, False, True, FlightMode.IDLE),
    (mc.MODE_HOLD, True, True, FlightMode.IDLE),
    (mc.MODE_HOLD, True, False, FlightMode.HOLD),
    (mc.MODE_OFFBOARD, True, True, FlightMode.OFFBOARD),
    (mc.MODE_TAKEOFF, True, False, FlightMode.TAKEOFF),
    (mc.MODE_LAND, True, False, FlightMode.LAND),
    (mc.MODE_RTL, True, False, FlightMode.RTL),
    (mc.MODE_POSCTL, True, False, FlightMode.HOLD),
])
def test_flight_mode_of_px4_state(custom, armed, landed, expected):
    assert mc.flight_mode(custom, armed, landed) is expected


def test_type_masks_select_exactly_one_vector_and_yaw():
    assert mc.type_mask(Setpoint.position(1, 2, -3, 0.5)) == 2552       # PX4 docs / facts: position + yaw
    assert mc.type_mask(Setpoint.position(1, 2, -3)) == 3576            # + YAW_IGNORE
    assert mc.type_mask(Setpoint.velocity(1, 0, 0, 0.0)) == 0b100111000111
    assert mc.type_mask(Setpoint.acceleration(0, 0, 1, 0.0)) == 0b100000111111
    assert mc.setpoint_of_target(0b111111111, (1, 2, 3), (4, 5, 6), (7, 8, 9), 0.0) is None   # nothing
    assert mc.setpoint_of_target(512 | 0b111111, (1, 2, 3), (4, 5, 6), (7, 8, 9), 0.0) is None  # force


@pytest.mark.parametrize("sp", [
    Setpoint.position(1.5, -2.25, -3.0, 0.75), Setpoint.position(4.0, 5.0, -6.0),
    Setpoint.velocity(1.0, -0.5, 0.25, -1.0), Setpoint.acceleration(0.5, 0.0, -1.0),
], ids=["pos_yaw", "pos", "vel", "acc"])
def test_setpoints_survive_the_wire(sp):
    msg = roundtrip(sp)
    assert msg.target_system == 3 and msg.frame == mc.FRAME_LOCAL_NED
    got = msg.setpoint
    assert got.kind is sp.kind and got.ned == pytest.approx(sp.ned, abs=1e-6)
    assert (got.yaw_rad is None) == (sp.yaw_rad is None)
    if sp.yaw_rad is not None:
        assert got.yaw_rad == pytest.approx(sp.yaw_rad, abs=1e-6)


def test_geoframe_matches_px4_projection_and_round_trips():
    f = GeoFrame(47.397742, 8.545594, 488.0)
    # 0.0001 deg of latitude is ~11.1 m north (the facts' instance spacing)
    n, e, d = f.ned_of(47.397842, 8.545594, 488.0)
    assert n == pytest.approx(2 * math.pi * EARTH_RADIUS_M * 1e-4 / 360, abs=1e-6) and abs(e) < 1e-9
    _, e, d = f.ned_of(47.397742, 8.545694, 491.0)
    assert e == pytest.approx(11.119 * math.cos(math.radians(47.397742)), rel=1e-3)
    assert d == pytest.approx(-3.0)
    for ned in [(0.0, 0.0, 0.0), (9.0, -3.0, -3.0), (-250.0, 400.0, 12.0), (3000.0, 2000.0, -50.0)]:
        assert f.ned_of(*f.geodetic_of(ned)) == pytest.approx(ned, abs=1e-6)
    with pytest.raises(ValueError):
        GeoFrame(95.0, 0.0, 0.0)


def test_vehicle_frame_places_the_local_frame_at_home():
    vf = VehicleFrame((-3.0, 3.0, 0.0), GeoFrame(47.397742, 8.545594, 488.0))
    assert vf.to_mission((1.0, 2.0, -3.0)) == (-2.0, 5.0, -3.0)
    local = vf.setpoint_to_local(Setpoint.position(-2.0, 5.0, -3.0, 0.5))
    assert local.ned == (1.0, 2.0, -3.0) and local.yaw_rad == 0.5
    vel = Setpoint.velocity(1.0, 0.0, 0.0)
    assert vf.setpoint_to_local(vel) is vel and vf.home_alt_m == 488.0
    lat, lon, alt = vf.origin.geodetic_of((-3.0, 3.0, -2.0))
    assert vf.geodetic_to_mission(lat, lon, alt) == pytest.approx((-3.0, 3.0, -2.0), abs=1e-6)


def test_framing_survives_garbage_and_truncation():
    enc = mc.GcsEncoder()
    a, b = enc.heartbeat(), enc.command((1, 1), mc.CMD_ARM_DISARM, (1.0,))
    data = b"\x00junk" + a + b"\xaa\xbb" + b + a[:7]
    items = list(mc.iter_packets(data))
    packets = [x for x in items if isinstance(x, mc.Packet)]
    assert [p.msg_id for p in packets] == [0, mc.MSG["COMMAND_LONG"]]
    assert sum(x for x in items if isinstance(x, int)) == 5 + 2 + 7
    dec = mc.Decoder({0, mc.MSG["COMMAND_LONG"]})
    values = [v for _, v in dec.decode(data)]
    assert isinstance(values[0], mc.HeartbeatMsg) and not values[0].autopilot   # a GCS heartbeat
    assert values[1].command == mc.CMD_ARM_DISARM and values[1].params[0] == 1.0
    assert dec.garbage_bytes == 14 and dec.bad_packets == 0


def test_decoder_skips_unwanted_and_rejects_bad_crc():
    enc = mc.GcsEncoder()
    hb = bytearray(enc.heartbeat())
    hb[-1] ^= 0xFF
    dec = mc.Decoder({0})
    assert list(dec.decode(bytes(hb))) == [] and dec.bad_packets == 1
    cmd = enc.command((1, 1), mc.CMD_LAND, ())
    assert list(dec.decode(cmd * 3)) == [] and dec.skipped == 3
    assert dec.skipped_ids == {mc.MSG["COMMAND_LONG"]: 3} and dec.decoded == 0


def test_connection_strings():
    assert parse_connection("udpin:127.0.0.1:14540") == ("udpin", ("127.0.0.1", 14540), None)
    assert parse_connection("udpout:127.0.0.1:14590")[2] == ("127.0.0.1", 14590)
    assert parse_connection("udp:127.0.0.1:24550@127.0.0.1:14590") == (
        "udp", ("127.0.0.1", 24550), ("127.0.0.1", 14590))
    for bad in ("tcp:127.0.0.1:5760", "udpin:127.0.0.1", "udpin:host:99999", "udp:127.0.0.1:1"):
        with pytest.raises(ValueError, match="MAVLink connection"):
            parse_connection(bad)


class Wire:
    """A fake link for CommandTracker: records sends and reports."""

    def __init__(self, timeout_s: float = 1.0, retries: int = 2) -> None:
        self.sent: list[tuple[int, tuple[float, ...], int]] = []
        self.reports: list[tuple[str, dict]] = []
        self.accepted: list[str] = []
        self.failures: list[tuple[str, str]] = []
        self.t = CommandTracker(lambda c, p, k: self.sent.append((c, p, k)) or True,
                                lambda n, d: self.reports.append((n, d)), timeout_s, retries,
                                on_failed=lambda cmd, result: self.failures.append((cmd.name, result)))

    def cmd(self, command: int, *params: float, name: str = "", quiet: bool = False) -> Command:
        return Command(command, params, quiet, lambda: self.accepted.append(name))

    def ack(self, command: int, result: int, now: float) -> None:
        self.t.on_ack(mc.CommandAckMsg(command, result, 255), now)


def test_command_retried_with_confirmation_then_timeout():
    w = Wire(timeout_s=1.0, retries=2)
    w.t.submit(w.cmd(mc.CMD_LAND), 0.0)
    for now in (0.5, 1.0, 1.5, 2.0, 3.0, 4.0):
        w.t.service(now)
    assert [k for _, _, k in w.sent] == [0, 1, 2]            # first send + 2 retries, confirmation counts up
    assert w.reports and w.reports[0][0] == "timeout" and not w.t.busy(mc.CMD_LAND)


def test_ack_results():
    w = Wire()
    w.t.submit(w.cmd(mc.CMD_ARM_DISARM, 1.0, name="arm"), 0.0)
    w.ack(mc.CMD_ARM_DISARM, mc.RESULT_TEMPORARILY_REJECTED, 0.1)   # retried after half a timeout
    w.t.service(0.4)
    assert len(w.sent) == 1
    w.t.service(0.7)
    assert len(w.sent) == 2
    w.ack(mc.CMD_ARM_DISARM, mc.RESULT_IN_PROGRESS, 0.8)            # waits, no resend
    w.t.service(1.5)
    assert len(w.sent) == 2
    w.ack(mc.CMD_ARM_DISARM, mc.RESULT_ACCEPTED, 1.6)
    assert w.accepted == ["arm"] and not w.reports
    w.t.submit(w.cmd(mc.CMD_RTL), 1.7)
    w.ack(mc.CMD_RTL, mc.RESULT_UNSUPPORTED, 1.8)                    # asking again will not help
    assert w.reports[-1][0] == "nack" and w.reports[-1][1]["result"] == "unsupported"
    assert w.failures == [("return_to_launch", "unsupported")]
    w.ack(mc.CMD_RTL, mc.RESULT_ACCEPTED, 2.2)                       # nothing pending for it
    assert w.reports[-1][0] == "unexpected_ack"


@pytest.mark.parametrize("result", [mc.RESULT_DENIED, mc.RESULT_FAILED, mc.RESULT_TEMPORARILY_REJECTED])
def test_refusals_are_retried_a_bounded_number_of_times_then_fail(result):
    w = Wire(timeout_s=1.0, retries=3)
    w.t.submit(w.cmd(mc.CMD_TAKEOFF, 3.0), 0.0)
    now, acked = 0.0, 0
    while w.t.busy(mc.CMD_TAKEOFF):
        assert now < 20.0, "retried without bound"
        if len(w.sent) > acked:
            acked = len(w.sent)
            w.ack(mc.CMD_TAKEOFF, result, now + 0.05)                 # every try is refused
        now += 0.1
        w.t.service(now)
    assert len(w.sent) == 4                                          # first send + 3 retries
    name = mc.RESULT_NAMES[result]
    assert w.reports == [("nack", {"command": "takeoff", "result": name, "tries": 4, "params": [3.0]})]
    assert w.failures == [("takeoff", name)] and w.accepted == []


def test_a_refusal_then_acceptance_is_no_failure():
    w = Wire(timeout_s=1.0, retries=3)
    w.t.submit(w.cmd(mc.CMD_ARM_DISARM, 1.0, name="arm"), 0.0)
    w.ack(mc.CMD_ARM_DISARM, mc.RESULT_DENIED, 0.1)                  # a pre-flight check still failing
    w.t.service(1.2)
    assert len(w.sent) == 2
    w.ack(mc.CMD_ARM_DISARM, mc.RESULT_ACCEPTED, 1.3)
    assert w.accepted == ["arm"] and not w.reports and not w.failures


def test_same_id_commands_go_one_at_a_time_and_the_latest_wins():
    w = Wire()
    w.t.submit(w.cmd(mc.CMD_SET_MODE, 1, 6, 0, name="offboard"), 0.0)
    w.t.submit(w.cmd(mc.CMD_SET_MODE, 1, 6, 0, name="dup"), 0.0)       # same request in flight: dropped
    w.t.submit(w.cmd(mc.CMD_SET_MODE, 1, 4, 3, name="hold"), 0.0)
    w.t.submit(w.cmd(mc.CMD_SET_MODE, 1, 4, 6, name="land"), 0.0)      # replaces the queued hold
    w.t.submit(w.cmd(mc.CMD_ARM_DISARM, 1, name="arm"), 0.0)           # another id: in flight at once
    assert [c for c, _, _ in w.sent] == [mc.CMD_SET_MODE, mc.CMD_ARM_DISARM]
    w.ack(mc.CMD_SET_MODE, mc.RESULT_ACCEPTED, 0.1)
    assert w.sent[-1][1][:3] == (1, 4, 6)
    w.ack(mc.CMD_SET_MODE, mc.RESULT_ACCEPTED, 0.2)
    w.ack(mc.CMD_ARM_DISARM, mc.RESULT_ACCEPTED, 0.2)
    assert w.accepted == ["offboard", "land", "arm"]


def test_message_interval_requests_queue_per_message():
    w = Wire()
    for msg_id, interval in ((32, 1e5), (33, 1e5), (1, 5e5), (33, 2e5)):
        w.t.submit(w.cmd(mc.CMD_SET_MESSAGE_INTERVAL, msg_id, interval, name=f"{msg_id}@{interval:g}"), 0.0)
    for k in range(3):
        w.ack(mc.CMD_SET_MESSAGE_INTERVAL, mc.RESULT_ACCEPTED, 0.1 * (k + 1))
    assert w.accepted == ["32@100000", "1@500000", "33@200000"]   # the later 33 replaced the queued one


def test_quiet_commands_fail_silently():
    w = Wire()
    w.t.submit(w.cmd(mc.CMD_SET_MESSAGE_INTERVAL, 30.0, -1.0, quiet=True), 0.0)
    w.ack(mc.CMD_SET_MESSAGE_INTERVAL, mc.RESULT_UNSUPPORTED, 0.1)
    assert not w.reports and w.t.failed == 1


def test_setpoint_kinds_cover_the_enum():
    assert set(mc.TYPE_MASK) == set(SetpointKind)
