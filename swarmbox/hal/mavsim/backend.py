"""The ``mavsim`` backend: the ``px4`` bridge, flying N mavsim vehicle processes it starts itself.

Everything between the swarm and the vehicles is the real bridge over real UDP sockets on
127.0.0.1; only the autopilots are :mod:`swarmbox.hal.mavsim.process` processes instead of PX4. The bridge
binds one free port per vehicle, starts each process with that port as its remote, waits until all
are ready to arm, and stops them at :meth:`close` (measuring their memory and CPU first).
"""

from __future__ import annotations

import atexit
import os
import shutil
import signal
import subprocess
import sys
import tempfile
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from swarmbox.hal.launch import ProcessSet, without_keys
from swarmbox.hal.mavlink.frames import GeoFrame
from swarmbox.hal.mavlink.signing import KEY_ENV
from swarmbox.hal.mavsim.options import MavsimOptions
from swarmbox.hal.px4.backend import BootClock, Px4Backend
from swarmbox.hal.safety import SafetyLimits
from swarmbox.hal.sim.params import SimParams

Vec3 = tuple[float, float, float]
_PACKAGE_ROOT = Path(__file__).resolve().parents[3]
STOP_TIMEOUT_S = 5.0


def proc_stats(pid: int) -> dict[str, float]:
    """Resident memory (now and peak, MB) and CPU time (s) of a live process, from /proc."""
    out: dict[str, float] = {}
    try:
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            key, _, value = line.partition(":")
            if key in ("VmRSS", "VmHWM"):
                out[key.lower() + "_mb"] = int(value.split()[0]) / 1024
        fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
        out["cpu_s"] = (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")
    except (OSError, ValueError, IndexError):
        pass
    return out


class MavsimLauncher(ProcessSet):
    """Starts one ``python -m swarmbox.hal.mavsim.process`` per vehicle on the bridge's ports."""

    what = "mavsim vehicle"

    def __init__(self, homes: list[Vec3], frame: GeoFrame, speed: float, seeds: list[int],
                 options: MavsimOptions, run_dir: Path | None, signing_key: str | None = None) -> None:
        self.homes, self.frame, self.speed, self.seeds, self.options = homes, frame, speed, seeds, options
        self.signing_key = signing_key   # handed to the vehicles in their environment, never their argv
        self._own_dir = run_dir is None
        self.log_dir = (Path(tempfile.mkdtemp(prefix="swarmbox_mavsim_")) if run_dir is None
                        else run_dir / "mavsim")
        self.procs: list[subprocess.Popen[bytes]] = []
        self.process_stats: list[dict[str, float]] = []
        self._reported: set[int] = set()
        self._stopped = False

    def connections(self) -> list[str]:
        return ["udpin:127.0.0.1:0"] * len(self.homes)

    def command(self, i: int, bridge_port: int) -> list[str]:
        o, (n, e, _) = self.options, self.homes[i]
        cmd = [sys.executable, "-m", "swarmbox.hal.mavsim.process", "--instance", str(i), "--home-n", repr(n),
               "--home-e", repr(e), "--origin-lat", repr(self.frame.lat_deg), "--origin-lon",
               repr(self.frame.lon_deg), "--origin-alt", repr(self.frame.alt_m), "--port-plan",
               f"{bridge_port}:0", "--speed", repr(self.speed), "--tick-s", repr(o.vehicle_tick_s),
               "--seed", str(self.seeds[i]), "--offboard-loss", o.offboard_loss,
               "--parent-pid", str(os.getpid())]
        for key, value in (o.sim or {}).items():
            cmd += ["--sim-param", f"{key}={value}"]
        for name in (o.refuse or {}).get(f"drone_{i}", ()):
            cmd += ["--refuse", str(name)]
        return cmd

    def start(self, local_ports: list[int]) -> None:
        self.log_dir.mkdir(parents=True, exist_ok=True)
        env = without_keys(os.environ)
        if self.signing_key:
            env[KEY_ENV] = str(self.signing_key)
        env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(_PACKAGE_ROOT), env.get("PYTHONPATH")]))
        atexit.register(self.stop)
        for i, port in enumerate(local_ports):
            with open(self.log_dir / f"vehicle_{i}.log", "wb") as log:
                self.procs.append(subprocess.Popen(self.command(i, port), stdin=subprocess.DEVNULL,
                                                   stdout=log, stderr=subprocess.STDOUT, env=env,
                                                   start_new_session=True))

    def _tail(self, i: int) -> str:
        try:
            return (self.log_dir / f"vehicle_{i}.log").read_text(errors="replace")[-2000:]
        except OSError:
            return ""

    def stop(self) -> None:
        if self._stopped:
            return
        self._stopped = True
        self.process_stats = [proc_stats(p.pid) if p.poll() is None else {} for p in self.procs]
        for proc in self.procs:
            if proc.poll() is None:
                proc.send_signal(signal.SIGTERM)
        for proc in self.procs:
            try:
                proc.wait(timeout=STOP_TIMEOUT_S)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait(timeout=STOP_TIMEOUT_S)

    def collect(self, run_dir: Path | None, clocks: list[BootClock]) -> list[str]:
        """mavsim keeps no flight log of its own; its console output stays in ``mavsim/``."""
        if self._own_dir:
            shutil.rmtree(self.log_dir, ignore_errors=True)
        return []


