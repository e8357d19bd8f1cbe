"""``hydra/sweeper=swarmbox`` makes the jobs Hydra's basic sweeper makes: the same override lists, in
the same order, in the same batches, with the same job numbers; built on Hydra's public ``Sweeper``
API (``hydra_plugins/swarmbox_sweeper``, ``swarmbox.run.sweeper.sweep_jobs``).

Both sweepers run their real ``sweep`` on SwarmBox's composed config and config loader; the launcher
they hand each batch to records it instead of flying it (a sweep of 60 flights would take minutes
and the launchers have their own tests: tests/run/test_launcher.py).
"""

from __future__ import annotations

from collections.abc import Sequence

import pytest
from hydra import compose, initialize_config_dir
from hydra.core.global_hydra import GlobalHydra
from hydra.core.utils import JobReturn, JobStatus
from hydra.errors import HydraException
from hydra.types import HydraContext
from hydra.utils import get_class

from tests.conftest import CONF


class RecordingLauncher:
    """Keeps each batch and its first job number; every job returns as completed."""

    def __init__(self) -> None:
        self.launches: list[tuple[int, list[list[str]]]] = []

    def launch(self, batch: Sequence[Sequence[str]], initial_job_idx: int) -> list[JobReturn]:
        self.launches.append((initial_job_idx, [list(job) for job in batch]))
        return [JobReturn(status=JobStatus.COMPLETED, _return_value=None) for _ in batch]


def launches(sweeper_name: str, arguments: list[str], tmp_path, max_batch_size=None, params=None):
    """What ``hydra/sweeper=<sweeper_name>`` hands its launcher for ``-m <arguments>``."""
    GlobalHydra.instance().clear()
    with initialize_config_dir(config_dir=str(CONF), version_base="1.3"):
        config = compose("config", overrides=[f"hydra/sweeper={sweeper_name}",
                                              f"hydra.sweep.dir={tmp_path / sweeper_name}"],
                         return_hydra_config=True)
        # The class Hydra's own config names for the choice (the basic sweeper's module is private).
        sweeper = get_class(config.hydra.sweeper._target_)(max_batch_size=max_batch_size, params=params)
        sweeper.hydra_context = HydraContext(config_loader=GlobalHydra.instance().config_loader(),
                                             callbacks=None)
        sweeper.config = config
        sweeper.launcher = RecordingLauncher()
        sweeper.sweep(arguments)
    GlobalHydra.instance().clear()
    assert (tmp_path / sweeper_name / "multirun.yaml").is_file()
    return sweeper.launcher.launches


SWEEPS = {
    "range and choices": (["algo=hover,formation", "seed=range(3)", "run.speed=2"], None, None),
    "range with a step": (["seed=range(1,10,3)", "algo=hover"], None, None),
    "choice() and a glob": (["mission=glob(formation*)", "seed=choice(4,5)"], None, None),
    "batches": (["algo=hover,formation,flocking", "seed=range(5)"], 4, None),
    "a key given twice": (["seed=7", "algo=hover,formation", "seed=1,2"], None, None),
    "sweeper params": (["algo=hover,formation"], 3, {"seed": "range(4)", "run.speed": "1,2"}),
    "params overridden": (["seed=9,10"], None, {"seed": "range(4)", "algo": "hover"}),
    "additions and deletions": (["+experiment=rq4_delivery_ci", "~hydra.callbacks.analyze", "seed=0,1"],
                                None, None),
}


@pytest.mark.parametrize("arguments, max_batch_size, params", SWEEPS.values(), ids=SWEEPS.keys())
def test_the_same_jobs_order_and_batches_as_hydras_basic_sweeper(tmp_path, arguments, max_batch_size, params):
    ours = launches("swarmbox", arguments, tmp_path, max_batch_size, params)
    basic = launches("basic", arguments, tmp_path, max_batch_size, params)
    assert ours == basic
    assert sum(len(batch) for _, batch in ours) > 1


def test_batches_number_jobs_on_from_the_previous_batch(tmp_path):
    ours = launches("swarmbox", ["algo=hover,formation,flocking", "seed=range(5)"], tmp_path,
                    max_batch_size=4)
    assert [(first, len(batch)) for first, batch in ours] == [(0, 4), (4, 4), (8, 4), (12, 3)]
    assert ours[0][1][:2] == [["algo=hover", "seed=0"], ["algo=hover", "seed=1"]]


def test_an_interval_is_refused_naming_the_override(tmp_path):
    with pytest.raises(HydraException, match=r"run\.speed=interval\(1,2\)"):
        launches("swarmbox", ["run.speed=interval(1,2)"], tmp_path)
