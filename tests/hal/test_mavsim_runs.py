"""Whole missions through the px4 bridge over UDP on 127.0.0.1, with four mavsim vehicles.

The same algorithm classes as on ``sim``; vehicles and run loop at speed 4 (``run.speed``) on a
free machine, slower on a loaded one (``tests/realtime.py``).
"""

from __future__ import annotations

import json
import math
import signal
import socket
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial import cKDTree

from swarmbox.hal.mavlink import codec as mc
from tests import realtime
from tests.conftest import table

pytestmark = pytest.mark.slow   # whole missions in wall-clock time

ROOT = Path(__file__).resolve().parents[2]
SPEED = realtime.speed(4.0)       # 4 on a free machine; slower when the cores are shared
FAST = (f"run.speed={SPEED}",)
HOVER = ("algo=hover", "mission=hover", "algo.params.hover_s=2", *FAST)
SHORT_FORMATION = ("algo=formation", "mission=formation", "algo.params.start_s=2",
                   "algo.params.angular_rate_rad_s=0.6", "algo.params.complete_after_s=8")
HOMES = {"hover": [(0, 0), (5, 0), (10, 0), (15, 0)], "formation": [(0, 0), (-3, -3), (-3, 3), (-6, -6)]}


def events(run_dir: Path, i: int):
    return table(run_dir, f"drone_{i}", "events")


def assert_clean_mission(manifest: dict, run_dir: Path, homes: list[tuple[float, float]]) -> None:
    assert manifest["status"] == "ok", manifest["reason"] or manifest["traceback"]
    for i, home in enumerate(homes):
        assert list(table(run_dir, f"drone_{i}", "stages")["stage"]) == [1, 2, 3, 4, 5]
        last = table(run_dir, f"drone_{i}", "state").iloc[-1]
        assert not last["armed"] and last["landed"], f"drone {i} did not land and disarm"
        assert math.hypot(last["pos_n"] - home[0], last["pos_e"] - home[1]) < 1.0, f"drone {i} landed away"
        ev = events(run_dir, i)
        assert "connected" in set(ev["name"]), f"drone {i}: no link/connected event"
        assert not (ev["kind"] == "safety").any(), ev[ev["kind"] == "safety"]


def test_hover_on_mavsim(run):
    manifest, d = run(*HOVER, "backend=mavsim")
    assert_clean_mission(manifest, d, HOMES["hover"])
    assert manifest["choices"]["backend"] == "mavsim" and manifest["real_time_factor"] > 0.6 * SPEED
    for i in range(4):
        ev = events(d, i)
        reached = ev[ev["name"] == "reached_altitude"]
        assert len(reached) == 1 and json.loads(reached["data"].iloc[0])["altitude_m"] > 2.6
        st = table(d, f"drone_{i}", "state")
        hover = st[(st["stage"] == 3) & (st["mode"] == "offboard")]
        assert hover["true_d"].iloc[-40:].between(-3.3, -2.7).all()     # ground truth streamed by mavsim
        assert st["gnss_n"].notna().any()


def path_rmse(ref: np.ndarray, other: np.ndarray) -> float:
    dist, _ = cKDTree(ref).query(other)
    return float(np.sqrt(np.mean(dist ** 2)))


def exec_track(run_dir: Path, i: int) -> np.ndarray:
    st = table(run_dir, f"drone_{i}", "state")
    return st.loc[st["stage"] == 3, ["pos_n", "pos_e"]].to_numpy()


def test_short_formation_on_mavsim_flies_the_sim_paths(run):
    sim_manifest, sim_dir = run(*SHORT_FORMATION)
    manifest, d = run(*SHORT_FORMATION, *FAST, "backend=mavsim")
    assert sim_manifest["status"] == "ok"
    assert_clean_mission(manifest, d, HOMES["formation"])
    lead = exec_track(d, 0)
    assert 17.0 < np.ptp(lead[:, 0]) < 19.5 and 17.0 < np.ptp(lead[:, 1]) < 19.5   # the 9 m circle
    for i in range(4):
        assert path_rmse(exec_track(sim_dir, i), exec_track(d, i)) < 0.3, f"drone {i} left the sim path"


def free_ports(n: int) -> list[int]:
    socks = [socket.socket(socket.AF_INET, socket.SOCK_DGRAM) for _ in range(n)]
    for s in socks:
        s.bind(("127.0.0.1", 0))
    ports = [s.getsockname()[1] for s in socks]
    for s in socks:
        s.close()
    return ports