def _refusals(refuse: Mapping[Any, Sequence[str]], n: int) -> dict[str, tuple[str, ...]]:
    """``refuse`` checked: keys ``drone_<i>`` of existing vehicles, values lists of command names."""
    known = {f"drone_{i}" for i in range(n)}
    bad = [k for k in refuse if str(k) not in known]
    if bad:
        raise ValueError(f"mavsim backend: refuse names unknown vehicles {bad} "
                         f"(use drone_0 .. drone_{n - 1})")
    return {str(k): tuple(str(c) for c in v) for k, v in refuse.items()}


class MavsimBackend(Px4Backend):
    """The px4 bridge plus its own mavsim vehicles (implements :class:`swarmbox.hal.vehicle.Backend`).

    Keys: those of :class:`~swarmbox.hal.px4.backend.Px4Params` (minus ``px4_build``) plus
    :class:`MavsimOptions`. The vehicles' GNSS noise is seeded from ``rng``, so a run is repeatable
    up to the scheduling of the processes.
    """

    def __init__(self, *, homes_ned_m: Sequence[Sequence[float]], tick_s: float, rng: np.random.Generator,
                 obstacles: Sequence[Mapping[str, Any]] = (), limits: SafetyLimits = SafetyLimits(),
                 vehicle_tick_s: float = 0.01, offboard_loss: str = "hold",
                 sim: Mapping[str, float | bool | str] | None = None,
                 refuse: Mapping[Any, Sequence[str]] | None = None,
                 **params: Any) -> None:
        if params.get("px4_build"):
            raise ValueError("mavsim backend: px4_build is not used (use backend=px4 to launch PX4 SITL)")
        if not vehicle_tick_s > 0 or offboard_loss not in ("hold", "land", "rtl"):
            raise ValueError(f"mavsim backend: need vehicle_tick_s > 0 and offboard_loss hold|land|rtl, got "
                             f"{vehicle_tick_s!r}, {offboard_loss!r}")
        SimParams.from_kwargs(dict(sim or {}))   # fail here, not in N child processes
        self.options = MavsimOptions(float(vehicle_tick_s), offboard_loss, dict(sim or {}),
                                     _refusals(refuse or {}, len(homes_ned_m)))
        self._seeds = [int(s) for s in rng.integers(0, 2**31 - 1, size=len(homes_ned_m))]
        super().__init__(homes_ned_m=homes_ned_m, tick_s=tick_s, rng=rng, obstacles=obstacles, limits=limits,
                         **params)

    def _make_launcher(self, homes: list[Vec3]) -> MavsimLauncher | None:
        if self.params.connections:   # vehicles that already run (a shared host of a distributed run)
            return None
        return MavsimLauncher(homes, self.frame, self.params.speed, self._seeds, self.options, self.run_dir,
                              self.params.signing_key)

    @property
    def processes(self) -> list[subprocess.Popen[bytes]]:
        """The vehicle processes, in vehicle order (for fault injection in tests)."""
        return self.launcher.procs if isinstance(self.launcher, MavsimLauncher) else []

    @property
    def process_stats(self) -> list[dict[str, float]]:
        """Per vehicle process, measured at :meth:`close`: ``vmrss_mb``, ``vmhwm_mb``, ``cpu_s``."""
        return self.launcher.process_stats if isinstance(self.launcher, MavsimLauncher) else []
