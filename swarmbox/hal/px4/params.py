"""The ``px4`` backend's configuration and clock mapping: the leaf both the bridge
(:mod:`swarmbox.hal.px4.backend`) and the SITL launcher (:mod:`swarmbox.hal.px4.sitl`) import.

:class:`Px4Params` is every key of ``conf/backend/px4.yaml``; :class:`BootClock` maps a vehicle's
boot time onto its drone node's clock (it is saved next to the vehicle's ULog so the analyzer can put
the log on the run's timeline later, outside the run).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, fields
from typing import Any

import numpy as np

from swarmbox.hal.mavlink.frames import GeoFrame
from swarmbox.hal.mavlink.signing import signing_key_of

__all__ = ["DEFAULT_RATES_HZ", "BootClock", "LinkConfig", "Px4Params", "boot_clock_fit"]

DEFAULT_RATES_HZ = {"LOCAL_POSITION_NED": 30.0, "GLOBAL_POSITION_INT": 10.0, "GPS_RAW_INT": 10.0,
                    "SYS_STATUS": 2.0, "EXTENDED_SYS_STATE": 2.0}
GROUND_TRUTH_RATE_HZ = 10.0
#: how a GNSS fault reaches a PX4 autopilot: its failure injection command, or PX4 SIH's
#: SIM_GPS_USED parameter (no fix); auto: the parameter on SIH SITL this backend launched
GNSS_FAILURE_MODES = ("auto", "inject", "sim_param")


@dataclass(frozen=True, slots=True)
class LinkConfig:
    """Per-vehicle link timing (all in vehicle/run seconds, i.e. sped up with the simulation)."""

    component_id: int = 1
    link_timeout_s: float = 3.0
    heartbeat_rate_hz: float = 1.0
    setpoint_rate_hz: float = 20.0
    offboard_lead_s: float = 0.5
    command_timeout_s: float = 1.0
    command_retries: int = 5
    stats_every_s: float = 10.0
    silence_unrequested: bool = True
    message_rates_hz: tuple[tuple[str, float], ...] = ()
    signing_key: bytes | None = None      # MAVLink 2 signing of what the bridge sends
    gnss_failure: str = "inject"          # inject (MAV_CMD_INJECT_FAILURE) | sim_param (SIM_GPS_USED)


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
    signing_key: str | None = None          # MAVLink 2 signing: 64 hex digits or a passphrase; None: off
    gnss_failure: str = "auto"              # how a GNSS fault reaches the autopilot: inject|sim_param|auto
    speed: float = 1.0                      # simulation speed factor of the vehicles (SITL, mavsim)
    px4_build: str | None = None            # a PX4 build to launch SITL from; "auto": find one; None: connect
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
        nullable = ("connections", "system_ids", "px4_build", "run_dir", "signing_key")
        kw = {k: v for k, v in params.items() if v is not None or k in nullable}
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
        # imported here: the message table loads pymavlink's dialect, which a run on another backend,
        # checking its config against this schema, never needs
        from swarmbox.hal.mavlink.codec import MSG

        unknown = [m for m in self.message_rates_hz if m not in MSG]
        if unknown:
            raise ValueError(f"px4 backend: message_rates_hz names unknown MAVLink messages {unknown}")
        GeoFrame(self.origin_lat_deg, self.origin_lon_deg, self.origin_alt_m)
        if not isinstance(self.command_retries, int) or self.command_retries < 0:
            raise ValueError(f"px4 backend: command_retries must be an integer >= 0, "
                             f"got {self.command_retries!r}")
        self.signing_bytes()
        if self.gnss_failure not in GNSS_FAILURE_MODES:
            raise ValueError(f"px4 backend: gnss_failure must be one of {', '.join(GNSS_FAILURE_MODES)}, "
                             f"got {self.gnss_failure!r}")

    def link_config(self, gnss_failure: str = "inject") -> LinkConfig:
        """The per-vehicle link settings; ``gnss_failure`` resolved by the backend (never ``auto``)."""
        rates = dict(self.message_rates_hz)
        if self.ground_truth:
            rates.setdefault("HIL_STATE_QUATERNION", GROUND_TRUTH_RATE_HZ)
        return LinkConfig(self.component_id, self.link_timeout_s, self.heartbeat_rate_hz,
                          self.setpoint_rate_hz, self.offboard_lead_s, self.command_timeout_s,
                          self.command_retries, self.stats_every_s, self.silence_unrequested,
                          tuple(rates.items()), self.signing_bytes(), gnss_failure)

    def signing_bytes(self) -> bytes | None:
        """The 32-byte signing key (None: signing off)."""
        return None if self.signing_key is None else signing_key_of(self.signing_key)


@dataclass(frozen=True, slots=True)
class BootClock:
    """A vehicle's boot time (s) -> its drone node's local clock (s): ``(a + b·boot)·scale + offset_s``.

    ``a, b`` come from :func:`boot_clock_fit` (run time of the least-delayed arrivals), ``scale`` and
    ``offset_s`` from the node's simulated clock (``run.clocks``: drift and offset).
    """

    a: float = 0.0
    b: float = 1.0
    offset_s: float = 0.0
    scale: float = 1.0

    def __call__(self, boot_s: np.ndarray | float) -> np.ndarray:
        return (self.a + self.b * np.asarray(boot_s, dtype=float)) * self.scale + self.offset_s

    def as_dict(self) -> dict[str, float]:
        return {"a": self.a, "b": self.b, "offset_s": self.offset_s, "scale": self.scale}


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
