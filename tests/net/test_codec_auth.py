"""The wire encoding and the signed envelope: round trips, exact sizes, every rejection reason."""

from __future__ import annotations

import math

import pytest

from swarmbox.core.messages import DescendantState, Heartbeat, ProxAlert, Report, TaskAck, TaskCommand
from swarmbox.net.auth import AuthSpec, Rejected, Signer, Verifier
from swarmbox.net.codec import DecodeError, decode, encode

D = (DescendantState(4, 3, (1.0, 2.0, -3.0)), DescendantState(7, 2, (0.5, -0.25, -10.0)))
MESSAGES = [
    Heartbeat(11, 1.25, -1, 2, (3, 5), (1.0, 2.0, -3.0), (0.5, 0.0, -0.25)),
    Report(12, 2.5, 3, -1, 3, True, 4, 3, (1.0, 2.0, -3.0), (0.0, 0.5, 0.0), None, "k=1", D),
    Report(13, 2.5, 3, -1, 3, False, 1, 1, (1.0, 2.0, -3.0), (0.0, 0.5, 0.0), (0.25, 0.0, 0.0), "", ()),
    TaskCommand(14, 3.0, -1, 2, 9, True, 7, (10.0, -4.0, -5.0), 1.5, "go", 3, 7),
    TaskCommand(15, 3.0, -1, 2, 10, False, 0, None, None, ""),
    Report(18, 9.0, 2, 0, -1, False, 1, 0, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), None, "", D[:1]),   # ABORT
    Heartbeat(19, 9.5, 0, -1, (), (0.0, 0.0, 0.0), (0.0, 0.0, 0.0)),
    TaskAck(16, 3.5, 2, -1, 9),
    ProxAlert(17, 4.0, -1, 3, D),
]


@pytest.mark.parametrize("msg", MESSAGES, ids=lambda m: type(m).__name__)
def test_round_trip_and_size(msg):
    wire = encode(msg)
    assert len(wire) == msg.nbytes          # the size the logs record is the size on the wire
    assert decode(wire) == msg              # values chosen exact in float32


def test_float32_positions_survive_within_float32_precision():
    hb = Heartbeat(1, 0.1, 0, 3, (), (1.1, -2.2, 3.3), (0.0, 0.0, 0.0))
    back = decode(encode(hb))
    assert back.t_sent_s == 0.1             # times stay float64
    assert all(math.isclose(a, b, rel_tol=1e-6) for a, b in zip(back.pos_ned_m, hb.pos_ned_m, strict=True))


BAD_FRAMES = [b"", b"\x09" + bytes(40), encode(MESSAGES[0])[:-3], encode(MESSAGES[7]) + b"x"]


@pytest.mark.parametrize("frame", BAD_FRAMES)
def test_malformed_frames_raise(frame):
    with pytest.raises(DecodeError):
        decode(frame)


KEY = b"0123456789abcdef0123456789abcdef"


class Wall:
    def __init__(self, t: float = 1000.0) -> None:
        self.t = t

    def __call__(self) -> float:
        return self.t


def _pair(mission: str = "m1", wall: Wall | None = None):
    wall = wall or Wall()
    spec = AuthSpec(KEY, mission, max_age_s=2.0, window=64)
    return Signer(spec, 3, wall), Verifier(spec, wall), wall


def _reason(verifier: Verifier, frame: bytes) -> str:
    with pytest.raises(Rejected) as info:
        verifier.open(frame)
    return info.value.reason


def test_signed_frame_opens_once_then_is_a_replay():
    signer, verifier, _ = _pair()
    payload = encode(MESSAGES[7])
    frame = signer.sign(payload)
    assert verifier.open(frame) == (3, payload)
    assert _reason(verifier, frame) == "replayed"


def test_out_of_order_within_window_accepted_beyond_window_rejected():
    signer, verifier, _ = _pair()
    frames = [signer.sign(b"m%d" % i) for i in range(100)]
    verifier.open(frames[99])
    verifier.open(frames[50])                 # late but inside the 64-counter window
    assert _reason(verifier, frames[50]) == "replayed"
    assert _reason(verifier, frames[10]) == "replayed"   # older than the window


