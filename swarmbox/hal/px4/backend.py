"""The ``px4`` backend: a fleet of PX4 autopilots over MAVLink, one UDP link per vehicle.

Any SwarmBox mission flies on PX4 (SITL instances on this machine, or real vehicles on a network)
with no change to the algorithm: the same :class:`~swarmbox.hal.vehicle.Backend` protocol, the same
safety monitor. Each vehicle is a :class:`~swarmbox.hal.px4.vehicle.Px4Vehicle`; its link is
serviced without blocking inside :meth:`Px4Backend.step`, which the run loop paces on the wall clock
(``realtime = True``, sped up by ``run.speed`` when the vehicles are simulated faster).

With ``px4_build`` set, the backend also starts one PX4 SITL instance per vehicle
(:mod:`swarmbox.hal.px4.sitl`), waits until all are ready to arm, stops them at :meth:`close` and
puts each instance's ULog on the run's timeline. Without it, it connects to vehicles that already run.

Times: the backend's clock advances by ``dt_s`` each step (run time; during start-up by the wall
clock times ``speed``). Telemetry ``t_s`` is the run time at which the latest position arrived, so
it freezes when a link falls silent.
"""

from __future__ import annotations

import logging
import math
import sys
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Any, Protocol

import numpy as np

from swarmbox.hal.mavlink.codec import MSG
from swarmbox.hal.mavlink.frames import GeoFrame, VehicleFrame
from swarmbox.hal.mavlink.link import VehicleLink
from swarmbox.hal.px4.vehicle import WANTED, LinkConfig, Px4Vehicle
from swarmbox.hal.safety import SafetyLimits
from swarmbox.hal.vehicle import VehicleEvent

__all__ = ["Launcher", "Px4Backend", "Px4Params", "boot_clock_fit"]

Vec3 = tuple[float, float, float]
DEFAULT_RATES_HZ = {"LOCAL_POSITION_NED": 30.0, "GLOBAL_POSITION_INT": 10.0, "GPS_RAW_INT": 10.0,
                    "SYS_STATUS": 2.0, "EXTENDED_SYS_STATE": 2.0}
GROUND_TRUTH_RATE_HZ = 10.0
WAIT_REPORT_S = 5.0        # a progress line this often while waiting for vehicles

log = logging.getLogger(__name__)
#: maps a vehicle's boot time (s) to its drone node's local clock (s), elementwise
BootClock = Callable[[np.ndarray], np.ndarray]