def test_px4_backend_flies_running_mavsim_instances(run):
    ports = free_ports(4)
    procs = [subprocess.Popen([sys.executable, "-m", "swarmbox.hal.mavsim.process", "--instance", str(i),
                               "--home-n", str(5.0 * i), "--port-plan", f"{port}:0", "--speed", str(SPEED),
                               "--max-wall-s", "120"], cwd=ROOT, stdout=subprocess.DEVNULL,
                              stderr=subprocess.DEVNULL) for i, port in enumerate(ports)]
    try:
        conns = ",".join(f"'udpin:127.0.0.1:{p}'" for p in ports)
        manifest, d = run(*HOVER, "backend=px4", f"backend.connections=[{conns}]", "backend.wait_ready=true")
    finally:
        for p in procs:
            p.terminate()
            p.wait(timeout=10)
    assert_clean_mission(manifest, d, HOMES["hover"])
    assert table(d, "drone_0", "state")["true_d"].isna().all()   # px4 backend: no ground truth requested


def run_in_subprocess(run_dir: Path, overrides: list[str]) -> dict:
    """Run a config in a fresh interpreter; report its status, heavy modules loaded and peak RSS."""
    code = ("import sys, json, resource, pathlib; from tests.conftest import run_config; "
            f"m = run_config(pathlib.Path({str(run_dir)!r}), {overrides!r}); "
            "print(json.dumps({'status': m['status'], 'modules': sorted({'pandas', 'matplotlib', 'seaborn'} "
            "& set(sys.modules)), 'maxrss_mb': resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024}))")
    proc = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=180)
    assert proc.returncode == 0, proc.stderr[-3000:]
    return json.loads(proc.stdout.strip().splitlines()[-1])


def test_runner_stays_small(tmp_path):
    """A mavsim run never loads pandas, matplotlib or seaborn into the runner process."""
    out = run_in_subprocess(tmp_path / "mavsim", [*HOVER, "backend=mavsim"])
    # Alone this run peaks near 140 MB; on a saturated machine the bridge buffers more traffic.
    assert out["status"] == "ok" and out["maxrss_mb"] < 1000, out
    assert not {"pandas", "matplotlib", "seaborn"} & set(out["modules"]), out


def test_px4_path_imports_neither_the_simulator_nor_analysis_libraries():
    code = ("import sys, swarmbox.hal.px4.backend, swarmbox.hal.px4.sitl, swarmbox.hal.mavsim.backend; "
            "print(sorted({'pandas', 'matplotlib', 'seaborn', 'pymunk', 'swarmbox.hal.sim.backend', "
            "'pyulog'} & set(sys.modules)))")
    proc = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=60)
    assert proc.returncode == 0 and proc.stdout.strip() == "[]", proc.stdout + proc.stderr


def inject_faults(swarm) -> None:
    """Vehicle 1's radio goes silent for 4.5 s; garbage and a foreign system hit every link;
    vehicle 2 is told to disarm in the air (NACKed)."""
    backend = swarm.backend
    radio = backend.processes[1]
    intruder, liar = mc.GcsEncoder(system_id=42, component_id=1), mc.mavlink.MAVLink(None, 42, 1)
    bogus = bytes(liar.local_position_ned_encode(0, 99.0, 99.0, -50.0, 0, 0, 0).pack(liar))

    def noise(_swarm) -> None:
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
            for port in backend.local_ports:
                s.sendto(b"\xde\xad\xbe\xef" * 8 + b"\xfd\x20", ("127.0.0.1", port))
                s.sendto(intruder.heartbeat() + bogus, ("127.0.0.1", port))

    for t in (2.0, 2.5, 3.0):
        swarm.schedule(t, noise)
    swarm.schedule(3.0, lambda s: radio.send_signal(signal.SIGUSR1))
    swarm.schedule(7.5, lambda s: radio.send_signal(signal.SIGUSR1))
    swarm.schedule(4.0, lambda s: s.backend.vehicles[2].disarm())


def test_faulty_links_are_logged_and_survived(run):
    manifest, d = run("algo=hover", "mission=hover", "algo.params.hover_s=9", *FAST, "backend=mavsim",
                      "backend.link_timeout_s=2", prepare=inject_faults)
    names = {i: list(events(d, i)["name"]) for i in range(4)}
    for i in range(4):
        assert {"garbage", "foreign_system"} <= set(names[i]), (i, names[i])
        assert math.dist(table(d, f"drone_{i}", "state")[["pos_n", "pos_e"]].max(), HOMES["hover"][i]) < 1.0
    lost = names[1]
    assert lost.index("lost") < lost.index("regained"), lost
    nack = events(d, 2)
    nack = nack[nack["name"] == "nack"]
    assert len(nack) == 1 and json.loads(nack["data"].iloc[0])["result"] == "denied"
    for i in range(4):
        last = table(d, f"drone_{i}", "state").iloc[-1]
        assert last["landed"] and not last["armed"]


def test_lost_vehicle_link_triggers_the_agent_failsafe(run):
    manifest, d = run("algo=hover", "mission=hover", "algo.params.hover_s=9", *FAST, "backend=mavsim",
                      "backend.link_timeout_s=2", prepare=inject_faults)
    stages = table(d, "drone_1", "stages")
    abort = stages[stages["stage"] == -1]
    assert len(abort) == 1 and "link" in abort["reason"].iloc[0]
    last = table(d, "drone_1", "state").iloc[-1]
    assert last["landed"] and not last["armed"]
