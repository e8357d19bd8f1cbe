"""The answer of a study: never a penalized trial, and for several objectives the Pareto trial best in
the first; the trials table shows penalized trials with their run counts."""

from __future__ import annotations

import math

import optuna
import pytest
from optuna.distributions import FloatDistribution

from swarmbox.tune.results import pick_best, trials_table

X = {"x": FloatDistribution(0, 1)}


def study_of(directions: list[str], told: list[tuple[list[float], int]]) -> optuna.Study:
    """An in-memory study whose trials were told ``values`` with ``not_ok`` runs not ok."""
    optuna.logging.set_verbosity(optuna.logging.WARNING)
    study = optuna.create_study(directions=directions, sampler=optuna.samplers.RandomSampler(seed=0))
    for values, not_ok in told:
        trial = study.ask(X)
        trial.set_user_attr("runs", {"ok": 5 - not_ok, "aborted": not_ok})
        trial.set_user_attr("values", {"m": [values[0]] * (5 - not_ok)})
        trial.set_constraint("runs_not_ok", float(not_ok))
        study.tell(trial, values)
    return study


def test_a_penalized_trial_is_never_the_answer_however_good_its_ok_runs():
    study = study_of(["maximize"], [([0.5], 0), ([0.9], 1), ([0.7], 0), ([-math.inf], 5)])
    assert pick_best(study, ("m",)).number == 2


def test_several_objectives_the_feasible_pareto_trial_best_in_the_first():
    study = study_of(["maximize", "maximize"], [([0.9, 1.0], 0), ([0.95, 0.5], 0), ([0.99, 9.0], 2),
                                                ([0.8, 2.0], 0)])
    assert pick_best(study, ("m", "n")).number == 1


def test_no_feasible_trial_no_answer():
    assert pick_best(study_of(["minimize"], [([1.0], 1), ([math.inf], 5)]), ("m",)) is None


def test_the_table_shows_a_penalized_trial_with_its_run_counts():
    study = study_of(["maximize"], [([0.5], 0), ([-math.inf], 5)])
    table = trials_table(study, ("m",), ["x"], 200).set_index("trial")
    assert list(table["state"]) == ["ok", "penalized"]
    assert table.loc[1, "runs_aborted"] == 5 and table.loc[1, "runs_ok"] == 0
    assert table.loc[1, "m_score"] == -math.inf and table.loc[1, "m_n"] == 0
    assert table.loc[0, "m_mean"] == pytest.approx(0.5) and table.loc[0, "success_rate"] == 1
