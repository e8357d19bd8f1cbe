"""Execute one run: check it, build it, tick it to the end, and leave a complete run directory behind.

A config error (any of :data:`~swarmbox.run.checks.INPUT_ERRORS`) is raised before anything is
written — or, if only the build can detect it, after removing what the run had created. Once a run
starts, whatever happens — success, abort, a crashing or hung user hook, a signal — the run
directory ends up with ``run.json`` (status ``ok`` / ``aborted`` / ``failed`` / ``interrupted``,
reason, traceback, simulated time and ticks reached), the resolved ``config.yaml`` and every log row
written so far. Files are written atomically, and a directory that already holds a finished run is
never written into.
"""

from __future__ import annotations

import json
import os
import platform
import shutil
import subprocess
import time
import traceback
from collections.abc import Callable
from datetime import UTC, datetime
from functools import cache
from importlib import metadata
from pathlib import Path
from typing import Any

from omegaconf import DictConfig, OmegaConf

from swarmbox import __version__
from swarmbox import monitor as live_monitor
from swarmbox.core.messages import GROUND_ID
from swarmbox.core.swarm import Swarm, gc_paused
from swarmbox.faults import FaultConfigError, describe
from swarmbox.record.schema import SCHEMA_VERSION, node_name
from swarmbox.record.writer import Recorder
from swarmbox.run import build, checks, interrupt
from swarmbox.run.build import ConfigError
from swarmbox.run.config import GROUPS
from swarmbox.run.progress import RunProgress
from swarmbox.run.tally import SafetyTally
from swarmbox.run.watchdog import HookTimeout, HookWatchdog

_PROJECT_ROOT = Path(__file__).resolve().parents[2]


class RunExistsError(FileExistsError):
    pass


def write_atomic(path: Path, text: str) -> None:
    tmp = path.with_name(f".{path.name}.tmp")
    tmp.write_text(text)
    os.replace(tmp, path)


def _versions() -> dict[str, str]:
    return dict(_package_versions())


@cache
def _package_versions() -> tuple[tuple[str, str], ...]:
    """What this process runs on (read once: a sweep worker runs many jobs)."""
    out = {"swarmbox": __version__, "python": platform.python_version()}
    for pkg in ("numpy", "pymunk", "hydra-core", "omegaconf", "pyarrow", "pymavlink"):
        try:
            out[pkg] = metadata.version(pkg)
        except metadata.PackageNotFoundError:
            pass
    return tuple(out.items())


@cache
def _git_sha() -> str | None:
    """The checkout's commit when this process first asks: the code it imported (a sweep worker
    would otherwise start a ``git`` process per job)."""
    try:
        out = subprocess.run(["git", "rev-parse", "HEAD"], cwd=_PROJECT_ROOT, capture_output=True,
                             text=True, timeout=5, check=False)
    except (OSError, subprocess.SubprocessError):
        return None
    return out.stdout.strip() or None


def run_choices(cfg: DictConfig, hydra_choices: Any) -> dict[str, str]:
    """The config group chosen for each swappable part (composed faults: ``a+b``)."""
    choices = {g: str(hydra_choices.get(g)) for g in GROUPS}
    try:
        choices["fault"] = describe(cfg.fault)
    except FaultConfigError:
        pass   # the run itself reports the bad fault config, naming it
    return choices


def _refuse_finished(run_dir: Path) -> None:
    if (run_dir / "run.json").exists():
        raise RunExistsError(f"{run_dir} already holds a finished run; refusing to overwrite it")


def _watchdog(cfg: DictConfig, swarm: Swarm) -> HookWatchdog | None:
    """A hook watchdog for this run, or None: off when unset, and for vehicles the run did not start."""
    limit = cfg.run.hook_timeout_s
    if limit is None or getattr(swarm.backend, "launcher", "own") is None:
        return None
    dog = HookWatchdog(limit)
    dog.guard(swarm.ground.algorithm, "ground")
    for agent in swarm.agents:
        dog.guard(agent.algorithm, f"drone {agent.node_id}")
    return dog if dog.start() else None


def _discard(run_dir: Path, existed: bool, logs_existed: bool) -> None:
    """Remove what a run that never started created (its directory too, if the run made it).

    Nothing was flushed before the first tick, so the recorder has no file open.
    """
    if not existed:
        shutil.rmtree(run_dir, ignore_errors=True)
        return
    (run_dir / "config.yaml").unlink(missing_ok=True)
    if not logs_existed:
        shutil.rmtree(run_dir / "logs", ignore_errors=True)


