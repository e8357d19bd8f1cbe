"""PX4 SITL launcher: port plan, environment, ULog collection; real PX4 when SWARMBOX_PX4_BUILD is set."""

from __future__ import annotations

import math
import os
import struct
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from swarmbox.analysis.ulog import local_position
from swarmbox.hal.mavlink.frames import GeoFrame
from swarmbox.hal.mavlink.link import parse_connection
from swarmbox.hal.px4.params import BootClock
from swarmbox.hal.px4.sitl import (
    SitlOptions,
    connection_of,
    find_build,
    instance_env,
    resolve_build,
    runnable_px4,
    write_ulog_index,
)
from tests.conftest import table

PX4_BUILD = os.environ.get("SWARMBOX_PX4_BUILD")
needs_px4 = pytest.mark.skipif(not PX4_BUILD, reason="no PX4 SITL build configured: set SWARMBOX_PX4_BUILD "
                               "to a PX4-Autopilot tree or its build/px4_sitl_default (see docs/px4.md)")


def test_port_plan_is_unique_past_ten_vehicles():
    plans = [parse_connection(connection_of(i)) for i in range(30)]
    assert connection_of(3) == "udpin:127.0.0.1:14543"                     # PX4's API link, as is
    assert connection_of(12) == "udp:127.0.0.1:24552@127.0.0.1:14592"      # bridge speaks first
    binds = [bind for _, bind, _ in plans]
    assert len(set(binds)) == 30
    assert all(peer is None or peer[1] == 14580 + i for i, (_, _, peer) in enumerate(plans))
    # never on a port a PX4 instance or a ground station binds (14550 GCS, 14580+ API, 18570+ GCS link)
    assert not {port for _, port in binds} & ({14550} | set(range(14580, 14700)) | set(range(18570, 18700)))


def test_instance_environment():
    frame = GeoFrame(47.397742, 8.545594, 488.0)
    options = SitlOptions(logger=False, params={"com_rc_in_mode": 1})
    env = instance_env(frame.geodetic_of((-3.0, 3.0, 0.0)), options, 5.0, {"PATH": "/bin"})
    assert env["PX4_SIM_MODEL"] == "sihsim_quadx" and env["PATH"] == "/bin"
    home = frame.ned_of(float(env["PX4_HOME_LAT"]), float(env["PX4_HOME_LON"]), float(env["PX4_HOME_ALT"]))
    assert home == pytest.approx((-3.0, 3.0, 0.0), abs=1e-3)
    assert env["PX4_SIM_SPEED_FACTOR"] == "5" and env["PX4_PARAM_SDLOG_MODE"] == "-1"
    assert env["PX4_PARAM_COM_RC_IN_MODE"] == "1"
    assert "PX4_SIM_SPEED_FACTOR" not in instance_env((0.0, 0.0, 0.0), SitlOptions(), 1.0, {})


def test_bad_build_and_options_are_named(tmp_path):
    with pytest.raises(FileNotFoundError, match="no PX4 SITL build"):
        find_build(tmp_path)
    (tmp_path / "build" / "px4_sitl_default" / "bin").mkdir(parents=True)
    (tmp_path / "build" / "px4_sitl_default" / "etc").mkdir()
    (tmp_path / "build" / "px4_sitl_default" / "bin" / "px4").write_text("")
    assert find_build(tmp_path) == (tmp_path / "build" / "px4_sitl_default").resolve()
    with pytest.raises(TypeError, match="unknown px4 backend sitl option 'modell'"):
        SitlOptions.from_mapping({"modell": "x"})


def fake_ulog(path: Path, rows: list[tuple[int, float, float, float]]) -> None:
    """A minimal ULog file with vehicle_local_position rows (timestamp µs, x, y, z)."""
    def msg(kind: str, payload: bytes) -> bytes:
        return struct.pack("<HB", len(payload), ord(kind)) + payload

    fmt = (b"vehicle_local_position:uint64_t timestamp;float x;float y;float z;float vx;float vy;float vz;"
           b"float heading;bool xy_valid;bool z_valid;")
    out = b"ULog\x01\x12\x35\x01" + struct.pack("<Q", 0) + msg("B", bytes(40)) + msg("F", fmt)
    out += msg("A", struct.pack("<BH", 0, 7) + b"vehicle_local_position")
    for stamp, x, y, z in rows:
        out += msg("D", struct.pack("<HQ7f??", 7, stamp, x, y, z, 0.5, 0.0, 0.0, 0.25, True, True))
    path.write_bytes(out)


