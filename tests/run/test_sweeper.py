"""The sweep checks a covering subset of its jobs before launching: every distinct combination of
config-group choices and every value, so a bad override anywhere still fails before the first run."""

from __future__ import annotations

import itertools

from swarmbox.run.sweeper import jobs_to_check, override_key
from tests.run.test_cli import swarmbox_run

ALGOS = [f"algo=delivery_{i}" for i in range(9)]
SEEDS = [f"seed={s}" for s in range(20)]


def is_group(key: str) -> bool:
    return key in {"algo", "mission", "experiment", "hydra/launcher"}


def test_rq4_shape_checks_9_of_180_jobs_covering_every_choice_and_kind_of_value():
    batch = [list(job) for job in itertools.product(ALGOS, SEEDS)]
    chosen = jobs_to_check(batch, is_group)
    assert len(chosen) == 9   # one per algorithm; twenty seeds are numbers of one key
    assert {job[0] for job in chosen} == set(ALGOS)
    assert chosen == [job for job in batch if job in chosen]          # the sweep's own order


def test_a_value_that_is_not_a_number_is_checked_on_its_own():
    batch = [["algo=a", "seed=0"], ["algo=a", "seed=1"], ["algo=a", "seed=1x"], ["algo=a", "seed=2.5"],
             ["algo=a", "seed=-3"], ["algo=a", "x=abc"], ["algo=a", "x=abd"], ["algo=a", "seed=1e3"]]
    assert jobs_to_check(batch, is_group) == [batch[i] for i in (0, 2, 3, 5, 6)]


def test_every_group_combination_is_checked_and_a_job_without_news_is_not():
    batch = [["algo=a", "mission=m1", "seed=0"], ["algo=a", "mission=m2", "seed=0"],
             ["algo=b", "mission=m1", "seed=0"], ["algo=b", "mission=m2", "seed=0"],
             ["algo=b", "mission=m2", "seed=0", "+run.speed=2"], ["algo=a", "mission=m1", "seed=0"]]
    assert jobs_to_check(batch, is_group) == batch[:5]


def test_override_keys():
    assert override_key("+algo.params.x=1") == "algo.params.x"
    assert override_key("~hydra.callbacks.analyze") == "hydra.callbacks.analyze"
    assert override_key("hydra/launcher=joblib") == "hydra/launcher"


def test_a_bad_value_in_a_later_job_fails_the_sweep_before_any_run(tmp_path):
    proc = swarmbox_run("-m", "algo=hover", "mission=hover", "seed=0,1,2", "run.speed=1,2,fast",
                        f"hydra.sweep.dir={tmp_path}", "~hydra.callbacks.analyze")
    assert proc.returncode != 0
    assert "run.speed=fast" in proc.stderr and "could not be converted to Float" in proc.stderr, proc.stderr
    assert not list(tmp_path.glob("*/run.json"))


def test_a_bad_group_choice_fails_the_sweep_before_any_run(tmp_path):
    proc = swarmbox_run("-m", "algo=hover,no_such_algo", "mission=hover", "seed=0,1",
                        f"hydra.sweep.dir={tmp_path}", "~hydra.callbacks.analyze")
    assert proc.returncode != 0
    assert "no_such_algo" in proc.stderr, proc.stderr
    assert not list(tmp_path.glob("*/run.json"))
