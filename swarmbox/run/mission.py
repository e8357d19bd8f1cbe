"""Missions: from a config group entry or from a file in the original SwarmBox format.

The original format (``drone_config.initial_positions``, ``drone_config.superiors``,
``mission_config.type/swarm_size/values``) loads unchanged, so existing mission files run as they are.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
import yaml
from hydra.utils import get_method
from omegaconf import DictConfig, OmegaConf

from swarmbox.api import MissionInfo
from swarmbox.run.files import FileProblem, read_text_bounded

#: a mission file larger than this is refused unread (the largest shipped one is a few kB)
MAX_MISSION_BYTES = 16 * 1024 * 1024


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
    """A spawn point: exactly [north, east] in metres (every drone starts on the ground, d = 0)."""
    try:
        vals = [float(x) for x in pos]
    except (TypeError, ValueError):
        raise MissionError(f"{where}: position of drone {drone} must be [north, east], got {pos!r}") from None
    if len(vals) != 2:
        extra = " (drones start on the ground: there is no altitude to give)" if len(vals) == 3 else ""
        raise MissionError(f"{where}: position of drone {drone} must be [north, east] (2 numbers), "
                           f"got {len(vals)}: {pos!r}{extra}")
    if not all(math.isfinite(v) for v in vals):
        raise MissionError(f"{where}: position of drone {drone} must be finite, got {pos!r}")
    return (vals[0], vals[1], 0.0)


def check_inside_fence(pos: Mapping[int, tuple[float, float, float]], fence_m: float, where: str) -> None:
    """Refuse spawn points outside the geofence (the safety monitor would pull each drone back in at
    once, or a typo put it kilometres away)."""
    for drone, (n, e, _) in pos.items():
        r = math.hypot(n, e)
        if not r <= fence_m:
            raise MissionError(f"{where}: drone {drone} starts {r:.6g} m from the origin, outside the "
                               f"geofence (run.safety.geofence_radius_m = {fence_m:g} m)")


def check_spacing(pos: Mapping[int, tuple[float, float, float]], min_m: float, where: str) -> None:
    """Refuse spawn points closer than ``min_m``: the drones would start inside each other."""
    if min_m <= 0 or len(pos) < 2:
        return
    ids = list(pos)
    xy = np.array([pos[i][:2] for i in ids])
    d = np.hypot(*(xy[:, None, :] - xy[None, :, :]).transpose(2, 0, 1))
    np.fill_diagonal(d, np.inf)
    i, j = np.unravel_index(int(np.argmin(d)), d.shape)
    gap = float(d[i, j])
    if gap < min_m:
        a, b = sorted((ids[i], ids[j]))
        raise MissionError(f"{where}: drones {a} and {b} start {gap:.2f} m apart, closer than "
                           f"mission.min_spawn_separation_m = {min_m:g} m")


def _int_keys(mapping: Mapping, where: str) -> dict[int, Any]:
    if not isinstance(mapping, Mapping):
        raise MissionError(f"{where} must be a mapping of drone id -> value, got {mapping!r}")
    out = {}
    for k, v in mapping.items():
        try:
            i = int(k)
        except (TypeError, ValueError):
            raise MissionError(f"{where}: key {k!r} is not a drone id (an integer)") from None
        if i in out:
            raise MissionError(f"{where}: drone id {i} is listed twice")
        out[i] = v
    return out


def from_parts(name: str, positions: Mapping, superiors: Mapping, values: Mapping,
               swarm_size: int | None, obstacles: list, max_sim_time_s: float, where: str,
               min_spawn_separation_m: float = 0.0, fence_m: float = math.inf) -> Mission:
    pos = {d: _position(d, p, f"{where}.initial_positions")
           for d, p in _int_keys(positions, f"{where}.initial_positions").items()}
    if not pos:
        raise MissionError(f"{where}: initial_positions is empty; a mission needs at least one drone")
    check_inside_fence(pos, fence_m, f"{where}.initial_positions")
    try:
        size = len(pos) if swarm_size is None else int(swarm_size)
    except (TypeError, ValueError):
        raise MissionError(f"{where}: swarm_size must be an integer, got {swarm_size!r}") from None
    if size != len(pos):
        raise MissionError(f"{where}: swarm_size {size} disagrees with the {len(pos)} initial_positions "
                           f"(drones {sorted(pos)})")
    check_spacing(pos, min_spawn_separation_m, f"{where}.initial_positions")
    sups = {}
    for d, sup in _int_keys(superiors, f"{where}.superiors").items():
        try:
            sups[d] = int(sup)
        except (TypeError, ValueError):
            raise MissionError(f"{where}.superiors[{d}] must be a drone id or -1 (ground), "
                               f"got {sup!r}") from None

    vals = {}
    for k, v in _int_keys(values, f"{where}.values").items():
        try:
            vals[k] = tuple(float(x) for x in (v if isinstance(v, list | tuple) else list(v)))
        except (TypeError, ValueError):
            raise MissionError(f"{where}.values[{k}] must be a list of numbers, got {v!r}") from None
    return Mission(name, size, dict(sorted(pos.items())), sups, vals, list(obstacles), float(max_sim_time_s))


class _StrictLoader(yaml.SafeLoader):
    """YAML without silent surprises: a key given twice in one mapping is an error, not a merge."""


def _mapping_no_duplicates(loader: yaml.SafeLoader, node: yaml.MappingNode) -> dict:
    seen: dict[Any, int] = {}
    for key_node, _ in node.value:
        key = loader.construct_object(key_node)
        if key in seen:
            raise MissionError(f"line {key_node.start_mark.line + 1}: key {key!r} is given twice "
                               f"(first on line {seen[key]})")
        seen[key] = key_node.start_mark.line + 1
    return loader.construct_mapping(node)


_StrictLoader.add_constructor(yaml.resolver.BaseResolver.DEFAULT_MAPPING_TAG, _mapping_no_duplicates)


def read_yaml(p: Path, key: str) -> Any:
    """A YAML file's content; any reason it cannot be read becomes a MissionError naming the file."""
    try:
        text = read_text_bounded(p, MAX_MISSION_BYTES).decode("utf-8")
    except FileProblem as exc:
        raise MissionError(f"{key} {p}: {exc}" if exc.exists else f"{key}: {exc}: {p}") from None
    except UnicodeDecodeError:
        raise MissionError(f"{key} {p}: not a text file (not UTF-8); expected a YAML mission file") from None
    if not text.strip():
        raise MissionError(f"{key} {p}: the file is empty")
    try:
        return yaml.load(text, Loader=_StrictLoader)  # noqa: S506 - a SafeLoader subclass
    except MissionError as exc:
        raise MissionError(f"{key} {p}: {exc}") from None
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        at = f" (line {mark.line + 1})" if mark is not None else ""
        problem = getattr(exc, "problem", None) or str(exc).splitlines()[0]
        raise MissionError(f"{key} {p}: not valid YAML{at}: {problem}") from None


