"""The bridge cannot be fooled: address binding, MAVLink 2 signing, wrong system ids named.

Real UDP sockets on 127.0.0.1; the "vehicles" are pymavlink encoders or mavsim processes.
"""

from __future__ import annotations

import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from swarmbox.hal.mavlink import codec as mc
from swarmbox.hal.mavlink.link import VehicleLink
from swarmbox.hal.mavlink.signing import signing_key_of, signing_timestamp
from swarmbox.hal.px4.backend import Px4Backend
from swarmbox.hal.px4.params import Px4Params
from swarmbox.hal.px4.streams import WANTED

ROOT = Path(__file__).resolve().parents[2]
KEY = signing_key_of("swarmbox test key")


def vehicle(system_id: int = 1, key: bytes | None = None):
    mav = mc.mavlink.MAVLink(None, srcSystem=system_id, srcComponent=1)
    if key is not None:
        mav.signing.secret_key, mav.signing.sign_outgoing = key, True
        mav.signing.timestamp = signing_timestamp()
    return mav


def heartbeat(mav) -> bytes:
    return bytes(mav.heartbeat_encode(mc.mavlink.MAV_TYPE_QUADROTOR, mc.mavlink.MAV_AUTOPILOT_PX4, 0, 0, 0)
                 .pack(mav))


def poll_all(link: VehicleLink, wait_s: float = 0.2) -> list:
    time.sleep(wait_s)
    return link.poll()


def test_vehicle_is_bound_to_its_first_address_and_impostors_are_dropped():
    link = VehicleLink("udpin:127.0.0.1:0", 1, set(WANTED))
    dest = ("127.0.0.1", link.endpoint.local_port)
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as real, \
            socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as fake:
        real.bind(("127.0.0.1", 0))
        fake.bind(("127.0.0.1", 0))
        real.sendto(heartbeat(vehicle(1)), dest)
        assert len(poll_all(link)) == 1 and link.bound == real.getsockname()
        for _ in range(3):
            fake.sendto(heartbeat(vehicle(1)), dest)        # the same system id, another address
        assert poll_all(link) == [] and link.stats.conflicts == {fake.getsockname(): 3}
        assert link.endpoint.peer == real.getsockname()   # commands still go to the real vehicle
        real.sendto(heartbeat(vehicle(1)), dest)
        assert len(poll_all(link)) == 1
    link.close()


def test_signed_link_accepts_only_packets_signed_with_its_key():
    link = VehicleLink("udpin:127.0.0.1:0", 1, set(WANTED), signing_key=KEY)
    dest = ("127.0.0.1", link.endpoint.local_port)
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        s.sendto(heartbeat(vehicle(1)), dest)                                   # unsigned
        s.sendto(heartbeat(vehicle(1, signing_key_of("another key"))), dest)    # signed, wrong key
        assert poll_all(link) == [] and link.bound is None
        assert link.decoder.signature_rejected == 2
        s.sendto(heartbeat(vehicle(1, KEY)), dest)
        assert len(poll_all(link)) == 1 and link.bound == s.getsockname()
    link.close()


def test_bridge_signs_what_it_sends_when_configured():
    enc = mc.GcsEncoder(signing_key=KEY)
    packet = bytearray(enc.command((1, 1), mc.CMD_ARM_DISARM, (1.0,)))
    assert packet[2] & 1                                      # MAVLINK_IFLAG_SIGNED
    right, wrong = vehicle(1, KEY), vehicle(1, signing_key_of("another key"))
    assert right.decode(bytearray(packet)).command == mc.CMD_ARM_DISARM
    with pytest.raises(mc.MAVError, match="signature"):
        wrong.decode(bytearray(packet))
    assert not mc.GcsEncoder().command((1, 1), mc.CMD_ARM_DISARM, (1.0,))[2] & 1   # off by default
    assert Px4Params.from_kwargs({"signing_key": "ab" * 32}).signing_bytes() == bytes([0xAB] * 32)
    with pytest.raises(ValueError, match="empty MAVLink signing key"):
        Px4Params.from_kwargs({"signing_key": " "})


