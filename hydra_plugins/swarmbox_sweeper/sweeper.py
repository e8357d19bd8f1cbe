"""The sweeper class Hydra instantiates; see ``swarmbox.run.sweeper``.

No ``from __future__ import annotations`` here: Hydra imports plugin modules without registering
them in ``sys.modules``, and dataclasses then cannot resolve string annotations.
"""

import logging
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Dict, List, Optional, Sequence  # noqa: UP035 - OmegaConf reads these annotations

from hydra.core.config_store import ConfigStore
from hydra.core.override_parser.overrides_parser import OverridesParser
from hydra.core.plugins import Plugins
from hydra.core.utils import JobReturn
from hydra.plugins.launcher import Launcher
from hydra.plugins.sweeper import Sweeper
from hydra.types import HydraContext, TaskFunction
from omegaconf import DictConfig, OmegaConf

from swarmbox.run.sweeper import jobs_to_check, sweep_jobs

log = logging.getLogger(__name__)


@dataclass
class SwarmBoxSweeperConf:
    _target_: str = "hydra_plugins.swarmbox_sweeper.sweeper.SwarmBoxSweeper"
    max_batch_size: Optional[int] = None  # noqa: UP045 - OmegaConf 2.3 reads Optional, not X | None
    params: Optional[Dict[str, str]] = None  # noqa: UP006, UP045


ConfigStore.instance().store(group="hydra/sweeper", name="swarmbox", node=SwarmBoxSweeperConf,
                             provider="swarmbox")


class SwarmBoxSweeper(Sweeper):
    """The basic sweeper's jobs, order and batches (``sweep_jobs``), checking fewer configs up front.

    Before launching, the basic sweeper composes every job's config to catch a bad override early;
    each composition costs ~0.1 s, and a worker composes the job again anyway. This one composes a
    covering subset: every distinct combination of config-group choices, and every distinct
    ``key=value`` override at least once (``jobs_to_check``): 28 compositions instead of 180 for
    nine algorithms by twenty seeds, and a typo in any value still fails before the first run.
    """

    def __init__(self, max_batch_size: Optional[int] = None,  # noqa: UP045
                 params: Optional[Dict[str, str]] = None) -> None:  # noqa: UP006, UP045
        self.max_batch_size = max_batch_size
        self.params = dict(params or {})
        self.hydra_context: Optional[HydraContext] = None  # noqa: UP045
        self.config: Optional[DictConfig] = None  # noqa: UP045
        self.launcher: Optional[Launcher] = None  # noqa: UP045

    def setup(self, *, hydra_context: HydraContext, task_function: TaskFunction, config: DictConfig) -> None:
        self.hydra_context = hydra_context
        self.config = config
        self.launcher = Plugins.instance().instantiate_launcher(
            hydra_context=hydra_context, task_function=task_function, config=config)

    def batches(self, arguments: List[str]) -> List[List[List[str]]]:  # noqa: UP006
        """The jobs of ``hydra.sweeper.params`` and then the command line's overrides, in batches."""
        assert self.hydra_context is not None
        parser = OverridesParser.create(config_loader=self.hydra_context.config_loader)
        params = [f"{key}={value}" for key, value in self.params.items()]
        return sweep_jobs(parser.parse_overrides([*params, *arguments]), self.max_batch_size)

    def sweep(self, arguments: List[str]) -> Any:  # noqa: UP006
        """Launch the jobs batch by batch, with every secret hidden from ``multirun.yaml`` and the
        console job list (the jobs compose from ``arguments``, which keep their values)."""
        from swarmbox.run.record import hide_in_config

        assert self.config is not None and self.launcher is not None
        hide_in_config(self.config)
        batches = self.batches(arguments)
        sweep_dir = Path(self.config.hydra.sweep.dir)
        sweep_dir.mkdir(parents=True, exist_ok=True)
        OmegaConf.save(self.config, sweep_dir / "multirun.yaml")   # as every Hydra sweeper does
        returns: List[Sequence[JobReturn]] = []  # noqa: UP006
        first = 0
        for batch in batches:
            tic = time.perf_counter()
            self.validate_batch_is_legal(batch)
            log.debug(f"Composed {len(batch)} jobs' configs in {time.perf_counter() - tic:.2f} s")
            results = self.launcher.launch(batch, initial_job_idx=first)
            for result in results:
                _ = result.return_value   # a failed job raises its exception here, as in Hydra's sweeper
            first += len(batch)
            returns.append(results)
        return returns

    def validate_batch_is_legal(self, batch: Sequence[Sequence[str]]) -> None:
        assert self.config is not None and self.hydra_context is not None
        config = self.config
        loader = self.hydra_context.config_loader
        groups = set(config.hydra.runtime.choices.keys()) if "runtime" in config.hydra else set()

        def is_group(key: str) -> bool:
            return key in groups or bool(loader.get_group_options(key, results_filter=None))

        super().validate_batch_is_legal(jobs_to_check(batch, is_group))