def load_legacy(path: str | Path, max_sim_time_s: float, obstacles: list,
                min_spawn_separation_m: float = 0.0, fence_m: float = math.inf) -> Mission:
    """Read a mission file in the original SwarmBox YAML format."""
    p = Path(path).expanduser()
    raw = read_yaml(p, "mission.file")
    if not isinstance(raw, dict) or "drone_config" not in raw or "mission_config" not in raw:
        raise MissionError(f"mission.file {p}: expected top-level keys drone_config and mission_config")
    drone, mission = raw["drone_config"] or {}, raw["mission_config"] or {}
    if not isinstance(drone, dict) or not isinstance(mission, dict):
        raise MissionError(f"mission.file {p}: drone_config and mission_config must be mappings")
    if "initial_positions" not in drone:
        raise MissionError(f"mission.file {p}: drone_config.initial_positions is missing")
    return from_parts(str(mission.get("type", p.stem)), drone["initial_positions"],
                      drone.get("superiors") or {}, mission.get("values") or {},
                      mission.get("swarm_size"), obstacles, max_sim_time_s, f"mission.file {p}",
                      min_spawn_separation_m, fence_m)


def load(cfg: DictConfig, rng: np.random.Generator | None = None) -> Mission:
    """The mission of a run config's ``mission`` group (``rng`` feeds its generator, if any)."""
    m = cfg.mission
    if not (math.isfinite(m.max_sim_time_s) and m.max_sim_time_s > 0):
        raise MissionError(f"mission.max_sim_time_s must be > 0, got {m.max_sim_time_s!r}")
    obstacles = OmegaConf.to_container(m.obstacles, resolve=True)
    fence_m = float(cfg.run.safety.geofence_radius_m) if "run" in cfg else math.inf
    if m.file:
        mission = load_legacy(m.file, m.max_sim_time_s, obstacles, m.min_spawn_separation_m, fence_m)
    else:
        mission = from_parts(m.name, _mapping(m, "initial_positions"), _mapping(m, "superiors"),
                             _mapping(m, "values"), m.swarm_size, obstacles, m.max_sim_time_s, "mission",
                             m.min_spawn_separation_m, fence_m)
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