def execute(cfg: DictConfig, run_dir: Path, choices: dict[str, str], overrides: list[str],
            prepare: Callable[[Swarm], None] | None = None) -> dict[str, Any]:
    """Run one configuration into ``run_dir``; returns the manifest written as ``run.json``.

    Raises :class:`RunExistsError` or one of :data:`~swarmbox.run.checks.INPUT_ERRORS` (leaving the
    disk as it was) when the run cannot start. ``prepare(swarm)`` is called once the swarm is built,
    before the first tick (programmatic use: schedule events with ``swarm.schedule``).
    """
    _refuse_finished(run_dir)
    m = checks.check(cfg)
    if cfg.run.runtime == "processes":
        if prepare is not None:
            raise ValueError("prepare() needs the single-process runtime (run.runtime=single)")
        from swarmbox.run import processes
        return processes.execute(cfg, run_dir, choices, overrides)
    if cfg.mission.file:   # record the file's own mission, not the group it was loaded over
        choices = {**choices, "mission": m.name}
    existed = run_dir.exists()
    logs_existed = (run_dir / "logs").exists()
    try:
        run_dir.mkdir(parents=True, exist_ok=True)
        write_atomic(run_dir / "config.yaml", _public_yaml(cfg))
    except OSError as exc:
        if run_dir.is_dir():
            _discard(run_dir, existed, logs_existed)
        raise ConfigError(f"run directory {run_dir} (run.out_dir / hydra.run.dir) cannot be written: "
                          f"{exc.strerror or exc}") from None
    manifest: dict[str, Any] = {
        "schema": SCHEMA_VERSION, "status": "failed", "reason": "", "traceback": None,
        "seed": int(cfg.seed), "choices": choices, "overrides": redacted(overrides),
        "sim_time_s": 0.0, "wall_time_s": 0.0, "real_time_factor": None, "ticks": 0,
        "tick_s": 1.0 / cfg.run.tick_hz, "n_drones": m.swarm_size,
        "nodes": [node_name(i) for i in [GROUND_ID, *m.drone_ids]], "clocks": build.clock_settings(cfg),
        "versions": _versions(), "git_sha": _git_sha(),
        "started_at": datetime.now(UTC).isoformat(timespec="seconds"),
    }
    recorder = Recorder(run_dir, writer=log_writer(cfg))
    swarm = progress = monitor = None
    dog = None
    discard = False
    started = time.perf_counter()
    try:
        with interrupt.armed():
            try:
                monitor = _monitor(cfg, f"SwarmBox {choices.get('algo', '?')}/{m.name} seed={cfg.seed}")
                swarm = build.build_swarm(cfg, m, monitor.tap(recorder) if monitor else recorder)
            except checks.INPUT_ERRORS:   # found only while building (a fault the backend cannot express)
                discard = True
                _discard(run_dir, existed, logs_existed)
                raise
            if prepare is not None:
                prepare(swarm)
            if monitor:
                monitor.start(swarm)
            dog = _watchdog(cfg, swarm)
            tally = SafetyTally(swarm.backend)
            label = f"{choices.get('algo', '?')} seed={cfg.seed}"
            show_progress = cfg.run.progress and not (monitor and monitor.dashboard)   # the dashboard says it
            progress = RunProgress(label, m.max_sim_time_s) if show_progress else None

            def tick_hook(s: Swarm) -> None:
                recorder.maybe_flush()
                if progress:
                    progress(s)

            outcome = swarm.run(m.max_sim_time_s, speed=cfg.run.speed, progress=tick_hook)
        reason = "; ".join(filter(None, [outcome.reason, tally.summary()]))
        manifest.update(status=outcome.status, reason=reason,
                        sim_time_s=outcome.sim_time_s, wall_time_s=outcome.wall_time_s, ticks=outcome.ticks,
                        real_time_factor=outcome.real_time_factor, safety=tally.record(),
                        tasks_refused={node_name(n.node_id): n.tasks_refused
                                       for n in (swarm.ground, *swarm.agents) if n.tasks_refused})
    except checks.INPUT_ERRORS as exc:
        if discard:
            raise
        manifest.update(status="failed", reason=f"{type(exc).__name__}: {exc}",   # raised while flying
                        traceback=traceback.format_exc())
    except interrupt.RunInterrupted as exc:
        manifest.update(status="interrupted", reason=f"{exc} at t={_t(swarm):.1f} s")
    except KeyboardInterrupt:     # no handler installed (programmatic use): record, then propagate
        manifest.update(status="interrupted", reason=f"interrupted by SIGINT at t={_t(swarm):.1f} s")
        raise
    except HookTimeout as exc:
        manifest.update(status="failed", reason=f"HookTimeout: {exc}", traceback=traceback.format_exc())
    except Exception as exc:
        manifest.update(status="failed", reason=f"{type(exc).__name__}: {exc}",
                        traceback=traceback.format_exc())
    finally:
        if dog is not None:
            dog.stop()
        if progress is not None:
            progress.close()
        if monitor is not None:
            try:
                manifest["monitor"] = monitor.stop(swarm)
            except Exception as exc:  # noqa: BLE001 - watching must never cost the run its logs
                manifest["monitor"] = {"error": f"{type(exc).__name__}: {exc}"}
        if manifest["status"] in ("failed", "interrupted"):
            _reached(manifest, swarm, started)
        if not discard:
            _close(manifest, swarm, recorder, run_dir)
    return manifest