def test_forged_unsigned_wrong_mission_and_stale_are_named():
    signer, verifier, wall = _pair()
    frame = bytearray(signer.sign(b"payload"))
    frame[-20] ^= 1
    assert _reason(verifier, bytes(frame)) == "forged"
    assert _reason(verifier, encode(MESSAGES[0])) == "unsigned"
    other = Signer(AuthSpec(KEY, "m2"), 3, wall)
    assert _reason(verifier, other.sign(b"payload")) == "wrong_mission"
    wrong_key = Signer(AuthSpec(b"x" * 32, "m1"), 3, wall)
    assert _reason(verifier, wrong_key.sign(b"payload")) == "forged"
    old = signer.sign(b"payload")
    wall.t += 5.0
    assert _reason(verifier, old) == "stale"


def test_age_bound_is_two_sided_a_frame_dated_in_the_future_is_stale():
    signer, verifier, wall = _pair()
    wall.t += 5.0
    ahead = signer.sign(b"from the future")                  # the sender's clock is 5 s ahead
    wall.t -= 5.0
    assert _reason(verifier, ahead) == "stale"
    wall.t += 1.9                                            # within the bound (2 s) it is fine
    assert verifier.open(signer.sign(b"slightly ahead"))[1] == b"slightly ahead"


def test_tag_covers_the_key_expression():
    signer, verifier, _ = _pair()
    frame = signer.sign(b"for drone 3", "swarmbox/m1/to/3")
    assert _reason(verifier, frame) == "forged" and verifier.open(frame, "swarmbox/m1/to/3")[0] == 3
    moved = Verifier(AuthSpec(KEY, "m1", window=64), Wall())
    with pytest.raises(Rejected, match="forged"):
        moved.open(frame, "swarmbox/m1/to/5")                 # replayed on drone 5's key


def test_restarted_sender_is_not_taken_for_a_replay():
    _, verifier, wall = _pair()
    spec = AuthSpec(KEY, "m1", window=64)
    first = Signer(spec, 3, wall)
    for _ in range(10):
        verifier.open(first.sign(b"a"))
    wall.t += 0.5
    verifier.open(Signer(spec, 3, wall).sign(b"b"))    # counter restarts from the later wall time


def test_key_is_never_shown_and_must_be_long_enough():
    assert "0123" not in repr(AuthSpec(KEY, "m1"))
    with pytest.raises(ValueError, match="16 bytes"):
        AuthSpec(b"short", "m1")


def test_both_transports_implement_the_medium_interface():
    from swarmbox.net.medium import SimMedium
    from swarmbox.net.transport import Medium
    from swarmbox.net.zenoh_medium import ZenohMedium

    methods = {n for proto in Medium.__mro__ if proto is not object for n in vars(proto)
               if not n.startswith("_") and callable(getattr(Medium, n))}
    assert {"deliver_due", "register", "send", "publish", "link", "subscribe"} <= methods
    for cls in (SimMedium, ZenohMedium):
        assert [n for n in methods if not callable(getattr(cls, n, None))] == [], cls.__name__


@pytest.mark.parametrize("code, size", [(127, 1), (128, 2), (1000, 2), (16384, 3), (2**32 - 1, 5)])
def test_task_codes_beyond_one_byte_round_trip_with_their_varint_size(code, size):
    small = TaskCommand(20, 3.0, -1, 2, 1, True, 7, (1.0, 2.0, 3.0), None, "x", 3, 1)
    cmd = small._replace(code=code)
    wire = encode(cmd)
    assert len(wire) == cmd.nbytes == small.nbytes + size - 1   # codes < 128 keep their old size
    assert decode(wire) == cmd


@pytest.mark.parametrize("code", [-1, 2**32, 1.5, "7", True])
def test_task_code_outside_the_wire_field_is_a_clear_error(code):
    cmd = TaskCommand(20, 3.0, -1, 2, 1, True, 0, None, None, "")._replace(code=code)
    with pytest.raises(ValueError, match=r"task code must be an integer in 0\.\.4294967295"):
        encode(cmd)


def test_overlong_or_padded_task_code_varint_is_malformed():
    wire = encode(TaskCommand(20, 3.0, -1, 2, 1, True, 5, None, None, ""))
    at = 21 + 5                                                  # header, seq u32, reliable
    padded = wire[:at] + bytes([0x85, 0x00]) + wire[at + 1:]     # 5 written in two bytes
    overlong = wire[:at] + bytes([0xFF] * 5 + [0x01]) + wire[at + 1:]
    for frame in (padded, overlong):
        with pytest.raises(DecodeError):
            decode(frame)
