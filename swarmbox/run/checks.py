"""Every check a run config can get before anything is created on disk.

:func:`check` validates each group — run timing, mission, topology, clocks, network, faults, backend
parameters, algorithm classes — and raises an error whose message names the offending key (or file).
The runner calls it before it makes the run directory, so a config error leaves nothing behind.
Only what needs the built swarm (e.g. a fault the backend cannot express) is checked later, at build.
"""

from __future__ import annotations

import importlib.util
import math
from dataclasses import fields
from typing import Any

import numpy as np
from hydra.utils import get_class
from omegaconf import DictConfig, OmegaConf

from swarmbox.api import DroneAlgorithm, FleetAlgorithm, GroundAlgorithm
from swarmbox.core.topology import TopologyError
from swarmbox.faults import FaultConfigError, FaultEnv, build_faults
from swarmbox.hal.mavsim.options import MavsimOptions
from swarmbox.hal.px4.params import Px4Params
from swarmbox.hal.px4.sitl import SitlOptions
from swarmbox.hal.sim.params import SimParams
from swarmbox.run import build, mission
from swarmbox.run.build import ConfigError
from swarmbox.run.mission import Mission, MissionError
from swarmbox.run.params import ParamsError, typed_params

#: The errors that mean "the input is wrong" (exit code 2, nothing written), not "the run failed".
INPUT_ERRORS = (ConfigError, MissionError, FaultConfigError, TopologyError)


def check(cfg: DictConfig) -> Mission:
    """Validate ``cfg``; returns its mission. Raises one of :data:`INPUT_ERRORS` naming the key."""
    _run(cfg.run)
    m = mission.load(cfg, build.rng_for(int(cfg.seed), "dataset"))
    _topology(cfg, m)
    build.clocks_of(cfg, m)
    _network(cfg.network, m)
    _faults(cfg, m)
    _backend(cfg.backend)
    _algo(cfg.algo)
    build.check_core(cfg)   # run.core: what the fleet core does not cover is refused here
    return m


def _topology(cfg: DictConfig, m: Mission) -> None:
    from_mission = cfg.topology.kind == "mission" and bool(m.superiors)
    kind = cfg.topology.kind
    where = (f"mission.file {cfg.mission.file}: drone_config.superiors" if from_mission and cfg.mission.file
             else "mission.superiors" if from_mission
             else "topology.superiors" if kind == "explicit"
             else "topology.leader" if kind == "leader_follower"
             else "topology.branching" if kind == "tree" else f"topology.kind={kind}")
    try:
        build.topology_of(cfg, m)
    except TopologyError as exc:
        raise TopologyError(f"{where}: {str(exc).removeprefix('topology: ')}") from None
    except (TypeError, ValueError) as exc:
        raise TopologyError(f"{where}: drone ids and superiors must be integers ({exc})") from None


def _positive(key: str, value: Any, *, allow_zero: bool = False) -> None:
    ok = isinstance(value, int | float) and math.isfinite(value) and (value >= 0 if allow_zero else value > 0)
    if not ok:
        raise ConfigError(f"{key} must be a finite number {'>=' if allow_zero else '>'} 0, got {value!r}")


def _run(r: DictConfig) -> None:
    _positive("run.tick_hz", r.tick_hz)
    _positive("run.speed", r.speed)
    for key, allowed in (("runtime", ("single", "processes")), ("monitor", ("auto", "on", "off")),
                         ("log_writer", ("auto", "thread", "process"))):
        if r[key] not in allowed:
            raise ConfigError(f"run.{key} must be one of {', '.join(allowed)}, got '{r[key]}'")
    if r.hook_timeout_s is not None:
        _positive("run.hook_timeout_s", r.hook_timeout_s)
    for key in ("lost_inferior_ticks", "lost_superior_ticks", "task_retry_ticks", "arm_retry_ticks",
                "state_every_ticks"):
        if r[key] < 1:
            raise ConfigError(f"run.{key} must be >= 1, got {r[key]}")
    for key in ("task_max_retries", "min_alive"):
        if r[key] < 0:
            raise ConfigError(f"run.{key} must be >= 0, got {r[key]}")
    for key in ("proximity_m",):
        _positive(f"run.{key}", r[key], allow_zero=True)
    for stage, value in r.timeouts_s.items():
        _positive(f"run.timeouts_s.{stage}", value)
    for key, value in r.safety.items():
        _positive(f"run.safety.{key}", value)
    if r.rerun and importlib.util.find_spec("rerun") is None:
        raise ConfigError("run.rerun needs the replay extra (pip install 'swarmbox[replay]'): "
                          "the rerun package is not installed")


