"""A signing vehicle obeys only its key: mavsim with MAVLink 2 signing, spoken to over real UDP.

The PX4 build the project tests against cannot sign (docs/px4.md), so mavsim stands for a signing
autopilot: with a key in its environment it signs what it sends and drops every packet that is not
signed with that key — a second process using the ground station's system id cannot arm it.
"""

from __future__ import annotations

import os
import subprocess
import sys

from swarmbox.hal.mavlink import codec as mc
from swarmbox.hal.mavlink.signing import KEY_ENV, signing_key_of
from tests.hal.test_mavsim import ROOT, VEHICLE_SPEED, Gcs

KEY = "field test key 7"
ARM = (1.0, 0, 0, 0, 0, 0, 0)


def start_vehicle(gcs: Gcs, key: str | None) -> subprocess.Popen[bytes]:
    env = {k: v for k, v in os.environ.items() if k != KEY_ENV}
    if key is not None:
        env[KEY_ENV] = key
    cmd = [sys.executable, "-m", "swarmbox.hal.mavsim.process", "--instance", "2", "--port-plan",
           f"{gcs.port}:0", "--speed", str(VEHICLE_SPEED), "--max-wall-s", "30"]
    return subprocess.Popen(cmd, cwd=ROOT, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)


def impostors_try_to_arm(gcs: Gcs, *encoders: mc.GcsEncoder) -> list[tuple[mc.Packet, object]]:
    """Each encoder speaks as system 255 (the ground station's id) from a socket of its own; returns
    what the vehicle sent to the impostor's socket in the next second."""
    imp = Gcs()
    for enc in encoders:
        for _ in range(3):
            imp.sock.sendto(enc.command((3, 1), mc.CMD_ARM_DISARM, ARM), gcs.peer)
    got = imp.collect(1.0)
    imp.sock.close()
    return got


def armed(packets) -> bool:
    return any(v.armed for _, v in packets if isinstance(v, mc.HeartbeatMsg))


def stop(proc: subprocess.Popen[bytes], gcs: Gcs) -> str:
    proc.terminate()
    _, err = proc.communicate(timeout=10)
    gcs.sock.close()
    assert proc.returncode == 0, err.decode()
    return err.decode()


def test_signed_vehicle_obeys_only_packets_signed_with_its_key():
    key = signing_key_of(KEY)
    gcs = Gcs()
    gcs.enc, gcs.dec = mc.GcsEncoder(signing_key=key), mc.Decoder(set(mc.DECODERS), key)
    proc = start_vehicle(gcs, KEY)
    try:
        first = gcs.collect(1.5)
        assert first, "no traffic from the signed vehicle"
        assert gcs.dec.signature_rejected == 0                  # everything it sends is signed with KEY
        to_impostor = impostors_try_to_arm(gcs, mc.GcsEncoder(),
                                           mc.GcsEncoder(signing_key=signing_key_of("not the key")))
        assert to_impostor == []                                # it did not even learn their address
        window = gcs.collect(1.0)
        assert window, "the vehicle stopped talking to its ground station"
        assert not armed(window)                                # neither impostor got through
        assert not any(isinstance(v, mc.CommandAckMsg) for _, v in window)
        acks = gcs.command(3, mc.CMD_ARM_DISARM, *ARM)          # the key holder is obeyed
        assert [a.result for a in acks] == [mc.RESULT_ACCEPTED]
        assert armed(gcs.collect(0.5))
    finally:
        err = stop(proc, gcs)
    assert "signing on" in err
    assert "unsigned or wrongly signed 6 packets" in err        # 3 unsigned + 3 with the wrong key


def test_without_a_key_the_same_impostor_arms_the_vehicle():
    """The contrast: an unsigned vehicle obeys anyone who uses the ground station's system id."""
    gcs = Gcs()
    proc = start_vehicle(gcs, None)
    try:
        assert gcs.collect(1.5), "no traffic from the vehicle"
        to_impostor = impostors_try_to_arm(gcs, mc.GcsEncoder())
        acks = [v.result for _, v in to_impostor if isinstance(v, mc.CommandAckMsg)]
        assert acks[:1] == [mc.RESULT_ACCEPTED]
        assert armed(to_impostor)                               # armed, and now talking to the impostor
    finally:
        err = stop(proc, gcs)
    assert "signing off" in err