@dataclass(frozen=True, slots=True)
class Px4Params:
    """Every key of ``conf/backend/px4.yaml``, with its unit in the name."""

    origin_lat_deg: float = 47.397742       # the mission's geodetic origin (NED (0, 0, 0))
    origin_lon_deg: float = 8.545594
    origin_alt_m: float = 488.0             # AMSL, ground level at the origin
    connections: tuple[str, ...] | None = None   # per vehicle; None: udpin:127.0.0.1:{14540+i}
    system_ids: tuple[int, ...] | None = None    # per vehicle; None: i+1 (PX4 SITL instance i)
    component_id: int = 1
    connect_timeout_s: float = 60.0         # wall s to hear every vehicle at start-up
    wait_ready: bool = False                # also wait until all are ready to arm (always when launching)
    ready_timeout_s: float = 120.0          # wall s
    link_timeout_s: float = 3.0             # no HEARTBEAT this long: link lost
    heartbeat_rate_hz: float = 1.0          # our ground-station HEARTBEAT
    setpoint_rate_hz: float = 20.0          # unchanged setpoints are re-sent at this rate (>= 10)
    offboard_lead_s: float = 0.5            # setpoints stream this long before OFFBOARD is requested
    command_timeout_s: float = 1.0          # COMMAND_LONG ack timeout before a retry
    command_retries: int = 5
    message_rates_hz: Mapping[str, float] = field(default_factory=lambda: dict(DEFAULT_RATES_HZ))
    silence_unrequested: bool = True        # ask the autopilot to stop every other stream
    ground_truth: bool = False              # request HIL_STATE_QUATERNION (simulators) -> true_pos_ned_m
    stats_every_s: float = 10.0             # a link/stats event per vehicle this often
    speed: float = 1.0                      # simulation speed factor of the vehicles (SITL, mavsim)
    px4_build: str | None = None            # a PX4 build (px4_sitl_default): launch SITL instances
    sitl: Mapping[str, Any] = field(default_factory=dict)   # launcher options (swarmbox.hal.px4.sitl)
    run_dir: str | None = None              # where ULogs go (default: the Hydra run directory)
    clocks: Mapping[str, Any] = field(default_factory=dict)  # run.clocks, to put ULogs on node clocks

    @classmethod
    def from_kwargs(cls, params: Mapping[str, Any]) -> Px4Params:
        """Build from config keys; an unknown key raises TypeError naming it."""
        known = {f.name for f in fields(cls)}
        for key in params:
            if key not in known:
                raise TypeError(f"unknown px4 backend parameter {key!r} (known: {', '.join(sorted(known))})")
        kw = {k: v for k, v in params.items() if v is not None or k in ("connections", "system_ids",
                                                                         "px4_build", "run_dir")}
        for key in ("connections", "system_ids"):
            if kw.get(key) is not None:
                kw[key] = tuple(kw[key])
        p = cls(**kw)
        p.validate()
        return p

    def validate(self) -> None:
        if self.setpoint_rate_hz < 10:
            raise ValueError(f"px4 backend: setpoint_rate_hz must be >= 10 (PX4 drops OFFBOARD below "
                             f"2 Hz), got {self.setpoint_rate_hz}")
        for name in ("link_timeout_s", "heartbeat_rate_hz", "command_timeout_s", "speed", "stats_every_s",
                     "connect_timeout_s", "ready_timeout_s"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"px4 backend parameter {name!r} must be finite and > 0, got {value!r}")
        unknown = [m for m in self.message_rates_hz if m not in MSG]
        if unknown:
            raise ValueError(f"px4 backend: message_rates_hz names unknown MAVLink messages {unknown}")
        GeoFrame(self.origin_lat_deg, self.origin_lon_deg, self.origin_alt_m)

    def link_config(self) -> LinkConfig:
        rates = dict(self.message_rates_hz)
        if self.ground_truth:
            rates.setdefault("HIL_STATE_QUATERNION", GROUND_TRUTH_RATE_HZ)
        return LinkConfig(self.component_id, self.link_timeout_s, self.heartbeat_rate_hz,
                          self.setpoint_rate_hz, self.offboard_lead_s, self.command_timeout_s,
                          self.command_retries, self.stats_every_s, self.silence_unrequested,
                          tuple(rates.items()))


class Launcher(Protocol):
    """Starts and stops the vehicles of a fleet (PX4 SITL instances, mavsim processes)."""

    def connections(self) -> list[str]:
        """The bridge's connection string for each vehicle (its port plan)."""

    def start(self, local_ports: list[int]) -> None:
        """Start every vehicle; ``local_ports`` are the ports the bridge is bound to."""

    def check(self) -> None:
        """Raise RuntimeError (with the vehicle's last output) if a vehicle process has exited."""

    def poll_exits(self) -> list[tuple[int, int]]:
        """``(vehicle index, return code)`` of processes that exited since the last call."""

    def stop(self) -> None:
        """Stop every vehicle (idempotent)."""

    def collect(self, run_dir: Path | None, clocks: list[BootClock]) -> None:
        """After :meth:`stop`: gather the vehicles' own logs into ``run_dir``."""


def boot_clock_fit(pairs: Sequence[tuple[float, float]]) -> tuple[float, float]:
    """``(a, b)`` with run_s ≈ a + b · boot_s, fitted to (boot_s, run_s − boot_s) minima.

    The minima per second of boot time are the least-delayed receptions; a line through them also
    absorbs a speed mismatch between the vehicle's simulation and the run loop.
    """
    if not pairs:
        return 0.0, 1.0
    boot = np.array([p[0] for p in pairs])
    offset = np.array([p[1] for p in pairs])
    if len(pairs) < 3 or np.ptp(boot) < 1.0:
        return float(offset.min()), 1.0
    slope, intercept = np.polyfit(boot, offset, 1)
    return float(intercept), float(1.0 + slope)