def _link(prefix: str, latency_ms: float, jitter_ms: float, loss_prob: float) -> None:
    _positive(f"{prefix}latency_ms", latency_ms, allow_zero=True)
    _positive(f"{prefix}jitter_ms", jitter_ms, allow_zero=True)
    if not (math.isfinite(loss_prob) and 0.0 <= loss_prob <= 1.0):
        raise ConfigError(f"{prefix}loss_prob must be within [0, 1], got {loss_prob!r}")


def _network(n: DictConfig, m: Mission) -> None:
    _link("network.", n.latency_ms, n.jitter_ms, n.loss_prob)
    known = {-1, *m.drone_ids}
    for i, link in enumerate(n.links):
        for end in ("src", "dst"):
            if link[end] not in known:
                raise ConfigError(f"network.links[{i}].{end}: unknown node {link[end]} "
                                  f"(known: {sorted(known)})")
        _link(f"network.links[{i}].", link.latency_ms, link.jitter_ms, link.loss_prob)


def _faults(cfg: DictConfig, m: Mission) -> None:
    """Build the fault objects against the mission (parameters, targets, timing) without a swarm."""
    name = str(cfg.backend.get("name", "?"))
    env = FaultEnv(swarm=None, backend=None, backend_name=name, drone_ids=list(m.drone_ids),
                   max_sim_time_s=float(m.max_sim_time_s), tick_s=1.0 / float(cfg.run.tick_hz),
                   rng_for=lambda _stream: np.random.default_rng(0))
    build_faults(cfg.get("fault"), env)


def _backend(node: DictConfig) -> None:
    """Range checks of the shipped backends' parameters (their dataclasses' own ``validate``)."""
    params = OmegaConf.to_container(node, resolve=True)
    target = str(params.pop("_target_", "") or "")
    params.pop("name", None)
    cls = build.backend_class(node)
    try:
        if target.endswith("MavsimBackend"):
            opts = {f.name: params.pop(f.name) for f in fields(MavsimOptions) if f.name in params}
            if opts.get("offboard_loss", "hold") not in ("hold", "land", "rtl"):
                raise ValueError(f"offboard_loss must be hold, land or rtl, got {opts['offboard_loss']!r}")
            _positive("backend.vehicle_tick_s", opts.get("vehicle_tick_s", 0.01))
            SimParams.from_kwargs({k: v for k, v in (opts.get("sim") or {}).items() if v is not None})
            Px4Params.from_kwargs(params)
        elif target.endswith("Px4Backend"):
            Px4Params.from_kwargs(params)
            SitlOptions.from_mapping(params.get("sitl") or {})
        elif cls.__module__ == "swarmbox.hal.sim.backend":
            SimParams.from_kwargs(params)
    except ConfigError:
        raise
    except (TypeError, ValueError) as exc:
        raise ConfigError(f"backend ({node.get('name')}): {exc}") from exc


def _algo(a: DictConfig) -> None:
    for role, base in (("drone", DroneAlgorithm), ("ground", GroundAlgorithm)):
        node = a.get(role)
        if node is None:
            continue
        target = node.get("_target_") if OmegaConf.is_dict(node) else None
        if not target:
            raise ConfigError(f"algo.{role}: needs a _target_ (the algorithm class)")
        try:
            cls = get_class(str(target))
        except Exception as exc:
            raise ConfigError(f"algo.{role}._target_: cannot import '{target}': {exc}") from exc
        allowed = (DroneAlgorithm, FleetAlgorithm) if base is DroneAlgorithm else (base,)
        if not (isinstance(cls, type) and issubclass(cls, allowed)):
            raise ConfigError(f"algo.{role}._target_: {target} is not a {base.__name__}")
    try:   # typed params (the algorithm's Params): a wrong type or an unknown key, before any directory
        typed_params(a)
    except ParamsError as exc:
        raise ConfigError(str(exc)) from None
