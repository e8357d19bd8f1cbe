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
from tests.hal.test_mavsim import ROOT, VEHICLE_SPEED, Gcs, of_type

KEY = "field test key 7"
ARM = (1.0, 0, 0, 0, 0, 0, 0)


def start_vehicle(gcs: Gcs, key: str | None) -> subprocess.Popen[bytes]:
    env = {k: v for k, v in os.environ.items() if k != KEY_ENV}
    if key is not None:
        env[KEY_ENV] = key
    cmd = [sys.executable, "-m", "swarmbox.hal.mavsim.process", "--instance", "2", "--port-plan",
           f"{gcs.port}:0", "--speed", str(VEHICLE_SPEED), "--max-wall-s", "300"]
    return subprocess.Popen(cmd, cwd=ROOT, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)


def impostors_try_to_arm(gcs: Gcs, *encoders: mc.GcsEncoder) -> Gcs:
    """Each encoder speaks as system 255 (the ground station's id) from a socket of its own, three
    times; returns the impostors' ground station (its socket gets whatever the vehicle answers)."""
    imp = Gcs()
    for enc in encoders:
        for _ in range(3):
            imp.sock.sendto(enc.command((3, 1), mc.CMD_ARM_DISARM, ARM), gcs.peer)
    return imp


def stop(proc: subprocess.Popen[bytes], gcs: Gcs) -> str:
    proc.terminate()
    _, err = proc.communicate(timeout=60)
    gcs.sock.close()
    assert proc.returncode == 0, err.decode()
    return err.decode()


# The checks follow the vehicle's own progress, never a wall-clock window: it reads its socket in
# order, so once it acks a later command of the key holder it has read the impostors' packets, and
# what it would have answered them is already in their socket.
def test_signed_vehicle_obeys_only_packets_signed_with_its_key():
    key = signing_key_of(KEY)
    gcs = Gcs()
    gcs.enc, gcs.dec = mc.GcsEncoder(signing_key=key), mc.Decoder(set(mc.DECODERS), key)
    proc = start_vehicle(gcs, KEY)
    try:
        assert gcs.ready_to_arm()
        assert gcs.dec.decoded and gcs.dec.signature_rejected == 0   # everything it sends is signed with KEY
        wrong_key = mc.GcsEncoder(signing_key=signing_key_of("not the key"))
        imp = impostors_try_to_arm(gcs, mc.GcsEncoder(), wrong_key)
        acks = gcs.command(3, mc.CMD_SET_MESSAGE_INTERVAL, mc.MSG["HEARTBEAT"], 0)   # harmless, after theirs
        assert [a.result for a in acks] == [mc.RESULT_ACCEPTED]   # no ack of their ARM among ours either
        assert not any(hb.armed for hb in gcs.heartbeats(2))      # neither impostor got through
        assert imp.collect(0.2) == []                             # it did not even learn their address
        imp.sock.close()
        acks = gcs.command(3, mc.CMD_ARM_DISARM, *ARM)           # the key holder is obeyed
        assert [a.result for a in acks] == [mc.RESULT_ACCEPTED]
        assert gcs.heartbeats()[-1].armed
    finally:
        err = stop(proc, gcs)
    assert "signing on" in err
    assert "unsigned or wrongly signed 6 packets" in err        # 3 unsigned + 3 with the wrong key


def test_without_a_key_the_same_impostor_arms_the_vehicle():
    """The contrast: an unsigned vehicle obeys anyone who uses the ground station's system id."""
    gcs = Gcs()
    proc = start_vehicle(gcs, None)
    try:
        assert gcs.ready_to_arm()
        imp = impostors_try_to_arm(gcs, mc.GcsEncoder())
        to_impostor = imp.until(lambda out: of_type(out, mc.HeartbeatMsg), "heartbeat sent to the impostor")
        imp.sock.close()
        assert [a.result for a in of_type(to_impostor, mc.CommandAckMsg)] == [mc.RESULT_ACCEPTED] * 3
        assert of_type(to_impostor, mc.HeartbeatMsg)[-1].armed   # armed, and now talking to the impostor
    finally:
        err = stop(proc, gcs)
    assert "signing off" in err
