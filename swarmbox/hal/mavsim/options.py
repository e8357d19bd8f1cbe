"""The options of ``backend=mavsim`` beyond the PX4 bridge's (a module of their own: the config schema
reads them on every run, and the backend imports pymavlink)."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass


@dataclass(frozen=True, slots=True)
class MavsimOptions:
    """How the vehicle processes run (keys of ``conf/backend/mavsim.yaml`` beyond the bridge's)."""

    vehicle_tick_s: float = 0.01        # physics step of each vehicle (simulation s)
    offboard_loss: str = "hold"         # failsafe when setpoints stop in OFFBOARD: hold | land | rtl
    sim: Mapping[str, float | bool | str] | None = None   # sim backend parameters for the vehicles
    refuse: Mapping[str, tuple[str, ...]] | None = None   # drone_<i> -> commands it denies (faults)
