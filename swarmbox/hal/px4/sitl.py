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

After the run each instance's ``vehicle_local_position`` goes to
``<run dir>/logs/drone_<i>/ulog_local_position.parquet`` with ``t_s`` on that drone's clock (the
bridge fits PX4's boot time to the run's time from LOCAL_POSITION_NED arrivals).
"""

from __future__ import annotations

import atexit
import os
import signal
import subprocess
import tempfile
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from swarmbox.hal.launch import ProcessSet
from swarmbox.hal.mavlink.frames import GeoFrame

if TYPE_CHECKING:
    from swarmbox.hal.px4.backend import BootClock, Px4Params

Vec3 = tuple[float, float, float]
ULOG_TABLE = "ulog_local_position"
_ULOG_FIELDS = (("x", "x_m"), ("y", "y_m"), ("z", "z_m"), ("vx", "vx_m_s"), ("vy", "vy_m_s"),
                ("vz", "vz_m_s"), ("heading", "heading_rad"))


@dataclass(frozen=True, slots=True)
class SitlOptions:
    """The ``sitl`` mapping of ``conf/backend/px4.yaml``."""

    model: str = "sihsim_quadx"       # PX4_SIM_MODEL
    start_stagger_s: float = 0.3      # wall s between instance starts
    stop_timeout_s: float = 10.0      # wall s to exit after SIGTERM before SIGKILL
    logger: bool = True               # False: PX4_PARAM_SDLOG_MODE=-1 (no ULog)
    params: Mapping[str, Any] = field(default_factory=dict)   # PX4 parameters, NAME: value

    @classmethod
    def from_mapping(cls, values: Mapping[str, Any]) -> SitlOptions:
        known = {f.name for f in fields(cls)}
        for key in values:
            if key not in known:
                raise TypeError(f"unknown px4 backend sitl option {key!r} "
                                f"(known: {', '.join(sorted(known))})")
        return cls(**values)


def find_build(path: str | Path) -> Path:
    """The ``px4_sitl_default`` build directory of ``path`` (the build itself or a PX4 source tree)."""
    p = Path(path).expanduser()
    for candidate in (p, p / "build" / "px4_sitl_default"):
        if (candidate / "bin" / "px4").is_file() and (candidate / "etc").is_dir():
            return candidate.resolve()
    raise FileNotFoundError(f"no PX4 SITL build at {p}: expected bin/px4 and etc/ there or in "
                            "build/px4_sitl_default (build PX4 with `make px4_sitl_default`)")


def connection_of(i: int) -> str:
    """The bridge's connection string for PX4 instance ``i`` (see the module docstring)."""
    if i <= 9:
        return f"udpin:127.0.0.1:{14540 + i}"
    return f"udp:127.0.0.1:{24540 + i}@127.0.0.1:{14580 + i}"


def instance_env(home_geo: tuple[float, float, float], options: SitlOptions, speed: float,
                 base: Mapping[str, str]) -> dict[str, str]:
    """The environment of one PX4 instance: model, home, speed factor, parameters."""
    env = dict(base)
    lat, lon, alt = home_geo
    env.update(PX4_SIM_MODEL=options.model, PX4_HOME_LAT=f"{lat:.9f}", PX4_HOME_LON=f"{lon:.9f}",
               PX4_HOME_ALT=f"{alt:.3f}")
    if speed != 1.0:
        env["PX4_SIM_SPEED_FACTOR"] = f"{speed:g}"
    if not options.logger:
        env["PX4_PARAM_SDLOG_MODE"] = "-1"
    for name, value in options.params.items():
        env[f"PX4_PARAM_{name.upper()}"] = str(value)
    return env


