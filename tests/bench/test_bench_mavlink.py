"""The bridge's receive path: its own header framing (unwanted messages skipped, never decoded)
against pymavlink's ``MAVLink.parse_buffer`` (every message decoded) on one second of PX4-like
traffic: ~400 packets of which the bridge wants ~55.

Run with ``python -m pytest tests/bench/test_bench_mavlink.py --benchmark-enable``; ``extra_info``
holds the wanted messages each path yields, and both must yield the same ones.
"""

from __future__ import annotations

import pytest

from swarmbox.hal.mavlink import codec as mc
from swarmbox.hal.px4.streams import WANTED

#: message -> Hz in one second of a PX4 SITL instance's API stream (defaults, before silencing)
STREAM_HZ = {"HEARTBEAT": 1, "LOCAL_POSITION_NED": 30, "GLOBAL_POSITION_INT": 10, "GPS_RAW_INT": 10,
             "SYS_STATUS": 2, "EXTENDED_SYS_STATE": 2, "ATTITUDE": 100, "ATTITUDE_QUATERNION": 50,
             "HIGHRES_IMU": 50, "SERVO_OUTPUT_RAW": 50, "ALTITUDE": 10, "VFR_HUD": 4,
             "ATTITUDE_TARGET": 10, "POSITION_TARGET_LOCAL_NED": 10, "ESTIMATOR_STATUS": 10,
             "VIBRATION": 5, "BATTERY_STATUS": 5}


def one_second_of_traffic() -> list[bytes]:
    mav = mc.mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
    m = mc.mavlink
    make = {
        "HEARTBEAT": lambda: mav.heartbeat_encode(2, 12, 0x81, 0x6040000, 4),
        "LOCAL_POSITION_NED": lambda: mav.local_position_ned_encode(1000, 1.0, 2.0, -3.0, 0.1, 0.2, 0.0),
        "GLOBAL_POSITION_INT": lambda: mav.global_position_int_encode(1000, 473977420, 85455940, 491000,
                                                                      3000, 0, 0, 0, 9000),
        "GPS_RAW_INT": lambda: mav.gps_raw_int_encode(10**6, 3, 473977420, 85455940, 491000, 100, 100, 0,
                                                      0, 10),
        "SYS_STATUS": lambda: mav.sys_status_encode(0, 0, 0x10000000, 500, 16000, -1, 90, 0, 0, 0, 0, 0, 0),
        "EXTENDED_SYS_STATE": lambda: mav.extended_sys_state_encode(0, 2),
        "ATTITUDE": lambda: mav.attitude_encode(1000, 0.01, 0.02, 1.5, 0.0, 0.0, 0.0),
        "ATTITUDE_QUATERNION": lambda: mav.attitude_quaternion_encode(1000, 1, 0, 0, 0, 0, 0, 0),
        "HIGHRES_IMU": lambda: mav.highres_imu_encode(10**6, 0, 0, -9.8, 0, 0, 0, 0, 0, 0, 1013, 0, 0, 20,
                                                      0xFF),
        "SERVO_OUTPUT_RAW": lambda: mav.servo_output_raw_encode(10**6, 0, *([1500] * 8)),
        "ALTITUDE": lambda: mav.altitude_encode(10**6, 488, 491, 3, 3, 3, 3),
        "VFR_HUD": lambda: mav.vfr_hud_encode(0, 0, 90, 50, 491, 0),
        "ATTITUDE_TARGET": lambda: mav.attitude_target_encode(1000, 0, [1, 0, 0, 0], 0, 0, 0, 0.5),
        "POSITION_TARGET_LOCAL_NED": lambda: mav.position_target_local_ned_encode(
            1000, m.MAV_FRAME_LOCAL_NED, 0, 1, 2, -3, 0, 0, 0, 0, 0, 0, 0, 0),
        "ESTIMATOR_STATUS": lambda: mav.estimator_status_encode(10**6, 0, 0.1, 0.1, 0.1, 0.1, 0.1, 0.1, 0.5,
                                                                0.5),
        "VIBRATION": lambda: mav.vibration_encode(10**6, 0.1, 0.1, 0.1, 0, 0, 0),
        "BATTERY_STATUS": lambda: mav.battery_status_encode(0, 0, 0, 2500, [16000] + [65535] * 9, -1, -1, -1,
                                                            90),
    }
    # interleave by rate over 100 slots of 10 ms; PX4 sends one packet per datagram on UDP
    out = []
    for slot in range(100):
        for name, hz in STREAM_HZ.items():
            if slot % max(1, 100 // hz) == 0:
                out.append(bytes(make[name]().pack(mav)))
    return out


TRAFFIC = one_second_of_traffic()


def own_framing() -> int:
    dec = mc.Decoder(set(WANTED))
    return sum(1 for data in TRAFFIC for _ in dec.decode(data))


def pymavlink_parse() -> int:
    mav = mc.mavlink.MAVLink(None)
    wanted = set(WANTED)
    n = 0
    for data in TRAFFIC:
        for msg in mav.parse_buffer(data) or ():
            if msg.get_msgId() in wanted:
                mc.DECODERS[msg.get_msgId()](msg)
                n += 1
    return n


@pytest.mark.parametrize("path", [own_framing, pymavlink_parse], ids=lambda f: f.__name__)
def test_receive_one_second_of_px4_traffic(benchmark, path):
    assert 350 < len(TRAFFIC) < 500
    wanted = benchmark(path)
    assert wanted == own_framing() == pymavlink_parse() > 40
    benchmark.extra_info.update(packets=len(TRAFFIC), wanted=wanted)