def test_ulog_goes_on_the_drone_clock_in_the_mission_frame(tmp_path):
    inst = tmp_path / "px4" / "instance_1" / "log"
    inst.mkdir(parents=True)
    a, b = inst / "a.ulg", inst / "b.ulg"
    fake_ulog(a, [(1_000_000 + k * 100_000, 0.1 * k, 0.0, -3.0) for k in range(5)])
    fake_ulog(b, [(9_000_000, 1.0, 2.0, -1.0)])
    clock = BootClock(a=20.0, b=0.5, offset_s=0.0, scale=0.5)   # boot -> drone clock: (20 + 0.5 b) / 2
    write_ulog_index(tmp_path / "logs" / "drone_1", [a, b], clock, (-3.0, 3.0, 0.0))
    t = local_position(tmp_path, 1)
    assert list(t["t_s"]) == pytest.approx([10.25, 10.275, 10.3, 10.325, 10.35, 12.25])
    assert list(t["pos_n"][:2]) == pytest.approx([-3.0, -2.9]) and t["pos_e"].iloc[-1] == pytest.approx(5.0)
    assert t["pos_d"][0] == pytest.approx(-3.0) and t["vx_m_s"][0] == pytest.approx(0.5)
    assert t["heading_rad"][0] == pytest.approx(0.25) and t["xy_valid"].all()
    assert t["px4_timestamp_us"].iloc[-1] == 9_000_000 and t["ulog_file"].iloc[-1] == "b.ulg"
    assert local_position(tmp_path, 2).empty


def test_build_is_found_from_config_env_or_shared_location(tmp_path, monkeypatch):
    build = tmp_path / "sitl"
    (build / "bin").mkdir(parents=True)
    (build / "etc").mkdir()
    (build / "bin" / "px4").write_text("#!/bin/sh\n")
    monkeypatch.setenv("HOME", str(tmp_path))
    assert resolve_build("~/sitl") == build.resolve()                     # `~` expanded
    assert resolve_build(None) is None and resolve_build("null") is None  # connect only
    assert resolve_build("auto", {"SWARMBOX_PX4_BUILD": str(build)}) == build.resolve()
    with pytest.raises(FileNotFoundError, match="SWARMBOX_PX4_BUILD: no PX4 SITL build at"):
        resolve_build("auto", {"SWARMBOX_PX4_BUILD": str(tmp_path / "nowhere")})
    with pytest.raises(FileNotFoundError, match="no PX4 SITL build at"):
        resolve_build(str(tmp_path / "nowhere"))


def test_aliases_that_lost_their_symlinks_are_linked_afresh(tmp_path):
    build = tmp_path / "sitl"
    (build / "bin").mkdir(parents=True)
    (build / "etc").mkdir()
    (build / "bin" / "px4").write_text("#!/bin/sh\n")
    (build / "bin" / "px4").chmod(0o755)
    (build / "bin" / "px4-alias.sh").write_text("alias x=y\n")
    (build / "bin" / "px4-param").write_text("px4")          # a copied symlink: plain text
    assert runnable_px4(build, tmp_path / "w") == tmp_path / "w" / "bin" / "px4"
    shadow = tmp_path / "w" / "bin"
    assert os.readlink(shadow / "px4-param") == "px4" and os.access(shadow / "px4-param", os.X_OK)
    assert (shadow / "px4").resolve() == (build / "bin" / "px4").resolve()
    assert (shadow / "px4-alias.sh").read_text() == "alias x=y\n"
    (build / "bin" / "px4-param").unlink()
    (build / "bin" / "px4-param").symlink_to("px4")
    assert runnable_px4(build, tmp_path / "w2") == build / "bin" / "px4"   # intact build: as is


@needs_px4
def test_hover_on_px4_sitl(run, tmp_path):
    out_dir = tmp_path / "px4run"
    manifest, d = run("algo=hover", "mission=hover", "algo.params.hover_s=3", "backend=px4",
                      f"backend.px4_build={PX4_BUILD}", f"run.out_dir={out_dir}", name="px4run")
    assert manifest["status"] == "ok", manifest["reason"] or manifest["traceback"]
    for i, home in enumerate([(0, 0), (5, 0), (10, 0), (15, 0)]):
        st = table(d, f"drone_{i}", "state")
        assert list(table(d, f"drone_{i}", "stages")["stage"]) == [1, 2, 3, 4, 5]
        assert st["pos_d"].min() < -2.5 and not st.iloc[-1]["armed"] and st.iloc[-1]["landed"]
        assert math.hypot(st.iloc[-1]["pos_n"] - home[0], st.iloc[-1]["pos_e"] - home[1]) < 2.5
        ulog = local_position(d, i)
        airborne = ulog[ulog["pos_d"] < -2.5]
        # the ULog's airborne span lies within the bridge's on the drone's clock
        assert len(airborne) and st["t_s"].min() - 1 < airborne["t_s"].min() < st["t_s"].max()


