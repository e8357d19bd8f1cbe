"""Launch PX4 SITL instances (SIH mode) for the ``px4`` backend, and collect their ULogs.

For a PX4 build (``px4_sitl_default``) and N vehicles, instance ``i`` runs as::

    PX4_SIM_MODEL=sihsim_quadx PX4_HOME_LAT=.. PX4_HOME_LON=.. PX4_HOME_ALT=.. \\
        [PX4_SIM_SPEED_FACTOR=k] [PX4_PARAM_<NAME>=<value> ...] <build>/bin/px4 -i i -d <build>/etc

in its own working directory (``<run dir>/px4/instance_i``: parameters, dataman, ``out.log``,
``err.log`` and the ULogs), with its home at the mission origin plus its initial position.

Port plan: PX4's API link of instance ``i`` listens on 14580+i and sends to 14540+i, except that
for i > 9 PX4 pins the remote port to 14549 for every instance. PX4 adopts the first address that
talks to it for good, so from the eleventh vehicle on the bridge binds its own port 24540+i and
speaks first to 14580+i (``udp:127.0.0.1:24540+i@127.0.0.1:14580+i``); a later run binds the same
port and reaches the same instance. Instances 0..9 use PX4's default ``udpin:127.0.0.1:14540+i``.

Where the build is (``px4_build``): a path (``~`` expanded) to the build or to a PX4-Autopilot tree;
``auto``: ``$SWARMBOX_PX4_BUILD``, else ``../shared/px4-sitl`` next to the repository, else no launch
(connect to vehicles that already run); ``null``: never launch.

A build whose command aliases (``bin/px4-param`` ...) lost their symlinks in a copy still runs: the
launcher then links them afresh in ``<work dir>/bin`` and starts PX4 from there.

After the run each instance's ULogs stay in its working directory and ``logs/drone_<i>/ulog.json``
records them with the vehicle's :class:`~swarmbox.hal.px4.params.BootClock` (boot time -> that
drone's clock) and home; :mod:`swarmbox.analysis.ulog` turns them into tables on the run's timeline
(parsing ULogs is the analyzer's job, not the run's).
"""

from __future__ import annotations

import atexit
import json
import os
import shutil
import signal
import subprocess
import tempfile
import time
from collections.abc import Mapping
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Any

from swarmbox.hal.launch import ProcessSet, without_keys
from swarmbox.hal.mavlink.frames import GeoFrame
from swarmbox.hal.px4.params import BootClock, Px4Params
from swarmbox.hal.safety import SafetyLimits, px4_geofence

Vec3 = tuple[float, float, float]
ENV_BUILD = "SWARMBOX_PX4_BUILD"
#: where CI keeps a prebuilt SITL: ``shared/px4-sitl`` next to the repository (or the working directory)
SHARED_BUILDS = (Path(__file__).resolve().parents[4] / "shared" / "px4-sitl",
                 Path("..") / "shared" / "px4-sitl")
ULOG_INDEX = "ulog.json"


@dataclass(frozen=True, slots=True)
class SitlOptions:
    """The ``sitl`` mapping of ``conf/backend/px4.yaml``."""

    model: str = "sihsim_quadx"       # PX4_SIM_MODEL
    start_stagger_s: float = 0.3      # wall s between instance starts
    stop_timeout_s: float = 10.0      # wall s to exit after SIGTERM before SIGKILL
    logger: bool = True               # False: PX4_PARAM_SDLOG_MODE=-1 (no ULog)
    params: Mapping[str, Any] = field(default_factory=dict)   # PX4 parameters, NAME: value
    first_instance: int = 0           # vehicle i runs as PX4 instance first_instance + i (system id + 1)

    @classmethod
    def from_mapping(cls, values: Mapping[str, Any]) -> SitlOptions:
        known = {f.name for f in fields(cls)}
        for key in values:
            if key not in known:
                raise TypeError(f"unknown px4 backend sitl option {key!r} "
                                f"(known: {', '.join(sorted(known))})")
        opts = cls(**values)
        if not isinstance(opts.first_instance, int) or not 0 <= opts.first_instance <= 200:
            raise ValueError(f"px4 backend sitl.first_instance must be an integer 0-200, "
                             f"got {opts.first_instance!r}")
        return opts


