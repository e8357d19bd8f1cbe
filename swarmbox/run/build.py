"""Turn a resolved config into a ready-to-run :class:`~swarmbox.core.swarm.Swarm`."""

from __future__ import annotations

import zlib
from pathlib import Path
from typing import Any

import numpy as np
from hydra.utils import get_class, instantiate
from omegaconf import DictConfig, OmegaConf

from swarmbox.api import DroneAlgorithm, FleetAlgorithm, GroundAlgorithm
from swarmbox.api.views import read_only_mission
from swarmbox.core.agent import AgentNode
from swarmbox.core.clock import ClockSpec, NodeClock, TimeSource
from swarmbox.core.fleet.agents import FleetAgent, FleetState
from swarmbox.core.fleet.ground import FleetGround
from swarmbox.core.fleet.network import FleetNetwork
from swarmbox.core.fleet.rows import MessageRows
from swarmbox.core.fleet.swarm import FleetSwarm
from swarmbox.core.fleet.whole import WholeSwarm
from swarmbox.core.ground import GroundNode
from swarmbox.core.messages import GROUND_ID, NET_ID
from swarmbox.core.node import CoreTiming
from swarmbox.core.swarm import Swarm
from swarmbox.core.topology import Topology, build
from swarmbox.faults import install_faults
from swarmbox.hal.safety import SafetyLimits
from swarmbox.net.medium import LinkSpec, SimMedium
from swarmbox.record.fleet import FleetCoreStateLog, FleetStateLog
from swarmbox.record.schema import node_name
from swarmbox.record.writer import Recorder
from swarmbox.run.mission import Mission
from swarmbox.run.params import typed_params


class ConfigError(ValueError):
    """A config value that type checking cannot catch (unknown node, bad class, ...)."""


def rng_for(seed: int, stream: str) -> np.random.Generator:
    """An independent generator per named consumer: adding a consumer never shifts the others."""
    return np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(zlib.crc32(stream.encode()),)))


def topology_of(cfg: DictConfig, mission: Mission) -> Topology:
    t = cfg.topology
    explicit = OmegaConf.to_container(t.superiors, resolve=True) if t.superiors is not None else None
    kind = t.kind
    if kind == "mission":
        explicit = mission.superiors or None
        kind = "mission" if explicit else "centralized"
    return build(kind, mission.drone_ids, leader=t.leader, branching=t.branching, explicit=explicit)


def timing_of(cfg: DictConfig) -> CoreTiming:
    r = cfg.run
    if r.tick_hz <= 0:
        raise ConfigError(f"run.tick_hz must be > 0, got {r.tick_hz}")
    return CoreTiming(
        tick_s=1.0 / r.tick_hz, lost_inferior_ticks=r.lost_inferior_ticks,
        lost_superior_ticks=r.lost_superior_ticks, task_retry_ticks=r.task_retry_ticks,
        task_max_retries=r.task_max_retries, arm_retry_ticks=r.arm_retry_ticks,
        proximity_m=r.proximity_m, proximity_window_s=r.proximity_window_s, min_alive=r.min_alive,
        state_every_ticks=max(1, r.state_every_ticks),
        timeouts_s=dict(OmegaConf.to_container(r.timeouts_s, resolve=True)))


def clocks_of(cfg: DictConfig, mission: Mission) -> dict[int, ClockSpec]:
    names = {node_name(i): i for i in [GROUND_ID, *mission.drone_ids]}
    out = {}
    for name, spec in clock_settings(cfg).items():
        if name not in names:
            raise ConfigError(f"run.clocks: unknown node '{name}' (nodes: {', '.join(names)})")
        if not isinstance(spec, dict) or set(spec) - {"offset_s", "drift_ppm"}:
            raise ConfigError(f"run.clocks.{name}: expected {{offset_s, drift_ppm}}, got {spec!r}")
        try:
            out[names[name]] = ClockSpec(float(spec.get("offset_s", 0.0)), float(spec.get("drift_ppm", 0.0)))
        except (TypeError, ValueError):
            raise ConfigError(f"run.clocks.{name}: offset_s and drift_ppm must be numbers, "
                              f"got {spec!r}") from None
    return out


def clock_settings(cfg: DictConfig) -> dict:
    """``run.clocks`` as plain data ({} when unset)."""
    clocks = cfg.run.clocks
    if clocks is None:
        return {}
    if not OmegaConf.is_dict(clocks):
        raise ConfigError(f"run.clocks must map node names to {{offset_s, drift_ppm}}, got {clocks!r}")
    return OmegaConf.to_container(clocks, resolve=True)


def medium_of(cfg: DictConfig, time: TimeSource, seed: int, recorder: Recorder,
              mission: Mission) -> SimMedium:
    n = cfg.network
    default = LinkSpec(n.latency_ms / 1e3, n.jitter_ms / 1e3, n.loss_prob)
    return SimMedium(time, rng_for(seed, "network"), default, links_of(cfg, mission),
                     drop_log=recorder.node(NET_ID).appender("messages"))


