"""Execute one run: build it, tick it to the end, and leave a complete run directory behind.

Whatever happens — success, abort, a crashing user algorithm, bad config — the run directory ends
up with ``run.json`` (status ``ok`` / ``aborted`` / ``failed``, reason, traceback), the resolved
``config.yaml`` and every log row written so far. Files are written atomically, and a directory that
already holds a finished run is never written into.
"""

from __future__ import annotations

import json
import os
import platform
import subprocess
import traceback
from collections.abc import Callable
from datetime import UTC, datetime
from importlib import metadata
from pathlib import Path
from typing import Any

from omegaconf import DictConfig, OmegaConf

from swarmbox import __version__
from swarmbox.core.messages import GROUND_ID
from swarmbox.core.swarm import Swarm, gc_paused
from swarmbox.faults import FaultConfigError, describe
from swarmbox.record.schema import SCHEMA_VERSION, node_name
from swarmbox.record.writer import Recorder
from swarmbox.run import build, mission
from swarmbox.run.config import GROUPS
from swarmbox.run.progress import RunProgress

_PROJECT_ROOT = Path(__file__).resolve().parents[2]


class RunExistsError(FileExistsError):
    pass


def write_atomic(path: Path, text: str) -> None:
    tmp = path.with_name(f".{path.name}.tmp")
    tmp.write_text(text)
    os.replace(tmp, path)


def _versions() -> dict[str, str]:
    out = {"swarmbox": __version__, "python": platform.python_version()}
    for pkg in ("numpy", "pymunk", "hydra-core", "omegaconf", "pyarrow", "pymavlink"):
        try:
            out[pkg] = metadata.version(pkg)
        except metadata.PackageNotFoundError:
            pass
    return out


def _git_sha() -> str | None:
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


def execute(cfg: DictConfig, run_dir: Path, choices: dict[str, str], overrides: list[str],
            prepare: Callable[[Swarm], None] | None = None) -> dict[str, Any]:
    """Run one configuration into ``run_dir``; returns the manifest written as ``run.json``.

    ``prepare(swarm)`` is called once the swarm is built, before the first tick (programmatic use:
    schedule events with ``swarm.schedule``).
    """
    if cfg.run.runtime == "processes":
        if prepare is not None:
            raise ValueError("prepare() needs the single-process runtime (run.runtime=single)")
        from swarmbox.run import processes
        return processes.execute(cfg, run_dir, choices, overrides)
    if cfg.run.runtime != "single":
        raise ValueError(f"run.runtime must be 'single' or 'processes', got '{cfg.run.runtime}'")
    run_dir.mkdir(parents=True, exist_ok=True)
    if (run_dir / "run.json").exists():
        raise RunExistsError(f"{run_dir} already holds a finished run; refusing to overwrite it")
    write_atomic(run_dir / "config.yaml", OmegaConf.to_yaml(cfg, resolve=True))
    manifest: dict[str, Any] = {
        "schema": SCHEMA_VERSION, "status": "failed", "reason": "", "traceback": None,
        "seed": int(cfg.seed), "choices": choices, "overrides": overrides,
        "sim_time_s": 0.0, "wall_time_s": 0.0, "real_time_factor": None, "ticks": 0,
        "tick_s": 1.0 / cfg.run.tick_hz, "n_drones": 0, "nodes": [],
        "clocks": {},
        "versions": _versions(), "git_sha": _git_sha(),
        "started_at": datetime.now(UTC).isoformat(timespec="seconds"),
    }
    recorder = Recorder(run_dir)
    swarm = progress = None
    try:
        m = mission.load(cfg, build.rng_for(int(cfg.seed), "dataset"))
        manifest["n_drones"] = m.swarm_size
        if cfg.mission.file:   # record the file's own mission, not the group it was loaded over
            manifest["choices"] = choices = {**choices, "mission": m.name}
        manifest["nodes"] = [node_name(i) for i in [GROUND_ID, *m.drone_ids]]
        manifest["clocks"] = build.clock_settings(cfg)
        swarm = build.build_swarm(cfg, m, recorder)
        if prepare is not None:
            prepare(swarm)
        label = f"{choices.get('algo', '?')} seed={cfg.seed}"
        progress = RunProgress(label, m.max_sim_time_s) if cfg.run.progress else None

        def tick_hook(s: Swarm) -> None:
            recorder.maybe_flush()
            if progress:
                progress(s)

        outcome = swarm.run(m.max_sim_time_s, speed=cfg.run.speed, progress=tick_hook)
        manifest.update(status=outcome.status, reason=outcome.reason, sim_time_s=outcome.sim_time_s,
                        wall_time_s=outcome.wall_time_s, ticks=outcome.ticks,
                        real_time_factor=outcome.real_time_factor)
    except Exception as exc:
        manifest.update(status="failed", reason=f"{type(exc).__name__}: {exc}",
                        traceback=traceback.format_exc())
        if swarm is not None:
            manifest.update(sim_time_s=swarm.time.t_s, ticks=swarm.time.tick)
    finally:
        if progress is not None:
            progress.close()
        try:
            if swarm is not None:
                swarm.backend.close()
        finally:
            try:
                with gc_paused():
                    recorder.close()
            except OSError as exc:
                manifest.update(status="failed", reason=f"{manifest['reason']}; {exc}".strip("; "))
            write_atomic(run_dir / "run.json", json.dumps(manifest, indent=2, sort_keys=True))
    return manifest


def summary_line(manifest: dict[str, Any], run_dir: Path) -> str:
    ch = manifest["choices"]
    head = f"{manifest['status'].upper():7} {ch.get('algo')}/{ch.get('mission')} seed={manifest['seed']}"
    if manifest["status"] == "failed":
        return f"{head}: {manifest['reason']}  [{run_dir}]"
    rtf = manifest["real_time_factor"]
    tail = f" ({manifest['reason']})" if manifest["reason"] else ""
    return (f"{head}: {manifest['sim_time_s']:.1f} s simulated in {manifest['wall_time_s']:.2f} s "
            f"({rtf:.0f}x real time){tail}  [{run_dir}]")