class Px4Backend:
    """A fleet of MAVLink autopilots (implements :class:`swarmbox.hal.vehicle.Backend`).

    Constructed by the runner as ``Px4Backend(homes_ned_m=..., tick_s=..., rng=..., obstacles=...,
    limits=..., **params)`` with ``params`` the keys of ``conf/backend/px4.yaml`` (:class:`Px4Params`).
    The constructor returns once every vehicle has been heard (and, when it launched them, is ready
    to arm); it raises TimeoutError naming the silent vehicles otherwise. ``obstacles`` are the
    autopilots' business (a real vehicle sees real walls) and are ignored.
    """

    realtime = True

    def __init__(self, *, homes_ned_m: Sequence[Sequence[float]], tick_s: float, rng: np.random.Generator,
                 obstacles: Sequence[Mapping[str, Any]] = (), limits: SafetyLimits = SafetyLimits(),
                 **params: Any) -> None:
        self.params = p = Px4Params.from_kwargs(params)
        homes = [tuple(float(x) for x in h) for h in homes_ned_m]
        if not homes or any(len(h) != 3 or not all(map(math.isfinite, h)) for h in homes) or not tick_s > 0:
            raise ValueError("need at least one finite [n, e, d] home and tick_s > 0")
        self.tick_s, self.limits, self.homes = float(tick_s), limits, homes
        self.frame = GeoFrame(p.origin_lat_deg, p.origin_lon_deg, p.origin_alt_m)
        self.run_dir = _run_dir(p.run_dir)
        self._clock_s = self.t0_s = 0.0
        self._events: list[VehicleEvent] = []
        self._links: list[VehicleLink] = []
        self.vehicles: list[Px4Vehicle] = []
        self._closed, self._k = False, 0
        self.launcher: Launcher | None = self._make_launcher(homes)  # type: ignore[arg-type]
        try:
            self._open(homes)  # type: ignore[arg-type]
        except BaseException:
            self.close()
            raise
        self.t0_s = self._clock_s
        self._events = [e._replace(t_s=e.t_s - self.t0_s) for e in self._events]

    @property
    def t_s(self) -> float:
        """Run time: 0 when the constructor returns."""
        return self._clock_s - self.t0_s

    def _make_launcher(self, homes: list[Vec3]) -> Launcher | None:
        if not self.params.px4_build:
            return None
        from swarmbox.hal.px4.sitl import SitlLauncher

        return SitlLauncher(self.params, homes, self.frame, self.run_dir)

    def _open(self, homes: list[Vec3]) -> None:
        p, n = self.params, len(homes)
        specs = (self.launcher.connections() if self.launcher is not None
                 else list(p.connections or [f"udpin:127.0.0.1:{14540 + i}" for i in range(n)]))
        sysids = list(p.system_ids or [i + 1 for i in range(n)])
        if len(specs) != n or len(sysids) != n:
            raise ValueError(f"px4 backend: {n} vehicles but {len(specs)} connections and "
                             f"{len(sysids)} system ids")
        wanted = set(WANTED)
        for spec, sysid in zip(specs, sysids, strict=True):
            self._links.append(VehicleLink(spec, sysid, wanted))
        if self.launcher is not None:
            self.launcher.start([link.endpoint.local_port for link in self._links])
        cfg = p.link_config()
        self.vehicles = [Px4Vehicle(i, link, cfg, VehicleFrame(homes[i], self.frame), self.limits,
                                    self._emitter(i)) for i, link in enumerate(self._links)]
        self._wait_for("heard (HEARTBEAT and LOCAL_POSITION_NED)", lambda v: v.has_position,
                       p.connect_timeout_s)
        if p.wait_ready or self.launcher is not None:
            self._wait_for("ready to arm", lambda v: v.telemetry().ready_to_arm, p.ready_timeout_s)

    def _emitter(self, i: int) -> Callable[[str, str, dict[str, Any]], None]:
        def emit(kind: str, name: str, data: dict[str, Any]) -> None:
            self._events.append(VehicleEvent(self._clock_s - self.t0_s, i, kind, name, data))
        return emit

    def _wait_for(self, what: str, done: Callable[[Px4Vehicle], bool], timeout_s: float) -> None:
        start = last = reported = time.monotonic()
        while True:
            now = time.monotonic()
            self._clock_s += (now - last) * self.params.speed
            last = now
            for v in self.vehicles:
                v.service(self._clock_s)
            if all(done(v) for v in self.vehicles):
                return
            if now - reported >= WAIT_REPORT_S:   # never silent while waiting for vehicles
                reported = now
                log.info("px4 backend: %d/%d vehicles %s after %.0f s (timeout %g s)",
                         sum(map(done, self.vehicles)), len(self.vehicles), what, now - start, timeout_s)
            if self.launcher is not None:
                self.launcher.check()
            if now - start > timeout_s:
                missing = [(v.drone_id, self._links[v.drone_id].endpoint.spec)
                           for v in self.vehicles if not done(v)]
                raise TimeoutError(f"px4 backend: vehicles (id, connection) {missing} not {what} within "
                                   f"{timeout_s:g} s")
            time.sleep(0.01)

    # ---- Backend protocol ---------------------------------------------------------------------
    def step(self, dt_s: float) -> None:
        """Service every link once (receive, watchdog, stream setpoints, retry commands)."""
        if self._closed:
            raise RuntimeError("Px4Backend.step() after close()")
        self._clock_s += dt_s
        now = self._clock_s
        for v in self.vehicles:
            v.service(now)
        self._k += 1
        if self.launcher is not None and self._k % 40 == 0:
            for i, code in self.launcher.poll_exits():
                self._emitter(i)("link", "process_exited", {"returncode": code})

    def drain_events(self) -> list[VehicleEvent]:
        out, self._events = self._events, []
        return out

    def close(self) -> None:
        """Stop launched vehicles, collect their logs, close the sockets; safe to call twice."""
        if self._closed:
            return
        self._closed = True
        try:
            if self.launcher is not None:
                self.launcher.stop()
                self._collect_logs(self.launcher)
        finally:
            for link in self._links:
                link.close()

    def _collect_logs(self, launcher: Launcher) -> None:
        """The vehicles' own logs into the run directory; a failure here must not fail the run."""
        try:
            launcher.collect(self.run_dir, [self.boot_clock(i) for i in range(len(self.homes))])
        except Exception as exc:   # a corrupt log: report it and keep the run's result
            print(f"px4 backend: could not collect the vehicles' logs: {type(exc).__name__}: {exc}",
                  file=sys.stderr)

    # ---- measurements ---------------------------------------------------------------------------
    @property
    def local_ports(self) -> list[int]:
        """The UDP port the bridge is bound to for each vehicle."""
        return [link.endpoint.local_port for link in self._links]

    def link_stats(self) -> list[dict[str, Any]]:
        """Per vehicle: bytes and packets in and out, decoded, skipped, bad, foreign."""
        return [link.stats.as_dict(link.decoder) for link in self._links]

    def boot_clock(self, i: int) -> BootClock:
        """Vehicle ``i``'s boot time -> its drone node's local clock (run.clocks offset and drift)."""
        a, b = boot_clock_fit(self.vehicles[i].clock_pairs if i < len(self.vehicles) else [])
        a -= self.t0_s
        spec = self.params.clocks.get(f"drone_{i}") or {}
        offset_s, scale = float(spec.get("offset_s", 0.0)), 1.0 + float(spec.get("drift_ppm", 0.0)) * 1e-6
        return lambda boot_s: (a + b * np.asarray(boot_s, dtype=float)) * scale + offset_s


def _run_dir(configured: str | None) -> Path | None:
    """The configured run directory, else Hydra's output directory when Hydra runs this process."""
    if configured:
        return Path(configured)
    hydra_config = sys.modules.get("hydra.core.hydra_config")
    if hydra_config is not None and hydra_config.HydraConfig.initialized():
        return Path(hydra_config.HydraConfig.get().runtime.output_dir)
    return None
