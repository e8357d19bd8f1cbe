"""``run.runtime=processes``: the ground and every agent as separate OS processes over Zenoh.

The launcher writes the run's resolved config (the key removed), picks a free TCP port per node on
127.0.0.1, starts ``python -m swarmbox.run.node`` for the ground and each drone, waits until every
node is built and connected (``nodes/<node>.ready``), then fixes the start instant
(``nodes/start.json``) so that all nodes tick from the same wall-clock epoch, each on its own clock.
The run ends when the ground process ends; agents get ``run.net.stop_timeout_s`` to land and
finish, then SIGTERM, then SIGKILL. Ctrl-C stops every node cleanly. Node logs land in the usual
``logs/<node>/`` tables, console output in ``nodes/<node>.log``, and ``run.json`` gathers every
node's outcome, exit code and resource use.
"""

from __future__ import annotations

import json
import os
import secrets
import signal
import subprocess
import sys
import time as wall
from pathlib import Path
from typing import Any

from omegaconf import DictConfig, OmegaConf

from swarmbox import monitor
from swarmbox.core.messages import GROUND_ID
from swarmbox.hal.mavlink.signing import KEY_ENV
from swarmbox.record.schema import node_name
from swarmbox.run import build, claims, interrupt, mission, node_faults, record, vehicle_host
from swarmbox.run.record import node_outcome, redact_overrides

#: The MAVLink 2 signing key of the vehicle links (``backend.signing_key``), handed to agent processes.
MAVLINK_KEY_ENV = KEY_ENV   # the MAVLink signing key, handed to agents and vehicle hosts
POLL_S = 0.2
#: the run's status and reason from its nodes' outcomes (the rules of :mod:`swarmbox.run.record`)
outcome = node_outcome
redact = redact_overrides


class LaunchError(RuntimeError):
    """A node process could not be started or never became ready."""


free_ports = vehicle_host.free_ports   # TCP ports for the Zenoh endpoints


def child_env(keep: dict[str, str] | None = None, key_env: str | None = None) -> dict[str, str]:
    """The environment of a process the launcher starts: this package first, only the keys in ``keep``."""
    return record.child_env(keep, key_env)


def _tail(path: Path) -> str:
    try:
        return path.read_text(errors="replace")[-1500:]
    except OSError:
        return ""


def autopilots(cfg: DictConfig, m: Any, run_dir: Path) -> tuple[Any, dict[str, dict[str, Any]]]:
    """PX4 SITL instances for ``backend=px4`` with a ``px4_build``, started here, not by the agents.

    They stand for the drones' autopilots, which exist before and apart from the companion computers:
    each agent process then connects to its own instance (``plan.json`` ``vehicles``) like to a real
    vehicle. Returns the launcher (None otherwise) and each agent's connection settings.
    """
    b = cfg.backend
    if b.get("name") != "px4" or not b.get("px4_build"):
        return None, {}
    from swarmbox.hal.mavlink.frames import GeoFrame
    from swarmbox.hal.px4.params import Px4Params
    from swarmbox.hal.px4.sitl import SitlLauncher, connection_of
    from swarmbox.hal.safety import SafetyLimits

    params = OmegaConf.to_container(b, resolve=True)
    params = {k: v for k, v in params.items() if k not in ("_target_", "name")}
    p = Px4Params.from_kwargs(params)
    homes = [tuple(float(x) for x in m.initial_positions[i]) for i in m.drone_ids]
    sitl = SitlLauncher(p, homes, GeoFrame(p.origin_lat_deg, p.origin_lon_deg, p.origin_alt_m), run_dir,
                        SafetyLimits(**OmegaConf.to_container(cfg.run.safety)))
    sitl.start([0] * len(homes))
    return sitl, {node_name(i): {"connections": [connection_of(k)], "system_ids": [k + 1]}
                  for k, i in enumerate(m.drone_ids)}


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    try:   # a zombie (ended, not yet reaped by its parent) is not alive
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0] != "Z"
    except (OSError, IndexError):
        return False


def _signal(pid: int, sig: signal.Signals) -> None:
    try:
        os.kill(pid, sig)
    except ProcessLookupError:
        pass


