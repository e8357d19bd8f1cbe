"""One node of a distributed run, in its own process: ``python -m swarmbox.run.node``.

    python -m swarmbox.run.node ground --run-dir RUN
    python -m swarmbox.run.node agent --drone 3 --run-dir RUN

``RUN`` holds the run's resolved ``config.yaml`` (the same config as a single-process run) and
``nodes/plan.json``: the mission id and every node's Zenoh locator. Once built and connected the
node writes ``nodes/<node>.ready`` and waits for ``nodes/start.json``, the wall-clock epoch of tick 0
shared by all nodes. The mission key comes from the ``SWARMBOX_NET_KEY`` environment variable (or
``run.net.key``). The node builds exactly what a single-process run builds for it — the same
mission, topology, timing, algorithm and, for an agent, a backend flying its one vehicle — then
ticks on its own wall clock, writes its logs under ``RUN/logs/<node>/`` and its outcome and
resource use to ``RUN/nodes/<node>.json``. SIGTERM or SIGINT ends it cleanly (logs closed).

Every process of a node counts its boot in ``nodes/<node>.boots``: the count is the node's
*incarnation*, carried in its message ids, reliable tasks and acknowledgements, so that a node started
again (after ``kill -9``, say) is never taken for its earlier process. A restarted ground adopts the
swarm's stage from the drones' Reports (``GroundNode.rejoin``).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import signal
import sys
import time as wall
import traceback
from pathlib import Path
from typing import Any

from omegaconf import DictConfig, OmegaConf

from swarmbox.api import DroneAlgorithm, GroundAlgorithm
from swarmbox.core.agent import AgentNode
from swarmbox.core.clock import ClockSpec, NodeClock, TimeSource
from swarmbox.core.messages import GROUND_ID
from swarmbox.core.rows import TEXTS
from swarmbox.core.stages import Stage
from swarmbox.net.auth import KEY_ENV, AuthSpec
from swarmbox.net.medium import LinkSpec
from swarmbox.net.zenoh_medium import ZenohMedium
from swarmbox.record.schema import node_name
from swarmbox.record.writer import Recorder
from swarmbox.run import build, mission, node_faults, node_logs, record
from swarmbox.run.params import typed_params
from swarmbox.run.runner import write_atomic

#: bytes reserved for a node's outcome (``nodes/<node>.json``, about 1 kB) before its logs are written
OUTCOME_RESERVE = 16 << 10


class NodeSetupError(ValueError):
    """The plan, the key or the node asked for does not fit the run."""


def proc_stats() -> dict[str, float]:
    """This process's CPU time (s) and resident memory now and at peak (MB), from /proc."""
    out: dict[str, float] = {"cpu_s": sum(os.times()[:2])}
    for line in Path("/proc/self/status").read_text().splitlines():
        key, _, value = line.partition(":")
        if key in ("VmRSS", "VmHWM"):
            out[key.lower() + "_mb"] = int(value.split()[0]) / 1024
    return out


def mission_key(cfg: DictConfig) -> bytes:
    """The mission's network key: ``run.net.key`` or the environment; never printed."""
    key = cfg.run.net.key or os.environ.get(cfg.run.net.key_env or KEY_ENV)
    if not key:
        raise NodeSetupError(f"no network key: set run.net.key or the {cfg.run.net.key_env} environment "
                             "variable (the launcher sets it for its nodes)")
    return str(key).encode()


def next_incarnation(run_dir: Path, name: str) -> int:
    """This process's boot count for node ``name`` in the run (0 for the first), counted on disk."""
    path = run_dir / "nodes" / f"{name}.boots"
    try:
        boots = int(path.read_text())
    except FileNotFoundError:
        boots = 0
    except ValueError as exc:
        raise NodeSetupError(f"{path} holds no boot count: {exc}") from None
    path.parent.mkdir(parents=True, exist_ok=True)
    write_atomic(path, str(boots + 1))
    return boots


