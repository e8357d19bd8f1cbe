"""The sweeper class Hydra instantiates for ``hydra/sweeper=tune``; see ``swarmbox.tune``.

No ``from __future__ import annotations`` here: Hydra imports plugin modules without registering
them in ``sys.modules``, and dataclasses then cannot resolve string annotations.
"""

from dataclasses import dataclass
from typing import Any, Dict, List, Optional  # noqa: UP035 - OmegaConf reads these annotations

from hydra.core.config_store import ConfigStore
from hydra.core.plugins import Plugins
from hydra.plugins.launcher import Launcher
from hydra.plugins.sweeper import Sweeper
from hydra.types import HydraContext, TaskFunction
from omegaconf import DictConfig


@dataclass
class TuneSweeperConf:
    """``hydra.sweeper.*`` of a tuning study (docs/tuning.md)."""

    _target_: str = "hydra_plugins.swarmbox_tune.sweeper.TuneSweeper"
    objective: Any = None             # a metric name, or a list of them (multi-objective)
    directions: Any = None            # null: each metric's own (catalog, algo.metrics); else higher|lower
    n_trials: int = 20                # finished trials the study ends with (a resumed study counts its own)
    seeds: int = 5                    # seeds each trial flies (first_seed, first_seed + 1, ...)
    first_seed: int = 0
    heldout_seeds: int = 10           # seeds the best parameters are flown again on, after the study
    heldout_first_seed: int = 1000    # held-out seeds: heldout_first_seed, +1, ... (disjoint from the above)
    sampler: str = "tpe"              # tpe | random | cmaes | nsga2
    sampler_seed: int = 0
    batch_trials: int = 1             # trials asked and flown together (their seeds all in one launch)
    study_name: str = "tune"
    n_boot: int = 2000                # bootstrap resamples of the CIs over seeds
    params: Optional[Dict[str, str]] = None  # noqa: UP006, UP045 - search space, as on the command line


# Package ``hydra``: the sweeper's settings and the tuner's callback, which must come first in
# hydra.callbacks (its checks run before the sweep directory is claimed). Sweeper configs compose
# before the primary config, so this callback precedes the ones conf/config.yaml declares.
ConfigStore.instance().store(
    group="hydra/sweeper", name="tune", package="hydra", provider="swarmbox",
    node={"sweeper": TuneSweeperConf,
          "callbacks": {"tune": {"_target_": "swarmbox.tune.callback.TuneCallback"}}})


class TuneSweeper(Sweeper):
    """An Optuna study (ask and tell): each trial's parameters flown on several seeds through the
    configured launcher, scored by the analyzer's metrics (``swarmbox.tune.study``)."""

    def __init__(self, **settings: Any) -> None:
        self.settings = settings
        self.config: Optional[DictConfig] = None  # noqa: UP045
        self.launcher: Optional[Launcher] = None  # noqa: UP045
        self.hydra_context: Optional[HydraContext] = None  # noqa: UP045

    def setup(self, *, hydra_context: HydraContext, task_function: TaskFunction, config: DictConfig) -> None:
        self.hydra_context = hydra_context
        self.config = config
        self.launcher = Plugins.instance().instantiate_launcher(
            hydra_context=hydra_context, task_function=task_function, config=config)

    def sweep(self, arguments: List[str]) -> Any:  # noqa: UP006
        from swarmbox.tune.study import run_study

        assert self.config is not None and self.launcher is not None
        return run_study(self.config, self.launcher)
