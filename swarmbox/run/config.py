"""Typed schemas of the configuration (Hydra structured configs).

Registered in Hydra's ConfigStore as ``base_config`` (the root config's first default), so a
misspelt key or a wrong type in any group fails before the run starts, with a message that names
the key. Each backend config file starts from its own schema (:mod:`swarmbox.run.backend_schema`,
generated from the backend's parameter dataclass), so backend keys are typed too.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Optional

from hydra.core.config_store import ConfigStore
from omegaconf import MISSING

from swarmbox.faults.schema import FaultConfig  # generated from the fault models' parameters
from swarmbox.run import backend_schema, dirname

GROUPS = ("algo", "mission", "topology", "backend", "network", "fault")


@dataclass
class AlgoConfig:
    name: str = MISSING
    drone: Any = MISSING            # {_target_: module.DroneClass}: one instance per drone
    ground: Any = None              # {_target_: module.GroundClass}; None: a ground with no mission logic
    params: dict[str, Any] = field(default_factory=dict)   # visible to both as ctx.params
    metrics: list[Any] = field(default_factory=list)       # marker -> metric rules for the analyzer


@dataclass
class MissionConfig:
    name: str = MISSING
    file: Optional[str] = None      # a mission YAML in the original SwarmBox format (overrides below)
    swarm_size: Optional[int] = None                        # default: number of initial positions
    # The maps below are checked when the mission loads (so that a whole map can also be given on
    # the command line, e.g. mission.initial_positions='{0:[0,0],1:[5,0]}').
    initial_positions: Optional[Any] = None   # id -> [n_m, e_m]
    superiors: Optional[Any] = None           # id -> superior id (-1 ground)
    values: Optional[Any] = None              # id -> list of numbers: mission data (e.g. packages)
    # A function that makes ``values`` from the run's seed: {_target_: module.fn, ...kwargs};
    # called as fn(rng=<numpy Generator>, **kwargs) -> {int: [float, ...]}; replaces ``values``.
    generator: Optional[Any] = None
    obstacles: list[Any] = field(default_factory=list)     # static obstacles for the simulator
    max_sim_time_s: float = 900.0   # hard stop of the run (s of simulated time)
    min_spawn_separation_m: float = 1.0   # initial positions closer than this are refused


@dataclass
class TopologyConfig:
    kind: str = "mission"   # mission | centralized | leader_follower | chain | tree | explicit
    leader: int = 0         # leader_follower
    branching: int = 2      # tree
    superiors: Optional[Any] = None   # explicit: id -> superior id (-1 ground)
    peers: str = "none"     # none | all: drones also hear each other's Heartbeats (ctx.peers)


@dataclass
class LinkConfig:
    src: int = MISSING
    dst: int = MISSING
    latency_ms: float = 0.0
    jitter_ms: float = 0.0
    loss_prob: float = 0.0


@dataclass
class NetworkConfig:
    name: str = "ideal"
    latency_ms: float = 0.0     # one-way, every link
    jitter_ms: float = 0.0      # extra uniform delay in [0, jitter_ms]
    loss_prob: float = 0.0      # Bernoulli per message and destination
    links: list[LinkConfig] = field(default_factory=list)   # per-link overrides


@dataclass
class StageTimeouts:
    ICEBREAK: float = 60.0      # s; a stage that overruns aborts the mission with a reason
    PREPARATION: float = 60.0
    EXECUTION: float = 900.0
    LANDING: float = 120.0
    TERMINATION: float = 10.0
    ABORT: float = 120.0


@dataclass
class SafetyConfig:
    max_speed_m_s: float = 12.0
    max_accel_m_s2: float = 5.0
    geofence_radius_m: float = 500.0
    max_alt_m: float = 120.0
    max_jump_m: float = 1000.0


@dataclass
class NetConfig:
    """The real network of ``runtime=processes`` (docs/distributed.md)."""

    key: Optional[str] = None       # the mission's HMAC key; null: from the env var below, else random
    key_env: str = "SWARMBOX_NET_KEY"   # environment variable holding the key
    max_age_s: float = 2.0          # s, wall-clock bound between a frame's sender and its receiver
    replay_window: int = 1024       # counters remembered per sender (replay protection)
    ready_timeout_s: float = 120.0  # wall s for every node process to be built and connected
    stop_timeout_s: float = 30.0    # wall s for agents to finish after the ground, then SIGTERM
    start_delay_s: float = 1.0      # wall s between "all ready" and tick 0
    # backend=mavsim: "agent" (each agent starts its own vehicle process) or "shared" (the launcher
    # starts one mavsim host with every vehicle; agents connect to theirs as to a running autopilot)
    vehicle_host: str = "agent"


@dataclass
class RunConfig:
    tick_hz: float = 40.0
    timeouts_s: StageTimeouts = field(default_factory=StageTimeouts)
    lost_inferior_ticks: int = 20   # no Report for this long: the inferior is lost
    lost_superior_ticks: int = 40   # no Heartbeat for this long: hand over, or failsafe
    task_retry_ticks: int = 8       # reliable TaskCommand re-send period
    task_max_retries: int = 40
    arm_retry_ticks: int = 20
    proximity_m: float = 2.0        # ProxAlert radius (m)
    proximity_window_s: float = 0.0  # s; > 0: also alert pairs that will come that close within it
    min_alive: int = 1              # fewer alive drones after ICEBREAK: abort
    state_every_ticks: int = 1      # state-table sampling period
    # node name -> {offset_s, drift_ppm}: local = true * (1 + drift_ppm * 1e-6) + offset_s, e.g.
    # run.clocks='{drone_2: {offset_s: 0.5, drift_ppm: 100}}'
    clocks: Optional[Any] = None
    safety: SafetyConfig = field(default_factory=SafetyConfig)
    speed: float = 1.0              # real-time backends: wall-clock pacing factor (SITL speed-up)
    progress: bool = True           # progress lines on stderr for long runs (off while the monitor shows)
    monitor: str = "auto"           # live dashboard: auto (real-time backends, on a terminal) | on | off
    monitor_hz: float = 2.0         # Hz, dashboard refresh rate
    # stream live to Rerun: a viewer's URL (rerun+http://127.0.0.1:9876/proxy) or an .rrd path
    # (a relative path is inside the run directory)
    rerun: Optional[str] = None
    out_dir: Optional[str] = None   # default: Hydra's output directory
    # wall s one hook call may take before the run fails naming it; null: off. Always off when the
    # vehicles were not started by the run (px4 backend connecting to running vehicles: hardware).
    hook_timeout_s: Optional[float] = 10.0
    resume: bool = False            # skip a run whose directory holds a finished run (ok/aborted)
    core: str = "object"            # object: one node object per drone | fleet: arrays (docs/performance.md)
    runtime: str = "single"         # single: one process | processes: ground + one process per agent
    # where log rows are encoded: thread (the run's process, during the loop) | process (one of its own,
    # another core) | auto (= thread, measured the faster of the two)
    log_writer: str = "auto"
    net: NetConfig = field(default_factory=NetConfig)


@dataclass
class SwarmConfig:
    seed: int = 0
    algo: AlgoConfig = MISSING
    mission: MissionConfig = MISSING
    topology: TopologyConfig = MISSING
    backend: Any = MISSING
    network: NetworkConfig = MISSING
    fault: FaultConfig = MISSING
    run: RunConfig = field(default_factory=RunConfig)


def register() -> None:
    dirname.register_resolver()   # run directory names (conf/config.yaml: hydra.run.dir, sweep.subdir)
    cs = ConfigStore.instance()
    cs.store(name="base_config", node=SwarmConfig)
    backend_schema.register(cs)