def find_build(path: str | Path) -> Path:
    """The ``px4_sitl_default`` build directory of ``path`` (the build itself or a PX4 source tree)."""
    p = Path(path).expanduser()
    for candidate in (p, p / "build" / "px4_sitl_default"):
        if (candidate / "bin" / "px4").is_file() and (candidate / "etc").is_dir():
            return candidate.resolve()
    raise FileNotFoundError(f"no PX4 SITL build at {p}: expected bin/px4 and etc/ there or in "
                            "build/px4_sitl_default (build PX4 with `make px4_sitl_default`)")


def resolve_build(configured: str | None, env: Mapping[str, str] | None = None) -> Path | None:
    """The PX4 build to launch for ``px4_build`` (see the module docstring); None: connect only.

    A configured path or ``$SWARMBOX_PX4_BUILD`` that holds no build raises FileNotFoundError naming it.
    """
    env = os.environ if env is None else env
    if configured is None or str(configured).strip().lower() in ("", "null", "none"):
        return None
    if str(configured).strip().lower() != "auto":
        return find_build(configured)
    if env.get(ENV_BUILD):
        try:
            return find_build(env[ENV_BUILD])
        except FileNotFoundError as exc:
            raise FileNotFoundError(f"{ENV_BUILD}: {exc}") from None
    for candidate in SHARED_BUILDS:
        try:
            return find_build(candidate)
        except FileNotFoundError:
            pass
    return None


def runnable_px4(build: Path, work_dir: Path) -> Path:
    """The ``px4`` binary to start. PX4's startup script calls ``px4-<module>`` aliases from the
    binary's directory; where a copy turned those symlinks into plain files, link them afresh under
    ``work_dir/bin`` (PX4 puts the directory it was started from on its PATH)."""
    binary = build / "bin" / "px4"
    aliases = [p for p in (build / "bin").glob("px4-*") if p.suffix != ".sh"]
    if all(os.access(p, os.X_OK) for p in aliases):
        return binary
    shadow = work_dir / "bin"
    shadow.mkdir(parents=True, exist_ok=True)
    for p in (binary, *(build / "bin").glob("px4-*")):
        link = shadow / p.name
        if not link.is_symlink():
            link.symlink_to("px4" if p in aliases else p)
    return shadow / "px4"


def connection_of(i: int) -> str:
    """The bridge's connection string for PX4 instance ``i`` (see the module docstring)."""
    if i <= 9:
        return f"udpin:127.0.0.1:{14540 + i}"
    return f"udp:127.0.0.1:{24540 + i}@127.0.0.1:{14580 + i}"


def instance_env(home_geo: tuple[float, float, float], options: SitlOptions, speed: float,
                 base: Mapping[str, str], fence: Mapping[str, float | int] | None = None) -> dict[str, str]:
    """The environment of one PX4 instance: model, home, speed factor, parameters (``fence``: PX4's
    geofence parameters, which the configured ``sitl.params`` may override)."""
    env = dict(base)
    lat, lon, alt = home_geo
    env.update(PX4_SIM_MODEL=options.model, PX4_HOME_LAT=f"{lat:.9f}", PX4_HOME_LON=f"{lon:.9f}",
               PX4_HOME_ALT=f"{alt:.3f}")
    if speed != 1.0:
        env["PX4_SIM_SPEED_FACTOR"] = f"{speed:g}"
    if not options.logger:
        env["PX4_PARAM_SDLOG_MODE"] = "-1"
    env["PX4_PARAM_SYS_FAILURE_EN"] = "1"   # MAV_CMD_INJECT_FAILURE answered (simulation only)
    for name, value in (fence or {}).items():
        env[f"PX4_PARAM_{name}"] = str(value)
    for name, value in options.params.items():
        env[f"PX4_PARAM_{name.upper()}"] = str(value)
    return env