def _t(swarm: Swarm | None) -> float:
    return swarm.time.t_s if swarm is not None else 0.0


def _reached(manifest: dict[str, Any], swarm: Swarm | None, started: float) -> None:
    """How far a run that did not end by itself got: simulated time, ticks, wall time."""
    wall_s = time.perf_counter() - started
    manifest.update(wall_time_s=wall_s)
    if swarm is not None:
        manifest.update(sim_time_s=swarm.time.t_s, ticks=swarm.time.tick,
                        real_time_factor=swarm.time.t_s / wall_s if wall_s > 0 else None)


def _close(manifest: dict[str, Any], swarm: Swarm | None, recorder: Recorder, run_dir: Path) -> None:
    """Stop the backend, finish every log file, then write run.json (last: it marks the run finished)."""
    try:
        if swarm is not None:
            swarm.backend.close()
    except Exception as exc:  # noqa: BLE001 - recorded; the logs must still be closed
        manifest.update(reason=f"{manifest['reason']}; backend close: {exc}".strip("; "))
    finally:
        try:
            with gc_paused():
                recorder.close()
        except OSError as exc:
            manifest.update(status="failed", reason=f"{manifest['reason']}; {exc}".strip("; "))
        manifest["log_writer"] = recorder.writer   # where the rows were encoded, in the end
        write_atomic(run_dir / "run.json", json.dumps(manifest, indent=2, sort_keys=True))


def _monitor(cfg: DictConfig, title: str):
    """The live dashboard of this run, or None (see :mod:`swarmbox.monitor`)."""
    realtime = bool(getattr(build.backend_class(cfg.backend), "realtime", False))
    dashboard = live_monitor.wanted(cfg.run.monitor, realtime=realtime, multirun=_in_sweep())
    if not dashboard and not cfg.run.rerun:
        return None
    return live_monitor.create(title, cfg.run.monitor_hz, dashboard=dashboard, rerun=cfg.run.rerun)


def log_writer(cfg: DictConfig) -> str:
    """Where this run's log rows are encoded (``run.log_writer``). ``auto`` is the run's own process
    (``thread``): measured on a 2-core machine, a writer process gained nothing at 200 and 1,000 drones
    and lost 10 % at 36, alone or beside the other runs of a sweep (docs/performance.md)."""
    mode = str(cfg.run.log_writer)
    return "thread" if mode == "auto" else mode


def _in_sweep() -> bool:
    from hydra.core.hydra_config import HydraConfig
    from hydra.types import RunMode

    return HydraConfig.initialized() and HydraConfig.get().mode == RunMode.MULTIRUN


def summary_line(manifest: dict[str, Any], run_dir: Path) -> str:
    ch = manifest["choices"]
    head = f"{manifest['status'].upper():7} {ch.get('algo')}/{ch.get('mission')} seed={manifest['seed']}"
    if manifest["status"] in ("failed", "interrupted"):
        return (f"{head}: {manifest['reason']} (stopped at t={manifest['sim_time_s']:.1f} s, tick "
                f"{manifest['ticks']})  [{run_dir}]")
    rtf = manifest["real_time_factor"]
    tail = f" ({manifest['reason']})" if manifest["reason"] else ""
    return (f"{head}: {manifest['sim_time_s']:.1f} s simulated in {manifest['wall_time_s']:.2f} s "
            f"({rtf:.0f}x real time){tail}  [{run_dir}]")


def _public_yaml(cfg: DictConfig) -> str:
    """The resolved config as written to ``config.yaml``: a MAVLink signing key is never written."""
    if not OmegaConf.select(cfg, "backend.signing_key", default=None):
        return OmegaConf.to_yaml(cfg, resolve=True)
    public = OmegaConf.to_container(cfg, resolve=True)
    public["backend"]["signing_key"] = None   # type: ignore[index]
    return OmegaConf.to_yaml(OmegaConf.create(public))


def redacted(overrides: list[str]) -> list[str]:
    """``overrides`` with the value of every key setting hidden (``backend.signing_key=***``)."""
    if not any("key=" in o for o in overrides):
        return overrides
    from swarmbox.run.processes import redact
    return redact(overrides)