def links_of(cfg: DictConfig, mission: Mission) -> dict[tuple[int, int], LinkSpec]:
    """``network.links``: (src, dst) -> its spec (a ConfigError for an unknown node)."""
    known = {GROUND_ID, *mission.drone_ids}
    links = {}
    for link in cfg.network.links:
        for end in (link.src, link.dst):
            if end not in known:
                raise ConfigError(f"network.links: unknown node {end} (known: {sorted(known)})")
        links[(link.src, link.dst)] = LinkSpec(link.latency_ms / 1e3, link.jitter_ms / 1e3, link.loss_prob)
    return links


def backend_class(node: DictConfig) -> type:
    """The class named by the backend config's ``_target_``, or a ConfigError naming the key."""
    target = node.get("_target_")
    if not target:
        raise ConfigError("backend._target_: no backend class given")
    try:
        return get_class(target)
    except Exception as exc:
        raise ConfigError(f"backend._target_: cannot import '{target}': {exc}") from exc


def backend_of(cfg: DictConfig, mission: Mission, tick_s: float, seed: int, run_dir: Path,
               drone_ids: list[int] | None = None) -> Any:
    """The backend flying ``drone_ids`` (default: every drone of the mission)."""
    params = OmegaConf.to_container(cfg.backend, resolve=True)
    params.pop("_target_", None)
    params.pop("name", None)
    if isinstance(params.get("sim"), dict):   # typed mavsim ``sim`` node: unset keys are None
        params["sim"] = {k: v for k, v in params["sim"].items() if v is not None}
    s = cfg.run.safety
    limits = SafetyLimits(s.max_speed_m_s, s.max_accel_m_s2, s.geofence_radius_m, s.max_alt_m, s.max_jump_m)
    homes = [mission.initial_positions[i] for i in (mission.drone_ids if drone_ids is None else drone_ids)]
    cls = backend_class(cfg.backend)
    if "run_dir" in params and (params["run_dir"] is None or drone_ids is not None):
        params["run_dir"] = str(run_dir)   # where a backend keeps its own logs (ULogs, vehicle output)
    return cls(homes_ned_m=homes, tick_s=tick_s, rng=rng_for(seed, "backend"),
               obstacles=mission.obstacles, limits=limits, **params)


def _algorithm(node: DictConfig | None, base: type, role: str) -> Any:
    if node is None:
        return base()
    try:
        alg = instantiate(node)
    except Exception as exc:
        raise ConfigError(f"algo.{role}: cannot create {node.get('_target_')}: {exc}") from exc
    allowed = (DroneAlgorithm, FleetAlgorithm) if base is DroneAlgorithm else (base,)
    if not isinstance(alg, allowed):
        raise ConfigError(f"algo.{role}: {type(alg).__name__} is not a {base.__name__}")
    return alg


def build_swarm(cfg: DictConfig, mission: Mission, recorder: Recorder) -> Swarm:
    if cfg.run.get("core", "object") == "fleet":   # the same run over arrays (swarmbox/core/fleet)
        return build_fleet_swarm(cfg, mission, recorder)
    params = typed_params(cfg.algo)   # first: a bad param stops the run before anything exists
    seed = int(cfg.seed)
    timing = timing_of(cfg)
    topo = topology_of(cfg, mission)
    clocks = clocks_of(cfg, mission)
    time = TimeSource()
    medium = medium_of(cfg, time, seed, recorder, mission)
    info = read_only_mission(mission.info())   # frozen once, shared by every node

    def common(node_id: int) -> dict[str, Any]:
        clock = NodeClock(time, clocks.get(node_id, ClockSpec()))
        log = recorder.node(node_id)
        inbox = medium.register(node_id, clock, log.appender("messages"))
        return dict(time=time, clock=clock, net=medium, inbox=inbox, log=log, timing=timing,
                    mission=info, params=params, rng=rng_for(seed, f"algo/{node_name(node_id)}"))

    ground = GroundNode(_algorithm(cfg.algo.ground, GroundAlgorithm, "ground"), **common(GROUND_ID))
    backend = backend_of(cfg, mission, timing.tick_s, seed, recorder.root.parent)
    agents = []
    fleet_alg = None   # a FleetAlgorithm: one instance for every drone
    for i, vehicle in zip(mission.drone_ids, backend.vehicles, strict=True):
        alg = fleet_alg or _algorithm(cfg.algo.drone, DroneAlgorithm, "drone")
        fleet_alg = alg if isinstance(alg, FleetAlgorithm) else None
        agents.append(AgentNode(i, superior=topo.superiors[i], vehicle=vehicle, algorithm=alg, **common(i)))
    subscribe_peers(cfg, medium, mission.drone_ids)
    event_logs = {i: recorder.node(i).appender("events") for i in mission.drone_ids}
    swarm = Swarm(time=time, tick_s=timing.tick_s, ground=ground, agents=agents, medium=medium,
                  backend=backend, event_logs=event_logs)
    if hasattr(backend, "state_columns") and hasattr(recorder, "state_block"):
        swarm.state_log = FleetStateLog(agents, backend, recorder, timing.state_every_ticks)
    install_faults(cfg, swarm, mission, backend, lambda stream: rng_for(seed, stream))
    return swarm