class NodeSet:
    """The node processes of one run."""

    def __init__(self, cfg: DictConfig, run_dir: Path, drone_ids: list[int]) -> None:
        self.cfg, self.run_dir = cfg, run_dir
        self.nodes_dir = run_dir / "nodes"
        self.ids = [GROUND_ID, *drone_ids]
        self.procs: dict[int, subprocess.Popen[bytes]] = {}
        self.restarts: dict[int, int] = {}   # node -> pid of a process started again by someone else
        # the live dashboard draws from the ground process: it gets this process's terminal (stderr)
        self.dashboard = monitor.wanted(cfg.run.monitor, realtime=True, multirun=record.in_sweep())

    def start(self, secrets_env: dict[str, str], vehicles: dict[str, dict[str, Any]]) -> None:
        self.nodes_dir.mkdir(parents=True, exist_ok=True)
        ports = free_ports(len(self.ids))
        locators = {node_name(i): f"tcp/127.0.0.1:{p}" for i, p in zip(self.ids, ports, strict=True)}
        plan = {"mission_id": secrets.token_hex(6), "locators": locators, "vehicles": vehicles}
        (self.nodes_dir / "plan.json").write_text(json.dumps(plan, indent=2))
        key_env = str(self.cfg.run.net.key_env)
        # the swarm key for every node; the MAVLink key only for agents (they sign their vehicle's link)
        ground_env = child_env({k: v for k, v in secrets_env.items() if k != MAVLINK_KEY_ENV}, key_env)
        agent_env = child_env(secrets_env, key_env)
        for i in self.ids:
            role = ["ground"] if i == GROUND_ID else ["agent", "--drone", str(i)]
            with open(self.nodes_dir / f"{node_name(i)}.log", "wb") as out:
                self.procs[i] = subprocess.Popen(
                    [sys.executable, "-m", "swarmbox.run.node", *role, "--run-dir", str(self.run_dir)],
                    stdin=subprocess.DEVNULL, stdout=out, env=ground_env if i == GROUND_ID else agent_env,
                    stderr=None if i == GROUND_ID and self.dashboard else subprocess.STDOUT,
                    start_new_session=True)
        pids = {node_name(i): p.pid for i, p in self.procs.items()}
        (self.nodes_dir / "pids.json").write_text(json.dumps(pids))

    def wait_ready(self, timeout_s: float) -> None:
        deadline = wall.monotonic() + timeout_s
        waiting = set(self.ids)
        while waiting:
            for i in list(waiting):
                if (self.nodes_dir / f"{node_name(i)}.ready").exists():
                    waiting.discard(i)
                elif self.procs[i].poll() is not None:
                    log = _tail(self.nodes_dir / f"{node_name(i)}.log")
                    raise LaunchError(f"{node_name(i)} exited with code {self.procs[i].returncode} "
                                      f"before it was ready:\n{log}")
            if wall.monotonic() > deadline:
                late = [node_name(i) for i in sorted(waiting)]
                raise LaunchError(f"nodes not ready after {timeout_s:g} s: {late}")
            wall.sleep(POLL_S)

    def go(self, delay_s: float) -> float:
        epoch = wall.time() + delay_s
        tmp = self.nodes_dir / ".start.json.tmp"
        tmp.write_text(json.dumps({"epoch_wall_s": epoch}))
        os.replace(tmp, self.nodes_dir / "start.json")
        return epoch

    def adopt_restarts(self) -> None:
        """Note node processes started again (by hand or a supervisor) after theirs ended.

        A restarted node writes its own pid to ``nodes/<node>.ready``; the launcher then waits for
        it at the end as for its own children, and stops it the same way.
        """
        for i, p in self.procs.items():
            if p.poll() is None:
                continue
            try:
                pid = int((self.nodes_dir / f"{node_name(i)}.ready").read_text())
            except (OSError, ValueError):
                continue
            if pid != p.pid and _alive(pid):
                self.restarts[i] = pid

    def _running(self) -> bool:
        self.adopt_restarts()
        return (any(p.poll() is None for p in self.procs.values())
                or any(_alive(pid) for pid in self.restarts.values()))

    def _ground_restarted(self) -> bool:
        pid = self.restarts.get(GROUND_ID)
        return pid is not None and _alive(pid)

    def wait_ground(self) -> None:
        """Until the ground process ends, or the process that restarted it does."""
        ground = self.procs[GROUND_ID]
        while ground.poll() is None or self._ground_restarted():
            self.adopt_restarts()
            wall.sleep(POLL_S)

    def finish_agents(self, timeout_s: float) -> None:
        deadline = wall.monotonic() + timeout_s
        while self._running() and wall.monotonic() < deadline:
            if self._ground_restarted():   # the ground was started again: the run goes on with it
                self.wait_ground()
                deadline = wall.monotonic() + timeout_s
            wall.sleep(POLL_S)
        self.stop()

    def stop(self, grace_s: float = 15.0) -> None:
        """SIGTERM every live node, then SIGKILL what is still running after ``grace_s``."""
        for p in self.procs.values():
            if p.poll() is None:
                p.send_signal(signal.SIGTERM)
        for pid in self.restarts.values():
            _signal(pid, signal.SIGTERM)
        deadline = wall.monotonic() + grace_s
        for p in self.procs.values():
            try:
                p.wait(timeout=max(0.1, deadline - wall.monotonic()))
            except subprocess.TimeoutExpired:
                p.kill()
                p.wait()
        for pid in self.restarts.values():
            while _alive(pid) and wall.monotonic() < deadline:
                wall.sleep(POLL_S)
            _signal(pid, signal.SIGKILL)

    def results(self) -> dict[str, dict[str, Any]]:
        out = {}
        for i, p in self.procs.items():
            name = node_name(i)
            try:
                res = json.loads((self.nodes_dir / f"{name}.json").read_text())
            except (OSError, ValueError):
                res = {"node": name, "status": "failed", "reason": "no outcome written"}
            code = p.returncode
            res["exit_code"] = code
            if i in self.restarts:   # the outcome is the restarted process's; the first one's exit stays
                killed = code is not None and code < 0
                res["first_exit"] = (f"killed by {signal.Signals(-code).name}" if killed
                                     else f"exit code {code}")
            elif code is not None and code < 0:
                res.update(status="killed", reason=f"killed by {signal.Signals(-code).name}")
            out[name] = res
        return out


