"""The ``px4`` backend: a fleet of PX4 autopilots over MAVLink, one UDP link per vehicle.

Any SwarmBox mission flies on PX4 (SITL instances on this machine, or real vehicles on a network)
with no change to the algorithm: the same :class:`~swarmbox.hal.vehicle.Backend` protocol, the same
safety monitor. Each vehicle is a :class:`~swarmbox.hal.px4.vehicle.Px4Vehicle`; its link is
serviced without blocking inside :meth:`Px4Backend.step`, which the run loop paces on the wall clock
(``realtime = True``, sped up by ``run.speed`` when the vehicles are simulated faster).

With a PX4 build (``px4_build``: a path, or ``auto`` to find one), the backend also starts one PX4
SITL instance per vehicle
(:mod:`swarmbox.hal.px4.sitl`), waits until all are ready to arm, stops them at :meth:`close` and
puts each instance's ULog on the run's timeline. Without it, it connects to vehicles that already run.

Times: the backend's clock advances by ``dt_s`` each step (run time; during start-up by the wall
clock times ``speed``). Telemetry ``t_s`` is the run time at which the latest position arrived, so
it freezes when a link falls silent.
"""

from __future__ import annotations

import errno
import logging
import math
import sys
import time
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any, Protocol

import numpy as np

from swarmbox.hal.mavlink.frames import GeoFrame, VehicleFrame
from swarmbox.hal.mavlink.link import VehicleLink, parse_connection
from swarmbox.hal.px4.params import BootClock, Px4Params, boot_clock_fit
from swarmbox.hal.px4.sitl import ENV_BUILD, SHARED_BUILDS, SitlLauncher, resolve_build
from swarmbox.hal.px4.streams import WANTED
from swarmbox.hal.px4.vehicle import Px4Vehicle
from swarmbox.hal.safety import SafetyLimits
from swarmbox.hal.vehicle import VehicleEvent

__all__ = ["BootClock", "Launcher", "Px4Backend", "Px4Params", "boot_clock_fit"]

Vec3 = tuple[float, float, float]
WAIT_REPORT_S = 5.0        # a progress line this often while waiting for vehicles