def heartbeat_subscribers(topo_superiors: dict[int, int], peers: str) -> dict[int, list[int]]:
    """Who hears whose Heartbeats at the start: inferiors their superior, and peers each other."""
    subs: dict[int, list[int]] = {}
    for drone, sup in topo_superiors.items():
        subs.setdefault(sup, []).append(drone)
    if peers == "all":
        for a in topo_superiors:
            subs.setdefault(a, []).extend(b for b in topo_superiors if b != a and b not in subs[a])
    return subs


class NodeProcess:
    """Builds one node and its transport, and ticks it on the wall clock."""

    def __init__(self, cfg: DictConfig, run_dir: Path, node_id: int, plan: dict[str, Any]) -> None:
        self.cfg, self.run_dir, self.node_id, self.plan = cfg, run_dir, node_id, plan
        self.name = node_name(node_id)
        self.stop_requested = ""
        self.rejected: dict[str, int] = {}
        self.incarnation = next_incarnation(run_dir, self.name)
        # the node's outcome, its space reserved before any log is written (a full disk keeps it)
        self.record = record.RunJson(run_dir / "nodes", name=f"{self.name}.json",
                                     reserve_bytes=OUTCOME_RESERVE)
        self.record.reserve()
        self.texts_before = TEXTS.overflowed
        seed = int(cfg.seed)
        m = self.mission = mission.load(cfg, build.rng_for(seed, "dataset"))
        if node_id != GROUND_ID and node_id not in m.drone_ids:
            raise NodeSetupError(f"drone {node_id} is not in the mission (drones: {m.drone_ids})")
        locators = plan["locators"]
        self.timing = build.timing_of(cfg)
        topo = build.topology_of(cfg, m)
        clock_spec = build.clocks_of(cfg, m).get(node_id, ClockSpec())
        self.speed, self.epoch = float(cfg.run.speed), wall.time()   # until the start instant is known
        self.time = TimeSource()
        self.clock = NodeClock(self.time, clock_spec)
        n = cfg.network
        links = {(lk.src, lk.dst): LinkSpec(lk.latency_ms / 1e3, lk.jitter_ms / 1e3, lk.loss_prob)
                 for lk in n.links}
        auth = AuthSpec(mission_key(cfg), plan["mission_id"], float(cfg.run.net.max_age_s),
                        int(cfg.run.net.replay_window))
        self.medium = ZenohMedium(
            node_id, time=self.time, true_of=self.true_time, auth=auth, listen=locators[self.name],
            peers=[loc for name, loc in locators.items() if name != self.name],
            rng=build.rng_for(seed, f"network/{self.name}"),
            default=LinkSpec(n.latency_ms / 1e3, n.jitter_ms / 1e3, n.loss_prob), links=links,
            subscribers=heartbeat_subscribers(dict(topo.superiors), cfg.topology.peers),
            on_reject=self._on_reject)
        # A restarted node: the logs an earlier process of this node wrote become its first segment
        self.segments = node_logs.set_aside(run_dir, self.name)
        self.restarted = False
        # One node per recorder; never flushed mid-run, so the run-wide spill directory stays unused
        self.recorder = Recorder(run_dir)
        self.monitor = ground_monitor(cfg, m.name, run_dir) if node_id == GROUND_ID else None
        log = (self.monitor.tap(self.recorder) if self.monitor else self.recorder).node(node_id)
        inbox = self.medium.register(node_id, self.clock, log.appender("messages"))
        common = dict(time=self.time, clock=self.clock, net=self.medium, inbox=inbox, log=log,
                      timing=self.timing, mission=m.info(),
                      params=typed_params(cfg.algo),
                      rng=build.rng_for(seed, f"algo/{self.name}"), incarnation=self.incarnation)
        self.backend = None
        if os.environ.get("SWARMBOX_MAVLINK_KEY"):   # set by the launcher from backend.signing_key
            cfg.backend.signing_key = os.environ["SWARMBOX_MAVLINK_KEY"]   # MAVLink 2 signing of the link
        vehicle = plan.get("vehicles", {}).get(self.name)
        if vehicle:   # an autopilot the launcher started: connect to it like to a real vehicle
            cfg.backend.update(px4_build=None, wait_ready=True, **vehicle)
        if node_id == GROUND_ID:
            from swarmbox.core.ground import GroundNode  # (scipy: the ground only, agents stay small)
            self.node = GroundNode(build._algorithm(cfg.algo.ground, GroundAlgorithm, "ground"), **common)
            if self.monitor:
                self.monitor.watch(self.node)
        else:
            self.backend = build.backend_of(cfg, m, self.timing.tick_s, seed, run_dir / "nodes" / self.name,
                                            drone_ids=[node_id])
            algorithm = build._algorithm(cfg.algo.drone, DroneAlgorithm, "drone")
            self.node = AgentNode(node_id, superior=topo.superiors[node_id], vehicle=self.backend.vehicles[0],
                                  algorithm=algorithm, **common)
            if cfg.topology.peers == "all":
                for other in m.drone_ids:
                    if other != node_id:
                        self.medium.subscribe(node_id, other)
            self._events = log.appender("events")
        self.faults = node_faults.LocalSwarm(self.node, node_id, list(m.drone_ids), self.medium, self.time,
                                             self.timing.tick_s)
        node_faults.install(cfg, self.faults, m, self.backend, lambda stream: build.rng_for(seed, stream))

    def true_time(self, wall_s: float) -> float:
        """Mission time of a wall-clock instant (the clock every node reads, before its own error)."""
        return (wall_s - self.epoch) * self.speed

    def _on_reject(self, reason: str, sender: int | None) -> None:
        self.rejected[reason] = self.rejected.get(reason, 0) + 1
        self.node.event("security", f"rejected_{reason}", -3 if sender is None else sender)

    def wait_start(self, poll_s: float = 0.05) -> bool:
        """Say this node is ready, then wait for the launcher's start instant (False: stopped)."""
        nodes = self.run_dir / "nodes"
        start = nodes / "start.json"
        self.restarted = start.exists()        # the run is under way: this process restarts the node
        write_atomic(nodes / f"{self.name}.ready", str(os.getpid()))
        while not start.exists():
            if self.stop_requested:
                return False
            wall.sleep(poll_s)
        self.epoch = float(json.loads(start.read_text())["epoch_wall_s"])
        if self.restarted:   # join at the tick now due, not at tick 0 (no burst of catch-up ticks)
            now_s = (wall.time() - self.epoch) * self.speed
            self.time.tick = max(0, math.ceil(now_s / self.timing.tick_s))
            self.time.t_s = now_s
            self.node.event("topology", "process_restarted", self.node_id, tick=self.time.tick,
                            earlier_segments=len(self.segments), incarnation=self.incarnation)
            if self.node_id == GROUND_ID:
                self.node.rejoin()   # adopt the swarm's stage rather than command ICEBREAK
        return True

    def run(self) -> dict[str, Any]:
        """Tick until the node finishes, the mission's time limit passes or a stop is requested."""
        tick_s, t = self.timing.tick_s, self.time
        max_ticks = int(round(self.mission.max_sim_time_s / tick_s))
        node = self.node
        while not node.finished and t.tick < max_ticks and not self.stop_requested:
            due = self.epoch + t.tick * tick_s / self.speed
            ahead = due - wall.time()
            if ahead > 0:
                wall.sleep(ahead)
            t.t_s = self.true_time(wall.time())
            self.faults.run_due()
            self.medium.deliver_due()
            node.tick()
            if self.backend is not None:
                self.backend.step(tick_s)
                for ev in self.backend.drain_events():
                    self._events((self.clock.now(), t.tick, ev.kind, ev.name, self.node_id,
                                  json.dumps(ev.data, sort_keys=True, default=str)))
            t.tick += 1
        return self.outcome(max_ticks)

    def outcome(self, max_ticks: int) -> dict[str, Any]:
        node = self.node
        if self.stop_requested:
            status, reason = "aborted", f"stopped by {self.stop_requested}"
        elif not node.finished:
            status, reason = "aborted", f"max_sim_time_s reached in {node.stage.name}"
        elif node.stage is Stage.ABORT:
            status, reason = "aborted", node.reason
        else:
            status, reason = "ok", ""
        out = {"node": self.name, "status": status, "reason": reason, "stage": node.stage.name,
               "ticks": self.time.tick, "sim_time_s": self.time.t_s, "restarted": self.restarted,
               "incarnation": self.incarnation, "tasks_refused": node.tasks_refused}
        if self.node_id == GROUND_ID:
            out["lost_drones"] = sorted(i for i, inf in node.inferiors.items() if not inf.alive)
        return out

    def close(self, result: dict[str, Any]) -> None:
        """Stop the vehicle link and the session, finish the logs, write ``nodes/<node>.json``."""
        elapsed = max(wall.time() - self.epoch, 1e-9)
        if self.monitor is not None:   # before the stats, so that its last frame is counted
            try:
                result["monitor"] = self.monitor.stop(ground=self.node)
            except Exception as exc:  # noqa: BLE001 - watching must never cost the node its logs
                result["monitor"] = {"error": f"{type(exc).__name__}: {exc}"}
        result.update(proc_stats(), wall_s=elapsed, bytes_out=self.medium.bytes_out,
                      bytes_in=self.medium.bytes_in, rejected=self.rejected)
        try:
            if self.backend is not None:
                self.backend.close()
        finally:
            self.medium.close()
            record.close_logs(result, self.recorder)
            problems = record.texts_overflowed(self.texts_before)
            if problems:
                result["problems"] = problems
            try:
                node_logs.append_segments(self.run_dir, self.name, self.segments)
            finally:
                self.record.write(result)