def _keys(cfg: DictConfig) -> dict[str, str]:
    """The keys the nodes need, by the environment variable that carries each to them."""
    out = {str(cfg.run.net.key_env): cfg.run.net.key or os.environ.get(cfg.run.net.key_env)
           or secrets.token_hex(32)}
    signing = OmegaConf.select(cfg, "backend.signing_key", default=None)
    if signing:
        out[MAVLINK_KEY_ENV] = str(signing)
    return out


def execute(cfg: DictConfig, run_dir: Path, choices: dict[str, str], overrides: list[str]) -> dict[str, Any]:
    """Run ``cfg`` as one process per node; returns the manifest written as ``run.json``."""
    keys = _keys(cfg)
    # the keys travel in the environment only
    claim, run_json = claims.claim_run(cfg, run_dir, {*record.secret_values(cfg, overrides), *keys.values()})
    manifest = record.new_manifest(cfg, choices, overrides, n_drones=0, nodes=[], runtime="processes",
                                   node_results={})
    start = wall.time()
    sitl = nodes = None
    try:
        m = mission.load(cfg, build.rng_for(int(cfg.seed), "dataset"))
        node_faults.check(cfg)
        vehicle_host.check(cfg)
        manifest.update(n_drones=m.swarm_size, nodes=[node_name(i) for i in [GROUND_ID, *m.drone_ids]])
        nodes = NodeSet(cfg, run_dir, list(m.drone_ids))
        sitl, vehicles = autopilots(cfg, m, run_dir)
        if sitl is None:
            nodes.nodes_dir.mkdir(parents=True, exist_ok=True)
            # a vehicle holds the MAVLink key its agent signs with, never the swarm key
            host_keys = {k: v for k, v in keys.items() if k == MAVLINK_KEY_ENV}
            host_env = child_env(host_keys, str(cfg.run.net.key_env))
            sitl, vehicles = vehicle_host.start(cfg, m, run_dir, host_env)
        with interrupt.armed():   # Ctrl-C / SIGTERM: every node is stopped, the run is interrupted
            nodes.start(keys, vehicles)
            nodes.wait_ready(float(cfg.run.net.ready_timeout_s))
            start = nodes.go(float(cfg.run.net.start_delay_s))
            nodes.wait_ground()
            nodes.finish_agents(float(cfg.run.net.stop_timeout_s))
        results = nodes.results()
        status, reason = outcome(results)
        g = results[node_name(GROUND_ID)]
        manifest.update(status=status, reason=reason, node_results=results, ticks=g.get("ticks", 0),
                        sim_time_s=g.get("sim_time_s", 0.0),
                        tasks_refused={k: r["tasks_refused"] for k, r in results.items()
                                       if r.get("tasks_refused")})
    except interrupt.RunInterrupted as exc:
        manifest.update(status="interrupted", reason=str(exc))
    except KeyboardInterrupt:   # no handler installed (programmatic use): record, then propagate
        manifest.update(status="interrupted", reason="interrupted by SIGINT")
        raise
    except Exception as exc:
        manifest.update(status="failed", reason=f"{type(exc).__name__}: {exc}")
    finally:
        _finish(manifest, nodes, sitl, start, run_json)
        claim.release()
    return manifest


def _finish(manifest: dict[str, Any], nodes: NodeSet | None, sitl: Any, start: float,
            run_json: record.RunJson) -> None:
    """Stop what still runs, then write run.json."""
    try:
        if nodes is not None:
            nodes.stop()
            manifest["node_results"] = manifest["node_results"] or nodes.results()
            g = manifest["node_results"].get(node_name(GROUND_ID), {})
            for name, res in manifest["node_results"].items():   # what a node's own log writing met
                manifest["problems"] += [f"{name}: {p}" for p in res.get("problems", [])]
                if res.get("tables_not_written"):
                    manifest["tables_not_written"] = [*manifest.get("tables_not_written", []),
                                                      *res["tables_not_written"]]
            if not manifest["ticks"]:   # stopped early: how far the ground got
                manifest.update(ticks=g.get("ticks", 0), sim_time_s=g.get("sim_time_s", 0.0))
        if sitl is not None:
            sitl.stop()
            if getattr(sitl, "stats", None):
                manifest["vehicle_host"] = sitl.stats
            manifest["problems"] += list(getattr(sitl, "problems", []))
    finally:
        elapsed = max(wall.time() - start, 1e-9)
        manifest.update(wall_time_s=elapsed, real_time_factor=manifest["sim_time_s"] / elapsed)
        run_json.write(manifest)
