"""The launcher class Hydra instantiates; see ``swarmbox.run.launcher``.

No ``from __future__ import annotations`` here: Hydra imports plugin modules without registering
them in ``sys.modules``, and dataclasses then cannot resolve string annotations. The joblib plugin's
modules are imported as modules, not their classes: Hydra lists every plugin class it finds in a
plugin module, and would list the joblib launcher twice.
"""

from collections.abc import Sequence
from dataclasses import dataclass

from hydra.core.config_store import ConfigStore
from hydra.core.utils import JobReturn
from hydra_plugins.hydra_joblib_launcher import config, joblib_launcher


@dataclass
class SwarmBoxLauncherConf(config.JobLibLauncherConf):
    """The joblib launcher's fields (``n_jobs``, ``timeout``, ``pre_dispatch``, ...), same meaning."""

    _target_: str = "hydra_plugins.swarmbox_launcher.launcher.SwarmBoxLauncher"


ConfigStore.instance().store(group="hydra/launcher", name="swarmbox", node=SwarmBoxLauncherConf,
                             provider="swarmbox")


class SwarmBoxLauncher(joblib_launcher.JoblibLauncher):
    """The joblib launcher (loky processes, same jobs, order and returns), with Hydra's context
    serialised once per launch instead of once per job (``swarmbox.run.launcher``)."""

    def launch(self, job_overrides: Sequence[Sequence[str]], initial_job_idx: int) -> Sequence[JobReturn]:
        from swarmbox.run import launcher  # imports joblib: only once a sweep launches

        return launcher.launch(self, job_overrides, initial_job_idx)
