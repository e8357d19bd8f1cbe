"""The sweep launcher ``hydra/launcher=swarmbox``: Hydra's joblib launcher's jobs, with their context
shipped once per launch, not once per job, on public APIs only (Hydra's ``Launcher`` plugin and
``hydra.core.utils``, ``joblib.Parallel``, ``cloudpickle``).

The joblib launcher hands every job the whole context of the sweep — Hydra's context (config loader
and callbacks), the master config, the task function and a copy of Hydra's singletons: the main
process pickles all of it for every job, and the worker unpickles it and installs the singletons,
re-scanning every Hydra plugin, before composing the job's config (~60 ms of CPU a job in all for
SwarmBox's config: docs/scale-out.md). Here :func:`launch` pickles that context once into a private
temporary file (removed when the launch returns, whatever happens); a job carries its index, its
overrides and the file's path. A worker process loads the file and installs Hydra's globals the
first time it meets that path and keeps them for the next jobs of the launch — as Hydra's basic
launcher keeps them for every job in its one process; a worker that loky starts afresh loads the
file again. From there a job is what the joblib launcher makes of it: :func:`execute_job` composes
its config with ``load_sweep_config``, sets ``hydra.job.id`` / ``num`` and calls ``run_job``. Jobs
run in loky processes through ``joblib.Parallel`` with the launcher's joblib settings, in the same
order, returning the same :class:`~hydra.core.utils.JobReturn` values. Unlike joblib's, a worker
routes SIGINT / SIGTERM through :mod:`swarmbox.run.interrupt`, as the command line does in a lone
sweep process: Ctrl-C ends the runs in flight as ``interrupted`` with their files written, starts no
later job, and the sweep closes with its summary instead of a traceback.
"""

from __future__ import annotations

import logging
import os
import pickle
import tempfile
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Protocol

import cloudpickle  # a task function defined in __main__ travels by value
from hydra.core.hydra_config import HydraConfig
from hydra.core.singleton import Singleton
from hydra.core.utils import JobReturn, configure_log, filter_overrides, run_job, setup_globals
from hydra.types import HydraContext, TaskFunction
from joblib import Parallel, delayed
from omegaconf import DictConfig, open_dict

from swarmbox.run import interrupt

log = logging.getLogger(__name__)

CONTEXT_PREFIX = "swarmbox-launch-"


@dataclass(frozen=True, slots=True)
class LaunchContext:
    """What every job of one launch shares (the joblib launcher's per-job arguments but two)."""

    hydra_context: HydraContext
    config: DictConfig                    # the sweep's master config
    task_function: TaskFunction
    singleton_state: dict[str, Any]       # Singleton.get_state() at launch time


class SetUpLauncher(Protocol):
    """A launcher after Hydra's ``setup``, with its ``joblib.Parallel`` settings."""

    config: DictConfig | None
    task_function: TaskFunction | None
    hydra_context: HydraContext | None
    joblib: dict[str, Any]


_INT_SETTINGS = ("pre_dispatch", "batch_size", "max_nbytes")   # strings in the config, numbers or not


def parallel_settings(settings: dict[str, Any]) -> dict[str, Any]:
    """The launcher's config as ``joblib.Parallel`` arguments: always loky processes (threads would
    share Hydra's globals between jobs), and ``pre_dispatch`` / ``batch_size`` / ``max_nbytes`` as
    integers when they are numbers (``"8"``), left as joblib's expressions otherwise (``"2*n_jobs"``,
    ``"auto"``, ``"1M"``)."""
    out = {**settings, "backend": "loky"}
    for key in _INT_SETTINGS:
        value = out.get(key)
        if isinstance(value, str) and value.strip().isdigit():
            out[key] = int(value)
    return out


_loaded: dict[str, LaunchContext] = {}   # in a worker: the context file met last, by path
_launcher_pid: int | None = None          # the process that launched (n_jobs=1 runs the jobs there)