def ground_monitor(cfg: DictConfig, mission_name: str, run_dir: Path) -> Any:
    """The ground process's live dashboard (``run.monitor``; the launcher hands it its terminal)."""
    from swarmbox import monitor

    dashboard = monitor.wanted(cfg.run.monitor, realtime=True, multirun=False)
    if not dashboard and not cfg.run.rerun:
        return None
    title = f"SwarmBox {mission_name} seed={cfg.seed} (processes)"
    return monitor.create(title, cfg.run.monitor_hz, dashboard=dashboard, rerun=cfg.run.rerun,
                          run_dir=run_dir)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m swarmbox.run.node", description=__doc__.split("\n\n")[0])
    ap.add_argument("role", choices=("ground", "agent"))
    ap.add_argument("--drone", type=int, help="the drone id (agent)")
    ap.add_argument("--run-dir", type=Path, required=True)
    args = ap.parse_args(argv)
    if (args.role == "agent") != (args.drone is not None):
        ap.error("--drone is required for an agent and not accepted for the ground")
    node_id = GROUND_ID if args.role == "ground" else args.drone
    cfg = OmegaConf.load(args.run_dir / "config.yaml")
    plan = json.loads((args.run_dir / "nodes" / "plan.json").read_text())
    proc = NodeProcess(cfg, args.run_dir, node_id, plan)

    def stop(signum: int, _frame: Any) -> None:
        proc.stop_requested = signal.Signals(signum).name

    signal.signal(signal.SIGTERM, stop)
    signal.signal(signal.SIGINT, stop)
    result: dict[str, Any] = {"node": proc.name, "status": "failed", "reason": ""}
    try:
        if proc.wait_start():
            result = proc.run()
        else:
            result.update(status="aborted", reason=f"stopped by {proc.stop_requested} before the start")
    except Exception as exc:
        result.update(reason=f"{type(exc).__name__}: {exc}", traceback=traceback.format_exc())
        print(result["traceback"], file=sys.stderr)
    finally:
        proc.close(result)
    print(f"{proc.name}: {result['status']} {result['reason']}", flush=True)
    return 0 if result["status"] != "failed" else 1


if __name__ == "__main__":
    sys.exit(main())
