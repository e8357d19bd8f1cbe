"""The fleet core (``run.core=fleet``): what it covers, and a run assembled on it.

The fleet core (:mod:`swarmbox.core.fleet`) writes the logs of the object core, table for table; it
covers the common path and refuses the rest up front, with one line naming what is not covered,
before anything is written (no silent fall-back to the object core).
"""

from __future__ import annotations

from typing import Any

from omegaconf import DictConfig, OmegaConf

from swarmbox.api import DroneAlgorithm, GroundAlgorithm
from swarmbox.api.views import read_only_mission
from swarmbox.core.clock import ClockSpec, NodeClock, TimeSource
from swarmbox.core.fleet.agents import FleetAgent, FleetState
from swarmbox.core.fleet.ground import FleetGround
from swarmbox.core.fleet.network import FleetNetwork
from swarmbox.core.fleet.rows import MessageRows
from swarmbox.core.fleet.swarm import FleetSwarm
from swarmbox.core.messages import GROUND_ID, NET_ID
from swarmbox.faults.install import selected
from swarmbox.record.fleet import FleetCoreStateLog
from swarmbox.record.schema import node_name
from swarmbox.record.writer import Recorder
from swarmbox.run import build
from swarmbox.run.mission import Mission
from swarmbox.run.params import typed_params

CORES = ("object", "fleet")


def refusal(cfg: DictConfig, mission: Mission) -> str:
    """What of ``cfg`` the fleet core does not cover yet ("" when it covers the run)."""
    r = cfg.run
    if r.runtime != "single":
        return f"run.runtime={r.runtime}"
    faults = list(selected(cfg.get("fault")))
    if faults:
        return f"faults ({', '.join(faults)})"
    if any(s != GROUND_ID for s in build.topology_of(cfg, mission).superiors.values()):
        return f"topology {cfg.topology.kind} (only every drone under the ground)"
    if cfg.topology.peers != "none":
        return f"topology.peers={cfg.topology.peers}"
    if cfg.network.links:
        return "network.links (per-link specs)"
    if r.proximity_window_s:
        return "run.proximity_window_s > 0"
    if r.monitor == "on" or r.rerun:
        return "the live monitor"
    if not hasattr(build.backend_class(cfg.backend), "state_into"):
        return f"backend {cfg.backend.get('name', '?')} (no fleet arrays)"
    ground = cfg.algo.ground
    if ground is not None:
        cls = build.get_class(ground._target_)
        if getattr(cls, "on_report", None) is not GroundAlgorithm.on_report:
            return "a ground algorithm with on_report"
    return ""


def check(cfg: DictConfig, mission: Mission) -> None:
    """Refuse a ``run.core`` this run cannot have (a ConfigError: exit 2, nothing written)."""
    core = cfg.run.get("core", "object")
    if core not in CORES:
        raise build.ConfigError(f"run.core must be one of {', '.join(CORES)}, got '{core}'")
    if core == "fleet":
        what = refusal(cfg, mission)
        if what:
            raise build.ConfigError(f"run.core=fleet does not cover {what} yet; use run.core=object")


def build_fleet_swarm(cfg: DictConfig, mission: Mission, recorder: Recorder) -> FleetSwarm:
    """build.build_swarm on the fleet core: the same nodes, generators and order of construction."""
    check(cfg, mission)
    params = typed_params(cfg.algo)
    seed = int(cfg.seed)
    timing = build.timing_of(cfg)
    topo = build.topology_of(cfg, mission)
    clocks = build.clocks_of(cfg, mission)
    time = TimeSource()
    ids = list(mission.drone_ids)
    node_clocks = {i: NodeClock(time, clocks.get(i, ClockSpec())) for i in [GROUND_ID, *ids]}
    rows = MessageRows({i: recorder.node(i).appender("messages") for i in [GROUND_ID, NET_ID, *ids]})
    n = cfg.network
    network = FleetNetwork(time, build.rng_for(seed, "network"), [GROUND_ID, *ids],
                           [node_clocks[i] for i in [GROUND_ID, *ids]], rows, latency_s=n.latency_ms / 1e3,
                           jitter_s=n.jitter_ms / 1e3, loss_prob=n.loss_prob)
    info = read_only_mission(mission.info())

    def common(node_id: int) -> dict[str, Any]:
        return dict(time=time, clock=node_clocks[node_id], net=network, inbox=[], log=recorder.node(node_id),
                    timing=timing, mission=info, params=params,
                    rng=build.rng_for(seed, f"algo/{node_name(node_id)}"))

    ground = FleetGround(build._algorithm(cfg.algo.ground, GroundAlgorithm, "ground"), ids,
                         **common(GROUND_ID))
    backend = build.backend_of(cfg, mission, timing.tick_s, seed, recorder.root.parent)
    fleet = FleetState(ids)
    agents = [FleetAgent(i, fleet=fleet, k=k, superior=topo.superiors[i], vehicle=vehicle,
                         algorithm=build._algorithm(cfg.algo.drone, DroneAlgorithm, "drone"), **common(i))
              for k, (i, vehicle) in enumerate(zip(ids, backend.vehicles, strict=True))]
    event_logs = {i: recorder.node(i).appender("events") for i in ids}
    swarm = FleetSwarm(fleet=fleet, network=network, rows=rows, time=time, tick_s=timing.tick_s,
                       ground=ground, agents=agents, backend=backend, event_logs=event_logs)
    swarm.state_log = FleetCoreStateLog(swarm, recorder, timing.state_every_ticks)
    return swarm


def core_of(cfg: DictConfig) -> str:
    return str(OmegaConf.select(cfg, "run.core", default="object"))