def test_wrong_system_id_is_named_not_reported_as_silence():
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    proc = subprocess.Popen([sys.executable, "-m", "swarmbox.hal.mavsim.process", "--instance", "0",
                             "--system-id", "7", "--port-plan", f"{port}:0", "--max-wall-s", "30"],
                            cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        with pytest.raises(TimeoutError, match=r"drone 0: packets seen from system ids \[7\], expected 1"):
            Px4Backend(homes_ned_m=[(0.0, 0.0, 0.0)], tick_s=0.025, rng=np.random.default_rng(0),
                       connections=[f"udpin:127.0.0.1:{port}"], connect_timeout_s=4.0)
    finally:
        proc.kill()
        proc.wait()


def test_a_wrongly_signed_packet_cannot_block_the_real_senders_stream():
    """pymavlink records a new stream's timestamp before checking the signature; the decoder forgets
    what a rejected packet recorded, so a wrong key with a later timestamp is not a denial of service."""
    dec = mc.Decoder({mc.MSG["COMMAND_LONG"]}, KEY)
    real = mc.GcsEncoder(signing_key=KEY)                       # older timestamps: created first
    later = mc.GcsEncoder(signing_key=signing_key_of("not the key"))
    later._mav.signing.timestamp += 10**6                       # ten seconds ahead of the real sender
    arm = (1.0, 0, 0, 0, 0, 0, 0)
    assert list(dec.decode(later.command((1, 1), mc.CMD_ARM_DISARM, arm))) == []
    assert dec.signature_rejected == 1
    assert len(list(dec.decode(real.command((1, 1), mc.CMD_ARM_DISARM, arm)))) == 1
    assert len(list(dec.decode(real.command((1, 1), mc.CMD_ARM_DISARM, arm)))) == 1
    replay = real.command((1, 1), mc.CMD_ARM_DISARM, arm)
    assert len(list(dec.decode(replay))) == 1 and list(dec.decode(replay)) == []   # a replay still is one


YEARS_AGO_S = time.time() - 3 * 365 * 86400


def test_a_packet_signed_years_ago_is_refused_as_the_first_of_a_new_stream():
    """Same key, right system id, real UDP: a packet recorded years ago and replayed to a freshly
    started link is refused (the decoder meets new streams with the current signing time)."""
    link = VehicleLink("udpin:127.0.0.1:0", 1, set(WANTED), signing_key=KEY)
    dest = ("127.0.0.1", link.endpoint.local_port)
    old = vehicle(1, KEY)
    old.signing.timestamp = signing_timestamp(YEARS_AGO_S)
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        s.sendto(heartbeat(old), dest)
        assert poll_all(link) == [] and link.bound is None
        assert link.decoder.signature_rejected == 1
        s.sendto(heartbeat(vehicle(1, KEY)), dest)                # signed now: accepted
        assert len(poll_all(link)) == 1 and link.bound == s.getsockname()
    link.close()


def test_senders_stamp_with_the_wall_clock_so_a_restarted_receiver_accepts_them():
    """pymavlink adds one per packet to the timestamp; a sender running for a while would fall minutes
    behind and a restarted receiver would take its packets for replays. The encoder keeps it current."""
    enc = mc.GcsEncoder(signing_key=KEY)
    enc._mav.signing.timestamp = signing_timestamp(YEARS_AGO_S)   # as if it had run for years
    packet = enc.command((1, 1), mc.CMD_ARM_DISARM, (1.0,))
    stamp = int.from_bytes(packet[-12:-6], "little")
    assert abs(stamp - signing_timestamp()) < 10**5                # within a second of now
    fresh = mc.Decoder({mc.MSG["COMMAND_LONG"]}, KEY)
    assert len(list(fresh.decode(packet))) == 1