class SitlLauncher(ProcessSet):
    """Starts, watches and stops N PX4 SITL instances (a :class:`~swarmbox.hal.px4.backend.Launcher`)."""

    what = "PX4 instance"

    def __init__(self, params: Px4Params, homes: list[Vec3], frame: GeoFrame, run_dir: Path | None,
                 limits: SafetyLimits | None = None) -> None:
        build = resolve_build(params.px4_build)
        if build is None:
            raise ValueError(f"px4 backend: no PX4 build to launch for px4_build={params.px4_build!r}")
        self.build = build
        self.options = SitlOptions.from_mapping(params.sitl)
        self.homes, self.frame, self.speed = homes, frame, params.speed
        self.limits = limits   # the safety envelope, mirrored in PX4's own geofence (None: PX4's defaults)
        self._own_dir = run_dir is None   # a temporary working directory, removed after the run
        self.work_dir = (run_dir / "px4" if run_dir is not None
                         else Path(tempfile.mkdtemp(prefix="swarmbox_px4_")))
        self.binary = runnable_px4(build, self.work_dir)
        self.procs: list[subprocess.Popen[bytes]] = []
        self._reported: set[int] = set()
        self._stopped = False

    def instance(self, i: int) -> int:
        """PX4's instance number of vehicle ``i`` (its ports, ``/tmp/px4-sock-<n>``, system id n+1)."""
        return self.options.first_instance + i

    def connections(self) -> list[str]:
        return [connection_of(self.instance(i)) for i in range(len(self.homes))]

    def system_ids(self) -> list[int]:
        return [self.instance(i) + 1 for i in range(len(self.homes))]

    def instance_dir(self, i: int) -> Path:
        return self.work_dir / f"instance_{i}"

    def start(self, local_ports: list[int]) -> None:
        atexit.register(self.stop)   # PX4 runs in its own session: never leave instances behind
        for i, home in enumerate(self.homes):
            wd = self.instance_dir(i)
            wd.mkdir(parents=True, exist_ok=True)
            fence = None if self.limits is None else px4_geofence(self.limits, home)
            env = instance_env(self.frame.geodetic_of(home), self.options, self.speed,
                               without_keys(os.environ), fence)
            cmd = [str(self.binary), "-i", str(self.instance(i)), "-d", str(self.build / "etc")]
            with open(wd / "out.log", "wb") as out, open(wd / "err.log", "wb") as err:
                self.procs.append(subprocess.Popen(cmd, cwd=wd, env=env, stdin=subprocess.DEVNULL, stdout=out,
                                                   stderr=err, start_new_session=True))
            if i + 1 < len(self.homes):
                time.sleep(self.options.start_stagger_s)

    def _tail(self, i: int) -> str:
        text = []
        for name in ("out.log", "err.log"):
            try:
                text.append((self.instance_dir(i) / name).read_text(errors="replace")[-1500:])
            except OSError:
                pass
        return "\n".join(text)

    def stop(self) -> None:
        if self._stopped:
            return
        self._stopped = True
        for proc in self.procs:
            if proc.poll() is None:
                proc.send_signal(signal.SIGTERM)
        deadline = time.monotonic() + self.options.stop_timeout_s
        for proc in self.procs:
            try:
                proc.wait(timeout=max(0.1, deadline - time.monotonic()))
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait(timeout=5.0)

    def collect(self, run_dir: Path | None, clocks: list[BootClock]) -> list[str]:
        """Index each instance's ULogs with its clock and home in ``logs/drone_<i>/ulog.json``;
        returns what could not be collected, per drone (the run records it in ``problems``)."""
        if self._own_dir:
            shutil.rmtree(self.work_dir, ignore_errors=True)
        if run_dir is None or not self.options.logger:
            return []
        problems = []
        for i, home in enumerate(self.homes):
            try:
                ulogs = sorted(self.instance_dir(i).rglob("*.ulg"), key=lambda p: p.stat().st_mtime)
                if not ulogs:
                    problems.append(f"drone {i}: no ULog in {self.instance_dir(i)} (PX4's logger wrote none)")
                    continue
                write_ulog_index(run_dir / "logs" / f"drone_{i}", ulogs, clocks[i], home)
            except OSError as exc:
                problems.append(f"drone {i}: its ULogs could not be indexed: {exc.strerror or exc}")
        return problems


def write_ulog_index(drone_dir: Path, ulogs: list[Path], clock: BootClock, home_ned_m: Vec3) -> Path:
    """``ulog.json``: the ULog files (relative to ``drone_dir``), in order, the boot clock and home."""
    drone_dir.mkdir(parents=True, exist_ok=True)
    index = {"files": [os.path.relpath(p, drone_dir) for p in ulogs], "clock": clock.as_dict(),
             "home_ned_m": list(home_ned_m)}
    out = drone_dir / ULOG_INDEX
    tmp = out.with_name(f".{out.name}.tmp")
    tmp.write_text(json.dumps(index, indent=1))
    os.replace(tmp, out)
    return out
