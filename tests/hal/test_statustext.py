"""Long STATUSTEXT lines arrive whole: mavsim splits them like PX4 (MAVLink 2 chunks of 50 bytes with
an id and a chunk_seq), the bridge's decoder and assembler join them; a critical line explains an
autopilot's own mode change."""

from __future__ import annotations

from swarmbox.hal.mavlink import codec as mc
from swarmbox.hal.mavlink.frames import GeoFrame
from swarmbox.hal.mavlink.statustext import CHUNK, StatusTexts, TextAssembler
from swarmbox.hal.mavsim.link import VehicleEncoder

LONG = "Arming denied: Resolve system health failures first"          # PX4's, 51 characters
LONGER = "Failsafe: GNSS lost while in OFFBOARD, activating descend mode (no position estimate)"


def packets_of(text: str, severity: int = 2, encoder: VehicleEncoder | None = None) -> list[mc.StatusTextMsg]:
    enc = encoder or VehicleEncoder(2, GeoFrame(47.0, 8.0, 400.0))
    dec = mc.Decoder({mc.MSG["STATUSTEXT"]})
    return [value for data in enc.statustext(severity, text) for _, value in dec.decode(data)]


def test_a_long_line_is_sent_in_chunks_and_assembled_whole():
    for text in (LONG, LONGER, "x" * (2 * CHUNK + 1)):
        chunks = packets_of(text)
        assert len(chunks) == -(-len(text) // CHUNK)
        assert len({c.line_id for c in chunks}) == 1 and chunks[0].line_id != 0
        assert [c.chunk_seq for c in chunks] == list(range(len(chunks)))
        asm = TextAssembler()
        lines = [line for c in chunks for line in asm.feed(c.severity, c.text, c.line_id, c.chunk_seq, 1.0)]
        assert lines == [(2, text)] and not asm.waiting


def test_a_short_line_is_one_packet_with_id_zero():
    (only,) = packets_of("Failsafe activated")
    assert (only.line_id, only.chunk_seq, only.text) == (0, 0, "Failsafe activated")
    assert TextAssembler().feed(2, only.text, 0, 0, 0.0) == [(2, "Failsafe activated")]


def test_chunks_out_of_order_and_interleaved_lines():
    enc = VehicleEncoder(2, GeoFrame(47.0, 8.0, 400.0))
    a, b = packets_of(LONGER, 2, enc), packets_of(LONG, 4, enc)
    assert a[0].line_id != b[0].line_id          # every long line gets its own id
    asm, out = TextAssembler(), []
    for c in (a[1], b[0], a[0], b[1]):
        out += asm.feed(c.severity, c.text, c.line_id, c.chunk_seq, 0.0)
    assert out == [(2, LONGER), (4, LONG)]


def test_a_line_whose_last_chunk_never_comes_is_flushed_when_stale():
    exact = "y" * (2 * CHUNK)                     # no NUL ends it: nothing says it is complete
    asm = TextAssembler(stale_s=1.0)
    for c in packets_of(exact):
        assert asm.feed(c.severity, c.text, c.line_id, c.chunk_seq, 5.0) == []
    assert asm.waiting and asm.flush(5.5) == []
    assert asm.flush(6.0) == [(2, exact)] and not asm.waiting
    lost = packets_of(LONGER)[:1]                  # the second chunk was lost
    asm.feed(lost[0].severity, lost[0].text, lost[0].line_id, 0, 10.0)
    assert asm.feed(6, "next", 0, 0, 11.5) == [(2, LONGER[:CHUNK]), (6, "next")]


def test_warnings_become_events_and_a_recent_critical_line_explains_a_mode_change():
    events = []
    texts = StatusTexts(lambda kind, name, data: events.append((kind, name, data)))
    for c in packets_of(LONG, severity=2):
        texts.on_chunk(c.severity, c.text, c.line_id, c.chunk_seq, 20.0)
    texts.on_chunk(6, "Takeoff detected", 0, 0, 20.5)              # info: not an event
    assert events == [("command", "statustext", {"severity": 2, "text": LONG})]
    assert texts.recent_alert(22.0) == LONG
    assert texts.recent_alert(30.0) == ""                          # too old to explain anything
