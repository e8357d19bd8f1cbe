"""From the ``fault`` config node to faults scheduled on a built swarm."""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Mapping
from typing import Any

import numpy as np
from omegaconf import DictConfig, OmegaConf

from swarmbox.faults.base import Fault, FaultConfigError, FaultEnv
from swarmbox.faults.schema import MODELS


def selected(fault_cfg: Any) -> dict[str, dict[str, Any]]:
    """The selected models and their parameters, with the top-level shortcuts applied.

    ``fault_cfg`` is the config's ``fault`` node (a DictConfig or a plain mapping).
    """
    raw = _plain(fault_cfg)
    unknown = sorted(k for k in raw if k not in MODELS and not _is_shortcut(k))
    if unknown:
        raise FaultConfigError(f"fault: unknown key(s) {unknown} (models: {', '.join(MODELS)})")
    models = {name: dict(raw[name]) for name in MODELS if isinstance(raw.get(name), Mapping)}
    for key, value in raw.items():
        if key in MODELS or value is None:
            continue
        takers = [name for name in models if key in _fields(name)]
        if not takers:
            chosen = ", ".join(models) or "none"
            raise FaultConfigError(f"fault.{key} is set but no selected fault has that parameter "
                                   f"(selected: {chosen})")
        for name in takers:
            models[name][key] = value
    return models


def describe(fault_cfg: Any) -> str:
    """A short label of the selected faults, e.g. ``gps_drift+packet_loss`` (``none`` if none)."""
    return "+".join(selected(fault_cfg)) or "none"


def build_faults(fault_cfg: Any, env: FaultEnv) -> list[Fault]:
    """Validated fault objects for the selected models (not yet scheduled)."""
    faults = []
    for name, values in selected(fault_cfg).items():
        cls = MODELS[name]
        try:
            params = cls.Params(**values)
        except TypeError as exc:
            raise FaultConfigError(f"fault {name}: {exc}") from exc
        faults.append(cls(params, env))
    return faults


def install_faults(cfg: DictConfig, swarm: Any, mission: Any, backend: Any,
                   rng_for: Callable[[str], np.random.Generator]) -> list[Fault]:
    """Build, check and schedule every fault of ``cfg.fault`` on ``swarm``; returns them.

    ``rng_for(stream)`` hands out the run's named random streams (each target of a model draws from
    ``fault/<model>/<target>``). Raises :class:`FaultConfigError` for an unknown drone, a parameter out
    of range, an onset after the mission's end, or a fault the backend cannot express.
    """
    backend_cfg = cfg.get("backend")
    name = str(backend_cfg.get("name")) if isinstance(backend_cfg, DictConfig) and backend_cfg.get("name") \
        else type(backend).__name__
    env = FaultEnv(swarm=swarm, backend=backend, backend_name=name, drone_ids=list(mission.drone_ids),
                   max_sim_time_s=float(mission.max_sim_time_s), tick_s=float(swarm.tick_s),
                   rng_for=rng_for)
    faults = build_faults(cfg.get("fault"), env)
    for fault in faults:
        fault.install()
    return faults


def _plain(node: Any) -> dict[str, Any]:
    if node is None:
        return {}
    if isinstance(node, DictConfig):
        out = OmegaConf.to_container(node, resolve=True)
    elif dataclasses.is_dataclass(node):
        out = dataclasses.asdict(node)  # type: ignore[arg-type]
    else:
        out = dict(node)
    return {str(k): v for k, v in out.items()}  # type: ignore[union-attr]


def _fields(model: str) -> set[str]:
    return {f.name for f in dataclasses.fields(MODELS[model].Params)}


def _is_shortcut(key: str) -> bool:
    return any(key in _fields(m) for m in MODELS)