FAKE_PX4 = """#!/bin/sh
# Stands in for PX4's binary (`px4 -i N -d ETC`): a mavsim vehicle on PX4's port plan and home.
mkdir -p log/2025-01-01 && cp "$(dirname "$0")/../fake.ulg" log/2025-01-01/10_00_00.ulg
exec "$SWARMBOX_TEST_PYTHON" -m swarmbox.hal.mavsim.process --instance "$2" --home-lat "$PX4_HOME_LAT" \\
    --home-lon "$PX4_HOME_LON" --home-alt "$PX4_HOME_ALT" --port-plan px4 \\
    --speed "${PX4_SIM_SPEED_FACTOR:-1}" --max-wall-s 120
"""


def ports_free(ports) -> bool:
    import socket

    for port in ports:
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
            try:
                s.bind(("127.0.0.1", port))
            except OSError:
                return False
    return True


def test_launcher_runs_eleven_instances_on_px4_port_plan(tmp_path, monkeypatch):
    """SitlLauncher end to end, with mavsim behind a fake ``bin/px4``: PX4's ports, including the
    pinned remote port past instance 9, homes from PX4_HOME_*, ULogs collected at close()."""
    import sys

    from swarmbox.hal.px4.backend import Px4Backend
    from swarmbox.testing import Flight

    n = 11
    if not ports_free([*range(14540, 14551), *range(14580, 14580 + n), 24550]):
        pytest.skip("PX4's SITL ports on 127.0.0.1 are in use on this machine")
    build = tmp_path / "build"
    (build / "bin").mkdir(parents=True)
    (build / "etc").mkdir()
    (build / "bin" / "px4").write_text(FAKE_PX4)
    (build / "bin" / "px4").chmod(0o755)
    fake_ulog(build / "fake.ulg", [(k * 200_000, 0.0, 0.0, -0.1 * k) for k in range(10)])
    monkeypatch.setenv("SWARMBOX_TEST_PYTHON", sys.executable)
    monkeypatch.setenv("PYTHONPATH", str(Path(__file__).resolve().parents[2]))
    homes = [(3.0 * i, -2.0, 0.0) for i in range(n)]
    backend = Px4Backend(homes_ned_m=homes, tick_s=0.025, rng=np.random.default_rng(0), px4_build=str(build),
                         run_dir=str(tmp_path / "run"), speed=2.0, sitl={"start_stagger_s": 0.05})
    try:
        for v, home in zip(backend.vehicles, homes, strict=True):
            tel = v.telemetry()
            assert tel.ready_to_arm and math.dist(tel.pos_ned_m, home) < 0.5, (v.drone_id, tel)
            assert v.system_id == v.drone_id + 1
        Flight(backend).airborne(10)                 # commands reach an instance past the tenth
    finally:
        backend.close()
    for i in range(n):
        assert (tmp_path / "run" / "px4" / f"instance_{i}" / "out.log").is_file()
        ulog = local_position(tmp_path / "run", i)
        assert len(ulog) == 10 and ulog["pos_n"][0] == pytest.approx(3.0 * i)


def test_launching_and_closing_px4_loads_no_pandas(tmp_path):
    """The run path of a launched fleet (start, fly, stop, index the ULogs) never loads pandas or pyulog."""
    if not ports_free([14543, 14583]):
        pytest.skip("PX4's SITL ports on 127.0.0.1 are in use on this machine")
    build = tmp_path / "build"
    (build / "bin").mkdir(parents=True)
    (build / "etc").mkdir()
    (build / "bin" / "px4").write_text(FAKE_PX4.replace('--instance "$2"', '--instance 3'))
    (build / "bin" / "px4").chmod(0o755)
    fake_ulog(build / "fake.ulg", [(k * 200_000, 0.0, 0.0, -0.1 * k) for k in range(10)])
    code = f"""
import sys, numpy as np
from swarmbox.hal.px4 import backend, sitl
sitl.connection_of = lambda i: "udpin:127.0.0.1:14543"
backend.SitlLauncher.connections = lambda self: ["udpin:127.0.0.1:14543"]
b = backend.Px4Backend(homes_ned_m=[(0.0, 0.0, 0.0)], tick_s=0.025, rng=np.random.default_rng(0),
                       px4_build={str(build)!r}, run_dir={str(tmp_path / "run")!r}, speed=2.0, system_ids=[4])
for _ in range(40):
    b.step(0.025)
b.close()
print(sorted({{"pandas", "pyulog", "matplotlib"}} & set(sys.modules)))
"""
    env = {**os.environ, "SWARMBOX_TEST_PYTHON": sys.executable,
           "PYTHONPATH": str(Path(__file__).resolve().parents[2])}
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120, env=env)
    assert proc.returncode == 0 and proc.stdout.strip() == "[]", proc.stdout + proc.stderr
    assert (tmp_path / "run" / "logs" / "drone_0" / "ulog.json").is_file()
    assert len(local_position(tmp_path / "run", 0)) == 10