log = logging.getLogger(__name__)


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

    def collect(self, run_dir: Path | None, clocks: list[BootClock]) -> list[str] | None:
        """After :meth:`stop`: gather the vehicles' own logs into ``run_dir``; what could not be."""


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
        self.problems: list[str] = []   # what went wrong that did not fail the run (run.json ``problems``)
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
        """The SITL launcher, or None (vehicles that already run); says at once which it is."""
        p, n = self.params, len(homes)
        auto = str(p.px4_build).strip().lower() == "auto"
        if p.connections and auto:   # listed connections: vehicles that already run
            _say(f"px4 backend: connecting to {n} running vehicle(s) at {', '.join(p.connections)} "
                 f"(backend.connections; no PX4 launched), waiting up to {p.connect_timeout_s:g} s")
            return None
        if resolve_build(p.px4_build) is None:
            specs = [f"udpin:127.0.0.1:{14540 + i}" for i in range(n)]
            why = (f"no PX4 build found (px4_build=auto: ${ENV_BUILD} is unset and "
                   f"{' and '.join(str(b) for b in SHARED_BUILDS)} hold none)" if auto
                   else "px4_build=null: no PX4 launched")
            _say(f"px4 backend: {why}; waiting up to {p.connect_timeout_s:g} s for {n} vehicle(s) already "
                 f"running, on UDP ports {_ports(specs)} "
                 "(backend.px4_build=<PX4-Autopilot tree> launches SITL)")
            return None
        launcher = SitlLauncher(self.params, homes, self.frame, self.run_dir, self.limits)
        first = launcher.instance(0)
        _say(f"px4 backend: launching {n} PX4 SITL instance(s) {first}-{first + n - 1} from {launcher.build} "
             f"(UDP ports {_ports(launcher.connections())}; backend.sitl.first_instance={first})")
        return launcher

    def _open(self, homes: list[Vec3]) -> None:
        p, n = self.params, len(homes)
        specs = (self.launcher.connections() if self.launcher is not None
                 else list(p.connections or [f"udpin:127.0.0.1:{14540 + i}" for i in range(n)]))
        own_ids = getattr(self.launcher, "system_ids", None)
        sysids = list(p.system_ids or (own_ids() if own_ids else [i + 1 for i in range(n)]))
        if len(specs) != n or len(sysids) != n:
            raise ValueError(f"px4 backend: {n} vehicles but {len(specs)} connections and "
                             f"{len(sysids)} system ids")
        wanted, key = set(WANTED), p.signing_bytes()
        for i, (spec, sysid) in enumerate(zip(specs, sysids, strict=True)):
            try:
                self._links.append(VehicleLink(spec, sysid, wanted, signing_key=key))
            except OSError as exc:
                if exc.errno != errno.EADDRINUSE:
                    raise
                raise OSError(self._busy_port(i, spec)) from None
        if self.launcher is not None:
            self.launcher.start([link.endpoint.local_port for link in self._links])
        cfg = p.link_config(self._gnss_failure())
        self.vehicles = [Px4Vehicle(i, link, cfg, VehicleFrame(homes[i], self.frame), self.limits,
                                    self._emitter(i)) for i, link in enumerate(self._links)]
        self._wait_for("heard (HEARTBEAT and LOCAL_POSITION_NED)", lambda v: v.has_position,
                       p.connect_timeout_s)
        if p.wait_ready or self.launcher is not None:
            self._wait_for("ready to arm", lambda v: v.telemetry().ready_to_arm, p.ready_timeout_s)

    def _busy_port(self, i: int, spec: str) -> str:
        """One line for a port another program holds: which vehicle, and the key that moves it."""
        port = _ports([spec])
        if not isinstance(self.launcher, SitlLauncher):
            return (f"px4 backend: UDP port {port} of vehicle {i} ({spec}) is in use by another program; "
                    "list the vehicles' own connections with backend.connections=[...]")
        first = self.launcher.options.first_instance
        return (f"px4 backend: UDP port {port} of vehicle {i} (PX4 instance {first + i}) is in use, by "
                "another run or PX4 on this machine; give this run a free instance range with "
                f"backend.sitl.first_instance=N (now {first}; vehicle i is instance N+i)")

    def _gnss_failure(self) -> str:
        """``auto``: PX4 SIH (up to Aug 2025) answers no GNSS failure injection; write SIM_GPS_USED there."""
        mode = self.params.gnss_failure
        if mode != "auto":
            return mode
        sih = isinstance(self.launcher, SitlLauncher) and self.launcher.options.model.startswith("sihsim")
        return "sim_param" if sih else "inject"

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
                missing = [v for v in self.vehicles if not done(v)]
                ids = [(v.drone_id, self._links[v.drone_id].endpoint.spec) for v in missing]
                raise TimeoutError(f"px4 backend: vehicles (id, connection) {ids} not {what} within "
                                   f"{timeout_s:g} s{_why_silent(self._links, missing)}")
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
            clocks = [self.boot_clock(i) for i in range(len(self.homes))]
            self.problems += launcher.collect(self.run_dir, clocks) or []
        except Exception as exc:   # a corrupt log: report it and keep the run's result
            self.problems.append(f"could not collect the vehicles' logs: {type(exc).__name__}: {exc}")
        for problem in self.problems:
            print(f"px4 backend: {problem}", file=sys.stderr)

    def inject_failure(self, i: int, unit: str, kind: str, instance: int = 0) -> None:
        """Vehicle ``i``'s autopilot fails ``unit`` itself (MAV_CMD_INJECT_FAILURE; ``kind="ok"``
        ends it). The answer arrives as a ``fault/inject_accepted`` or ``inject_refused`` event."""
        self.vehicles[i].inject_failure(unit, kind, instance)

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
        scale = 1.0 + float(spec.get("drift_ppm", 0.0)) * 1e-6
        return BootClock(a, b, float(spec.get("offset_s", 0.0)), scale)


def _why_silent(links: list[VehicleLink], missing: list[Px4Vehicle]) -> str:
    """What the silent vehicles' links did receive: other system ids, impostors, bad signatures."""
    notes = []
    for v in missing:
        link = links[v.drone_id]
        st = link.stats
        if st.foreign:
            notes.append(f"drone {v.drone_id}: packets seen from system ids {sorted(st.foreign)}, "
                         f"expected {link.system_id}")
        if link.decoder.signature_rejected:
            notes.append(f"drone {v.drone_id}: {link.decoder.signature_rejected} packets unsigned or "
                         "wrongly signed")
        if not (st.foreign or link.decoder.signature_rejected) and st.rx_datagrams == 0:
            notes.append(f"drone {v.drone_id}: nothing received on port {link.endpoint.local_port}")
    return "; " + "; ".join(notes) if notes else ""


def _say(line: str) -> None:
    """A start-up line on stderr, at once: what the backend does before it waits for vehicles."""
    print(line, file=sys.stderr, flush=True)


def _ports(specs: Sequence[str]) -> str:
    """The local UDP ports of connection strings, as ``14540-14543`` or ``14540, 24550``."""
    ports = [parse_connection(s)[1][1] for s in specs]
    if len(ports) > 1 and ports == list(range(ports[0], ports[0] + len(ports))):
        return f"{ports[0]}-{ports[-1]}"
    return ", ".join(map(str, ports))


def _run_dir(configured: str | None) -> Path | None:
    """The configured run directory, else Hydra's output directory when Hydra runs this process."""
    if configured:
        return Path(configured)
    hydra_config = sys.modules.get("hydra.core.hydra_config")
    if hydra_config is not None and hydra_config.HydraConfig.initialized():
        return Path(hydra_config.HydraConfig.get().runtime.output_dir)
    return None
