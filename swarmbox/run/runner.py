"""Execute one run: check it, build it, tick it to the end, and leave a complete run directory behind.

A config error (any of :data:`~swarmbox.run.checks.INPUT_ERRORS`) is raised before anything is
written — or, if only the build can detect it, after removing what the run had created. Once a run
starts, whatever happens — success, abort, a crashing or hung user hook, a signal — the run
directory ends up with ``run.json`` (status ``ok`` / ``aborted`` / ``failed`` / ``interrupted``,
reason, traceback, simulated time and ticks reached), the resolved ``config.yaml`` and every log row
written so far. Files are written atomically; a directory that already holds a finished run, or that
another process is writing into (:mod:`swarmbox.run.claims`), is never written into. The record's
fields, status rules and redaction are :mod:`swarmbox.run.record`'s, shared with the processes
runtime.
"""

from __future__ import annotations

import shutil
import time
import traceback
from collections.abc import Callable
from pathlib import Path
from typing import Any

from omegaconf import DictConfig

from swarmbox import monitor as live_monitor
from swarmbox.core.messages import GROUND_ID
from swarmbox.core.rows import TEXTS
from swarmbox.core.swarm import Swarm, gc_paused
from swarmbox.faults import FaultConfigError, describe
from swarmbox.record.schema import node_name
from swarmbox.record.writer import Recorder
from swarmbox.run import build, checks, claims, interrupt, record
from swarmbox.run.config import GROUPS
from swarmbox.run.progress import RunProgress
from swarmbox.run.record import RunExistsError, write_atomic
from swarmbox.run.tally import SafetyTally
from swarmbox.run.watchdog import HookTimeout, HookWatchdog

__all__ = ["RunExistsError", "execute", "redacted", "run_choices", "summary_line", "write_atomic"]


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


def _discard(claim: claims.Claim, run_json: record.RunJson, logs_existed: bool) -> None:
    """Remove what a run that never started created: its config, its reservation, its claim, and
    its directory if the run made it. Nothing was flushed before the first tick."""
    run_dir = claim.dir
    (run_dir / "config.yaml").unlink(missing_ok=True)
    run_json.discard()
    if not logs_existed:
        shutil.rmtree(run_dir / "logs", ignore_errors=True)
    claim.undo()


def execute(cfg: DictConfig, run_dir: Path, choices: dict[str, str], overrides: list[str],
            prepare: Callable[[Swarm], None] | None = None) -> dict[str, Any]:
    """Run one configuration into ``run_dir``; returns the manifest written as ``run.json``.

    Raises :class:`RunExistsError` (the directory holds a finished run, or another process is
    writing into it) or one of :data:`~swarmbox.run.checks.INPUT_ERRORS` (leaving the disk as it
    was) when the run cannot start. ``prepare(swarm)`` is called once the swarm is built, before the
    first tick (programmatic use: schedule events with ``swarm.schedule``).
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
    logs_existed = (run_dir / "logs").exists()
    secrets = record.secret_values(cfg, overrides)
    claim, run_json = claims.claim_run(cfg, run_dir, secrets)
    manifest = record.new_manifest(cfg, choices, overrides, n_drones=m.swarm_size,
                                   nodes=[node_name(i) for i in [GROUND_ID, *m.drone_ids]])
    recorder = Recorder(run_dir, writer=log_writer(cfg))
    swarm = progress = monitor = dog = None
    discard = False
    started = time.perf_counter()
    refused_texts = TEXTS.overflowed
    try:
        with interrupt.armed():
            try:
                title = f"SwarmBox {choices.get('algo', '?')}/{m.name} seed={cfg.seed}"
                monitor = _monitor(cfg, title, run_dir)
                swarm = build.build_swarm(cfg, m, monitor.tap(recorder) if monitor else recorder)
            except checks.INPUT_ERRORS:   # found only while building (a fault the backend cannot express)
                discard = True
                _discard(claim, run_json, logs_existed)
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
        _stop_watchers(manifest, dog, progress, monitor, swarm)
        if manifest["status"] in ("failed", "interrupted"):
            _reached(manifest, swarm, started)
        manifest["problems"] += record.texts_overflowed(refused_texts)
        if not discard:
            try:
                _close(manifest, swarm, recorder, run_json)
            finally:
                claim.release()
    return manifest


def _stop_watchers(manifest: dict[str, Any], dog: Any, progress: Any, monitor: Any, swarm: Any) -> None:
    if dog is not None:
        dog.stop()
    if progress is not None:
        progress.close()
    if monitor is not None:
        try:
            manifest["monitor"] = monitor.stop(swarm)
        except Exception as exc:  # noqa: BLE001 - watching must never cost the run its logs
            manifest["monitor"] = {"error": f"{type(exc).__name__}: {exc}"}


def _t(swarm: Swarm | None) -> float:
    return swarm.time.t_s if swarm is not None else 0.0


def _reached(manifest: dict[str, Any], swarm: Swarm | None, started: float) -> None:
    """How far a run that did not end by itself got: simulated time, ticks, wall time."""
    wall_s = time.perf_counter() - started
    manifest.update(wall_time_s=wall_s)
    if swarm is not None:
        manifest.update(sim_time_s=swarm.time.t_s, ticks=swarm.time.tick,
                        real_time_factor=swarm.time.t_s / wall_s if wall_s > 0 else None)


def _close(manifest: dict[str, Any], swarm: Swarm | None, recorder: Recorder, run_json: record.RunJson,
           ) -> None:
    """Stop the backend, finish every log file, then write run.json (last: it marks the run finished)."""
    try:
        if swarm is not None:
            swarm.backend.close()
            manifest["problems"] += list(getattr(swarm.backend, "problems", []))
    except Exception as exc:  # noqa: BLE001 - recorded; the logs must still be closed
        record.add_reason(manifest, f"backend close: {exc}")
    finally:
        with gc_paused():
            record.close_logs(manifest, recorder)
        manifest["log_writer"] = recorder.writer   # where the rows were encoded, in the end
        run_json.write(manifest)


def _monitor(cfg: DictConfig, title: str, run_dir: Path):
    """The live dashboard of this run, or None (see :mod:`swarmbox.monitor`)."""
    realtime = bool(getattr(build.backend_class(cfg.backend), "realtime", False))
    dashboard = live_monitor.wanted(cfg.run.monitor, realtime=realtime, multirun=record.in_sweep())
    if not dashboard and not cfg.run.rerun:
        return None
    return live_monitor.create(title, cfg.run.monitor_hz, dashboard=dashboard, rerun=cfg.run.rerun,
                               run_dir=run_dir)


def log_writer(cfg: DictConfig) -> str:
    """Where this run's log rows are encoded (``run.log_writer``). ``auto`` is the run's own process
    (``thread``): measured on a 2-core machine, a writer process gained nothing at 200 and 1,000 drones
    and lost 10 % at 36, alone or beside the other runs of a sweep (docs/performance.md)."""
    mode = str(cfg.run.log_writer)
    return "thread" if mode == "auto" else mode


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


def redacted(overrides: list[str]) -> list[str]:
    """``overrides`` with the value of every secret hidden (``backend.signing_key=***``)."""
    return record.redact_overrides(overrides)
