"""``run.net.vehicle_host=shared``: one mavsim host process flying every vehicle of a distributed run.

The launcher starts it before the nodes (the vehicles stand for autopilots, which exist apart from
the companion computers), on one free UDP port of 127.0.0.1 per vehicle for the agent's bridge;
each agent then connects to its vehicle (``plan.json`` ``vehicles``) as to a running autopilot.
The vehicle outlives its agent: an agent killed and restarted finds its drone where the
failsafe left it (untested: the rejoin test uses one vehicle per agent). The host runs
:mod:`swarmbox.hal.mavsim.host`; its output is in ``nodes/mavsim_host.log``.
"""

from __future__ import annotations

import json
import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

from omegaconf import DictConfig, OmegaConf

from swarmbox.record.schema import node_name
from swarmbox.run import build

HOSTS = ("agent", "shared")
STOP_TIMEOUT_S = 10.0


def free_ports(n: int, kind: int = socket.SOCK_STREAM) -> list[int]:
    """``n`` distinct ports (TCP, or UDP with ``socket.SOCK_DGRAM``) the OS reports free on 127.0.0.1."""
    socks = []
    try:
        for _ in range(n):
            s = socket.socket(socket.AF_INET, kind)
            s.bind(("127.0.0.1", 0))
            socks.append(s)
        return [s.getsockname()[1] for s in socks]
    finally:
        for s in socks:
            s.close()


class VehicleHost:
    """The host process; :meth:`stop` ends it (SIGTERM, then SIGKILL)."""

    def __init__(self, proc: subprocess.Popen[bytes], n: int) -> None:
        self.proc, self.n, self.started = proc, n, time.monotonic()
        self.stats: dict[str, float] = {}

    def stop(self) -> None:
        """Measure the host (CPU s, peak RSS, wall s), then end it."""
        if self.proc.poll() is None and not self.stats:
            from swarmbox.hal.mavsim.backend import proc_stats

            self.stats = dict(proc_stats(self.proc.pid), wall_s=time.monotonic() - self.started,
                              vehicles=self.n)
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGTERM)
            try:
                self.proc.wait(timeout=STOP_TIMEOUT_S)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()


def check(cfg: DictConfig) -> str:
    """``run.net.vehicle_host``, checked (ValueError naming the allowed values)."""
    host = str(cfg.run.net.get("vehicle_host", "agent"))
    if host not in HOSTS:
        raise ValueError(f"run.net.vehicle_host must be one of {', '.join(HOSTS)}, got {host!r}")
    return host


def start(cfg: DictConfig, m: Any, run_dir: Path, env: dict[str, str]) -> tuple[VehicleHost | None,
                                                                              dict[str, dict[str, Any]]]:
    """Start the shared host for ``backend=mavsim`` with ``run.net.vehicle_host=shared``.

    Returns the host (None when not asked for) and each agent's connection settings.
    """
    if check(cfg) == "agent" or cfg.backend.get("name") != "mavsim":
        return None, {}
    from swarmbox.hal.mavlink.frames import GeoFrame
    from swarmbox.hal.mavsim.backend import MavsimLauncher, MavsimOptions

    b = OmegaConf.to_container(cfg.backend, resolve=True)
    sim = {k: v for k, v in (b.get("sim") or {}).items() if v is not None}
    options = MavsimOptions(float(b["vehicle_tick_s"]), str(b["offboard_loss"]), sim,
                            {str(k): tuple(v) for k, v in (b.get("refuse") or {}).items()})
    homes = [tuple(float(x) for x in m.initial_positions[i]) for i in m.drone_ids]
    rng = build.rng_for(int(cfg.seed), "backend")
    seeds = [int(s) for s in rng.integers(0, 2**31 - 1, size=len(homes))]
    frame = GeoFrame(float(b["origin_lat_deg"]), float(b["origin_lon_deg"]), float(b["origin_alt_m"]))
    plan = MavsimLauncher(homes, frame, float(b["speed"]), seeds, options, run_dir / "nodes")
    ports = free_ports(len(homes), socket.SOCK_DGRAM)
    vehicles = [plan.command(k, port)[3:] for k, port in enumerate(ports)]   # drop "python -m module"
    for argv in vehicles:
        k = argv.index("--parent-pid")
        del argv[k:k + 2]
    spec = run_dir / "nodes" / "mavsim_host.json"
    spec.write_text(json.dumps({"vehicles": vehicles}))
    cmd = [sys.executable, "-m", "swarmbox.hal.mavsim.host", "--spec", str(spec),
           "--parent-pid", str(os.getpid())]
    with open(run_dir / "nodes" / "mavsim_host.log", "wb") as out:
        proc = subprocess.Popen(cmd, stdin=subprocess.DEVNULL, stdout=out, stderr=subprocess.STDOUT, env=env,
                                start_new_session=True)
    return VehicleHost(proc, len(homes)), {
        node_name(i): {"connections": [f"udpin:127.0.0.1:{ports[k]}"], "system_ids": [k + 1]}
        for k, i in enumerate(m.drone_ids)}
