"""The launcher class Hydra instantiates; see ``swarmbox.run.launcher``.

No ``from __future__ import annotations`` here: Hydra imports plugin modules without registering
them in ``sys.modules``, and dataclasses then cannot resolve string annotations.
"""

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, Optional  # noqa: UP035 - OmegaConf reads these annotations

from hydra.core.config_store import ConfigStore
from hydra.core.utils import JobReturn
from hydra.plugins.launcher import Launcher
from hydra.types import HydraContext, TaskFunction
from omegaconf import DictConfig


@dataclass
class SwarmBoxLauncherConf:
    """``joblib.Parallel``'s settings, with the defaults and meaning of ``hydra/launcher=joblib``."""

    _target_: str = "hydra_plugins.swarmbox_launcher.launcher.SwarmBoxLauncher"
    n_jobs: int = -1                      # concurrent jobs; -1: one per CPU
    backend: Optional[str] = None         # noqa: UP045 - always loky: threads break Hydra's globals
    prefer: str = "processes"
    require: Optional[str] = None         # noqa: UP045
    verbose: int = 0                      # joblib's progress messages when > 0
    timeout: Optional[float] = None       # noqa: UP045 - per job, seconds
    pre_dispatch: str = "2*n_jobs"
    batch_size: str = "auto"
    temp_folder: Optional[str] = None     # noqa: UP045 - where joblib memory-maps large arrays
    max_nbytes: Optional[str] = None      # noqa: UP045
    mmap_mode: str = "r"


ConfigStore.instance().store(group="hydra/launcher", name="swarmbox", node=SwarmBoxLauncherConf,
                             provider="swarmbox")


class SwarmBoxLauncher(Launcher):
    """Jobs in loky processes through ``joblib.Parallel`` (same jobs, order, records and exit codes as
    ``hydra/launcher=joblib``), with Hydra's context serialised once per launch instead of once per
    job, and workers that end on Ctrl-C as a lone sweep process does (``swarmbox.run.launcher``)."""

    def __init__(self, **joblib_settings: Any) -> None:
        self.config: Optional[DictConfig] = None   # noqa: UP045
        self.task_function: Optional[TaskFunction] = None   # noqa: UP045
        self.hydra_context: Optional[HydraContext] = None   # noqa: UP045
        self.joblib = joblib_settings

    def setup(self, *, hydra_context: HydraContext, task_function: TaskFunction, config: DictConfig) -> None:
        self.config = config
        self.task_function = task_function
        self.hydra_context = hydra_context

    def launch(self, job_overrides: Sequence[Sequence[str]], initial_job_idx: int) -> Sequence[JobReturn]:
        from swarmbox.run import launcher  # imports joblib: only once a sweep launches

        return launcher.launch(self, job_overrides, initial_job_idx)