def write_context(context: LaunchContext) -> Path:
    """Pickle ``context`` into a new file readable by this user only (``mkstemp``) and return its path."""
    fd, name = tempfile.mkstemp(prefix=CONTEXT_PREFIX, suffix=".pkl")
    try:
        with os.fdopen(fd, "wb") as f:
            cloudpickle.dump(context, f, protocol=pickle.HIGHEST_PROTOCOL)
    except BaseException:
        os.unlink(name)
        raise
    return Path(name)


def load_context(path: str) -> LaunchContext:
    """The launch's context in this process, with Hydra's globals set up for it: read from ``path``
    and installed on the first job of the launch this process runs, reused by the next."""
    context = _loaded.get(path)
    if context is None:
        with open(path, "rb") as f:
            context = pickle.load(f)
        setup_globals()
        Singleton.set_state(context.singleton_state)
        _loaded.clear()          # a reused worker holds only the current launch
        _loaded[path] = context
        if os.getpid() != _launcher_pid:   # a worker process: signals as in a lone sweep process
            interrupt.install()            # (the run in flight ends interrupted, no later job starts)
    return context


def execute_job(idx: int, overrides: Sequence[str], context_path: str) -> JobReturn:
    """One job, in a worker: its config composed from the sweep's master config and its overrides,
        numbered, run by Hydra's ``run_job`` in its own directory of the sweep."""
    context = load_context(context_path)
    sweep_config = context.hydra_context.config_loader.load_sweep_config(context.config, list(overrides))
    with open_dict(sweep_config):
        sweep_config.hydra.job.id = f"{sweep_config.hydra.job.name}_{idx}"
        sweep_config.hydra.job.num = idx
    HydraConfig.instance().set_config(sweep_config)
    return run_job(hydra_context=context.hydra_context, config=sweep_config,
                   task_function=context.task_function, job_dir_key="hydra.sweep.dir",
                   job_subdir_key="hydra.sweep.subdir")


def launch(launcher: SetUpLauncher, job_overrides: Sequence[Sequence[str]],
           initial_job_idx: int) -> Sequence[JobReturn]:
    """Every job of the batch through ``joblib.Parallel``, each carrying only its index, overrides and
    the context file's path; their ``JobReturn`` values in job order."""
    global _launcher_pid
    _launcher_pid = os.getpid()
    setup_globals()
    assert launcher.config is not None
    assert launcher.task_function is not None
    assert launcher.hydra_context is not None

    configure_log(launcher.config.hydra.hydra_logging, launcher.config.hydra.verbose)
    sweep_dir = Path(str(launcher.config.hydra.sweep.dir))
    sweep_dir.mkdir(parents=True, exist_ok=True)

    joblib_cfg = parallel_settings(dict(launcher.joblib))
    settings = ",".join(f"{k}={v}" for k, v in joblib_cfg.items())
    log.info(f"SwarmBox launcher: Joblib.Parallel({settings}) is launching {len(job_overrides)} jobs")
    log.info(f"Launching jobs, sweep output dir : {sweep_dir}")
    for idx, overrides in enumerate(job_overrides):
        log.info(f"\t#{idx} : {' '.join(filter_overrides(overrides))}")

    context = LaunchContext(launcher.hydra_context, launcher.config, launcher.task_function,
                            Singleton.get_state())
    path = write_context(context)
    try:
        log.info(f"Job context: {path} ({path.stat().st_size / 1e3:.0f} kB), read once by each worker")
        runs = Parallel(**joblib_cfg)(
            delayed(execute_job)(initial_job_idx + idx, overrides, str(path))
            for idx, overrides in enumerate(job_overrides)
        )
    finally:
        path.unlink(missing_ok=True)
        _loaded.pop(str(path), None)   # n_jobs=1 runs the jobs in this process
    assert isinstance(runs, list)
    for run in runs:
        assert isinstance(run, JobReturn)
    return runs
