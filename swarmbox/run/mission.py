"""Missions: from a config group entry or from a file in the original SwarmBox format.

The original format (``drone_config.initial_positions``, ``drone_config.superiors``,
``mission_config.type/swarm_size/values``) loads unchanged, so existing mission files run as they are.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
from hydra.utils import get_method
from omegaconf import DictConfig, OmegaConf

from swarmbox.api import MissionInfo


class MissionError(ValueError):
    """The mission cannot run; the message says which key is wrong and why."""


@dataclass(frozen=True)
class Mission:
    name: str
    swarm_size: int
    initial_positions: dict[int, tuple[float, float, float]]
    superiors: dict[int, int]
    values: dict[int, tuple[float, ...]]
    obstacles: list[dict[str, Any]]
    max_sim_time_s: float

    @property
    def drone_ids(self) -> list[int]:
        return sorted(self.initial_positions)

    def info(self) -> MissionInfo:
        return MissionInfo(self.name, self.swarm_size, self.initial_positions, self.superiors, self.values,
                           tuple(self.obstacles))


def _position(drone: Any, pos: Any, where: str) -> tuple[float, float, float]:
    try:
        vals = [float(x) for x in pos]
    except (TypeError, ValueError):
        raise MissionError(f"{where}: position of drone {drone} must be [north, east], got {pos!r}") from None
    if len(vals) not in (2, 3):
        raise MissionError(f"{where}: position of drone {drone} must be [north, east], got {pos!r}")
    return (vals[0], vals[1], 0.0)


def _int_keys(mapping: Mapping, where: str) -> dict[int, Any]:
    out = {}
    for k, v in mapping.items():
        try:
            out[int(k)] = v
        except (TypeError, ValueError):
            raise MissionError(f"{where}: key {k!r} is not a drone id (an integer)") from None
    return out


def from_parts(name: str, positions: Mapping, superiors: Mapping, values: Mapping,
               swarm_size: int | None, obstacles: list, max_sim_time_s: float, where: str) -> Mission:
    pos = {d: _position(d, p, f"{where}.initial_positions")
           for d, p in _int_keys(positions, f"{where}.initial_positions").items()}
    if not pos:
        raise MissionError(f"{where}: initial_positions is empty; a mission needs at least one drone")
    size = len(pos) if swarm_size is None else int(swarm_size)
    if size != len(pos):
        raise MissionError(f"{where}: swarm_size {size} disagrees with the {len(pos)} initial_positions "
                           f"(drones {sorted(pos)})")
    sups = {d: int(s) for d, s in _int_keys(superiors, f"{where}.superiors").items()}
    vals = {}
    for k, v in _int_keys(values, f"{where}.values").items():
        try:
            vals[k] = tuple(float(x) for x in (v if isinstance(v, list | tuple) else list(v)))
        except (TypeError, ValueError):
            raise MissionError(f"{where}.values[{k}] must be a list of numbers, got {v!r}") from None
    return Mission(name, size, dict(sorted(pos.items())), sups, vals, list(obstacles), float(max_sim_time_s))


def load_legacy(path: str | Path, max_sim_time_s: float, obstacles: list) -> Mission:
    """Read a mission file in the original SwarmBox YAML format."""
    p = Path(path).expanduser()
    if not p.is_file():
        raise MissionError(f"mission.file: no such file: {p}")
    raw = OmegaConf.to_container(OmegaConf.load(p), resolve=True)
    if not isinstance(raw, dict) or "drone_config" not in raw or "mission_config" not in raw:
        raise MissionError(f"mission.file {p}: expected top-level keys drone_config and mission_config")
    drone, mission = raw["drone_config"] or {}, raw["mission_config"] or {}
    if "initial_positions" not in drone:
        raise MissionError(f"mission.file {p}: drone_config.initial_positions is missing")
    return from_parts(str(mission.get("type", p.stem)), drone["initial_positions"],
                      drone.get("superiors") or {}, mission.get("values") or {},
                      mission.get("swarm_size"), obstacles, max_sim_time_s, f"mission.file {p}")


def load(cfg: DictConfig, rng: np.random.Generator | None = None) -> Mission:
    """The mission of a run config's ``mission`` group (``rng`` feeds its generator, if any)."""
    m = cfg.mission
    obstacles = OmegaConf.to_container(m.obstacles, resolve=True)
    if m.file:
        mission = load_legacy(m.file, m.max_sim_time_s, obstacles)
    else:
        mission = from_parts(m.name, _mapping(m, "initial_positions"), _mapping(m, "superiors"),
                             _mapping(m, "values"), m.swarm_size, obstacles, m.max_sim_time_s, "mission")
    # A mission file's own values (e.g. its packages) win over the group's generator: the generator
    # fills values only when the file has none.
    if m.generator is not None and not (m.file and mission.values):
        mission = replace(mission, values=generate_values(m.generator, rng or np.random.default_rng(0)))
    return mission


def _mapping(node: DictConfig, key: str) -> dict:
    value = node[key]
    if value is None:
        return {}
    if not OmegaConf.is_dict(value):
        raise MissionError(f"mission.{key} must be a mapping of drone id -> value, got {value!r}")
    return OmegaConf.to_container(value, resolve=True)


def generate_values(spec: DictConfig, rng: np.random.Generator) -> dict[int, tuple[float, ...]]:
    """Call the mission's ``generator`` and check what it returns."""
    params = OmegaConf.to_container(spec, resolve=True)
    target = params.pop("_target_", None)
    if not target:
        raise MissionError("mission.generator: no _target_ (the generating function) given")
    try:
        fn = get_method(target)
    except Exception as exc:
        raise MissionError(f"mission.generator: cannot import '{target}': {exc}") from exc
    try:
        raw = fn(rng=rng, **params)
    except TypeError as exc:
        raise MissionError(f"mission.generator {target}: {exc}") from exc
    return from_parts("generated", {0: [0, 0]}, {}, raw, None, [], 0.0, f"mission.generator {target}").values