class SitlLauncher(ProcessSet):
    """Starts, watches and stops N PX4 SITL instances (a :class:`~swarmbox.hal.px4.backend.Launcher`)."""

    what = "PX4 instance"

    def __init__(self, params: Px4Params, homes: list[Vec3], frame: GeoFrame, run_dir: Path | None) -> None:
        self.build = find_build(params.px4_build or "")
        self.options = SitlOptions.from_mapping(params.sitl)
        self.homes, self.frame, self.speed = homes, frame, params.speed
        self.work_dir = (run_dir / "px4" if run_dir is not None
                         else Path(tempfile.mkdtemp(prefix="swarmbox_px4_")))
        self.procs: list[subprocess.Popen[bytes]] = []
        self._reported: set[int] = set()
        self._stopped = False

    def connections(self) -> list[str]:
        return [connection_of(i) for i in range(len(self.homes))]

    def instance_dir(self, i: int) -> Path:
        return self.work_dir / f"instance_{i}"

    def start(self, local_ports: list[int]) -> None:
        atexit.register(self.stop)   # PX4 runs in its own session: never leave instances behind
        for i, home in enumerate(self.homes):
            wd = self.instance_dir(i)
            wd.mkdir(parents=True, exist_ok=True)
            env = instance_env(self.frame.geodetic_of(home), self.options, self.speed, os.environ)
            cmd = [str(self.build / "bin" / "px4"), "-i", str(i), "-d", str(self.build / "etc")]
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

    def collect(self, run_dir: Path | None, clocks: list[BootClock]) -> None:
        """Each instance's ULogs -> ``logs/drone_<i>/ulog_local_position.parquet`` (if any)."""
        if run_dir is None or not self.options.logger:
            return
        for i, home in enumerate(self.homes):
            ulogs = sorted(self.instance_dir(i).rglob("*.ulg"), key=lambda p: p.stat().st_mtime)
            out = run_dir / "logs" / f"drone_{i}" / f"{ULOG_TABLE}.parquet"
            if ulogs:
                write_ulog_table(ulogs, clocks[i], home, out)


def ulog_local_position(paths: Sequence[Path], clock: BootClock, home_ned_m: Vec3) -> dict[str, np.ndarray]:
    """``vehicle_local_position`` of ULog files as columns, with ``t_s`` on the drone's clock and
    ``pos_n/pos_e/pos_d`` in the mission frame (local + home, as the bridge converts)."""
    from pyulog import ULog

    parts: list[dict[str, np.ndarray]] = []
    for path in paths:
        ulog = ULog(str(path), ["vehicle_local_position"])
        for data in ulog.data_list:
            if data.name != "vehicle_local_position" or data.multi_id != 0:
                continue
            d = data.data
            stamp = d["timestamp"].astype(np.int64)
            cols = {"t_s": clock(stamp / 1e6), "px4_timestamp_us": stamp}
            for src, dst in _ULOG_FIELDS:
                cols[dst] = d[src].astype(np.float64) if src in d else np.full(len(stamp), np.nan)
            for k, axis in enumerate(("pos_n", "pos_e", "pos_d")):
                cols[axis] = cols[("x_m", "y_m", "z_m")[k]] + home_ned_m[k]
            for flag in ("xy_valid", "z_valid"):
                cols[flag] = d[flag].astype(bool) if flag in d else np.zeros(len(stamp), dtype=bool)
            cols["ulog_file"] = np.array([path.name] * len(stamp), dtype=object)
            parts.append(cols)
    if not parts:
        return {}
    return {key: np.concatenate([p[key] for p in parts]) for key in parts[0]}


def write_ulog_table(paths: Sequence[Path], clock: BootClock, home_ned_m: Vec3, out: Path) -> Path | None:
    """Write :func:`ulog_local_position` as Parquet (atomically); None if the logs hold no rows."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    cols = ulog_local_position(paths, clock, home_ned_m)
    if not cols:
        return None
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = out.with_name(f".{out.name}.tmp")
    pq.write_table(pa.table({k: pa.array(v) for k, v in cols.items()}), tmp)
    os.replace(tmp, out)
    return out