def subscribe_peers(cfg: DictConfig, medium: Any, ids: list[int]) -> None:
    """``topology.peers=all``: every drone subscribes to every other drone's Heartbeats."""
    if cfg.topology.peers == "all":
        for a in ids:
            for b in ids:
                if a != b:
                    medium.subscribe(a, b)
    elif cfg.topology.peers != "none":
        raise ConfigError(f"topology.peers must be 'none' or 'all', got '{cfg.topology.peers}'")


# -- the fleet core (run.core=fleet) ---------------------------------------------------------------
#: The fleet core (swarmbox.core.fleet) writes the object core's logs, table for table; it covers the
#: common path and refuses the rest up front, before anything is written (no silent fall-back).
CORES = ("object", "fleet")


def refusal(cfg: DictConfig) -> str:
    """What of ``cfg`` the fleet core does not cover yet ("" when it covers the run)."""
    r = cfg.run
    if r.runtime != "single":
        return f"run.runtime={r.runtime}"
    if not hasattr(backend_class(cfg.backend), "state_into"):
        return f"backend {cfg.backend.get('name', '?')} (no fleet arrays)"
    return ""


def check_core(cfg: DictConfig) -> None:
    """Refuse a ``run.core`` this run cannot have (a ConfigError: exit 2, nothing written)."""
    core = cfg.run.get("core", "object")
    if core not in CORES:
        raise ConfigError(f"run.core must be one of {', '.join(CORES)}, got '{core}'")
    if core == "fleet":
        what = refusal(cfg)
        if what:
            raise ConfigError(f"run.core=fleet does not cover {what} yet; use run.core=object")


def build_fleet_swarm(cfg: DictConfig, mission: Mission, recorder: Recorder) -> FleetSwarm:
    """build_swarm on the fleet core: the same nodes, generators and order of construction."""
    check_core(cfg)
    params = typed_params(cfg.algo)
    seed = int(cfg.seed)
    timing = timing_of(cfg)
    topo = topology_of(cfg, mission)
    clocks = clocks_of(cfg, mission)
    time = TimeSource()
    ids = list(mission.drone_ids)
    node_clocks = {i: NodeClock(time, clocks.get(i, ClockSpec())) for i in [GROUND_ID, *ids]}
    rows = MessageRows({i: recorder.node(i).appender("messages") for i in [GROUND_ID, NET_ID, *ids]})
    n = cfg.network
    network = FleetNetwork(time, rng_for(seed, "network"), [GROUND_ID, *ids],
                           [node_clocks[i] for i in [GROUND_ID, *ids]], rows, latency_s=n.latency_ms / 1e3,
                           jitter_s=n.jitter_ms / 1e3, loss_prob=n.loss_prob, links=links_of(cfg, mission))
    info = read_only_mission(mission.info())

    def common(node_id: int) -> dict[str, Any]:
        return dict(time=time, clock=node_clocks[node_id], net=network, inbox=[], log=recorder.node(node_id),
                    timing=timing, mission=info, params=params,
                    rng=rng_for(seed, f"algo/{node_name(node_id)}"))

    # drones under drones, peer Heartbeats or a ground that reads each Report (on_report): every drone
    # ticks whole, under the object core's ground
    ground_alg = _algorithm(cfg.algo.ground, GroundAlgorithm, "ground")
    whole = (cfg.topology.peers != "none" or any(s != GROUND_ID for s in topo.superiors.values())
             or type(ground_alg).on_report is not GroundAlgorithm.on_report)
    ground = (GroundNode(ground_alg, **common(GROUND_ID)) if whole
              else FleetGround(ground_alg, ids, **common(GROUND_ID)))
    backend = backend_of(cfg, mission, timing.tick_s, seed, recorder.root.parent)
    fleet = FleetState(ids)
    agents = []
    fleet_alg = None   # a FleetAlgorithm: one instance for every drone, as build_swarm makes it
    for k, (i, vehicle) in enumerate(zip(ids, backend.vehicles, strict=True)):
        alg = fleet_alg or _algorithm(cfg.algo.drone, DroneAlgorithm, "drone")
        fleet_alg = alg if isinstance(alg, FleetAlgorithm) else None
        agents.append(FleetAgent(i, fleet=fleet, k=k, superior=topo.superiors[i], vehicle=vehicle,
                                 algorithm=alg, **common(i)))
    subscribe_peers(cfg, network, ids)
    event_logs = {i: recorder.node(i).appender("events") for i in ids}
    swarm = (WholeSwarm if whole else FleetSwarm)(
        fleet=fleet, network=network, rows=rows, time=time, tick_s=timing.tick_s, ground=ground,
        agents=agents, backend=backend, event_logs=event_logs)
    swarm.state_log = FleetCoreStateLog(swarm, recorder, timing.state_every_ticks)
    install_faults(cfg, swarm, mission, backend, lambda stream: rng_for(seed, stream))
    return swarm


