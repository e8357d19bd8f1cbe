"""The fault models' registry and the ``fault`` config schema derived from it.

One source of truth: each model class carries its parameter dataclass (``Params``); the registry
:data:`MODELS` lists the classes; :class:`FaultConfig` — the typed schema of the config's ``fault``
node — is generated from them:

- one optional sub-node per model (``fault.gps_drift``, ``fault.latency``, ...), filled by selecting
  the model's config file (``conf/fault/<model>.yaml`` is packaged at ``fault.<model>``), so that
  several models compose: ``fault=[gps_drift,packet_loss]``;
- one optional top-level *shortcut* per parameter name of any model (``fault.targets``,
  ``fault.onset_s``, ``fault.rate_m_s``, ...): when set, it overrides that parameter in every
  selected model that has it. So the one-line form ``fault=gps_drift fault.rate_m_s=2
  fault.targets=[3]`` works, and ``fault=[gps_drift,packet_loss] fault.targets=[3]`` aims both
  faults at drone 3; ``fault.packet_loss.loss_prob=0.2`` sets one model's parameter only.

A misspelt key fails at compose time, like every other config group.
"""

from __future__ import annotations

import dataclasses
import typing
from typing import Any, Optional

from swarmbox.faults.autopilot import GpsFailure
from swarmbox.faults.base import Fault
from swarmbox.faults.clock import ClockSkew
from swarmbox.faults.gnss import GpsBias, GpsDrift, GpsDropout, GpsNoise
from swarmbox.faults.network import BurstLoss, Latency, LinkCut, PacketLoss, Partition
from swarmbox.faults.vehicle import BatteryFailsafe, Crash, MotorLoss

#: Every fault model, by config name.
MODELS: dict[str, type[Fault]] = {cls.name: cls for cls in (
    GpsDrift, GpsBias, GpsNoise, GpsDropout, GpsFailure,
    Latency, PacketLoss, BurstLoss, LinkCut, Partition,
    Crash, MotorLoss, BatteryFailsafe,
    ClockSkew,
)}


def param_types() -> dict[str, Any]:
    """Every parameter name of any model (common fields first) with its type."""
    out: dict[str, Any] = {}
    for name, cls in MODELS.items():
        for key, typ in typing.get_type_hints(cls.Params).items():
            if key in out and out[key] != typ:
                raise TypeError(f"fault parameter {key!r} has two types: {out[key]} and {typ} ({name})")
            out[key] = typ
    return out


def _optional(typ: Any) -> Any:
    return typ if typ is Any else Optional[typ]   # noqa: UP045 - OmegaConf 2.3 reads Optional[X]


def _make_schema() -> type:
    shortcuts = [(key, _optional(typ), dataclasses.field(default=None)) for key, typ in param_types().items()]
    models = [(name, Optional[cls.Params], dataclasses.field(default=None))  # noqa: UP045
              for name, cls in MODELS.items()]
    schema = dataclasses.make_dataclass("FaultConfig", shortcuts + models)
    schema.__module__ = __name__
    schema.__doc__ = (
        "Schema of the ``fault`` config node: a sub-node per selected model, and top-level shortcuts "
        "that override the same-named parameter of every selected model (None: not given). "
        f"Models: {', '.join(MODELS)}.")
    return schema


FaultConfig = _make_schema()
