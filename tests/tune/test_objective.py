"""A trial's score over its seeds and the penalty rule; objectives resolved against the metric catalog
and the algorithm's declared metrics."""

from __future__ import annotations

import math

import numpy as np
import pytest

from swarmbox.tune.objective import Objective, ObjectiveError, resolve, score

FLOCKING = {"algo": {"name": "flocking", "metrics": [
    {"name": "flock_order", "marker": "flock", "field": "order", "agg": ["mean", "min"],
     "direction": "higher"},
    {"name": "wait_s", "marker": "w", "measure": "since_exec_start"}]}}
ORDER = Objective(("flock_order_mean",), ("higher",))
TWO = Objective(("flock_order_mean", "collision_events"), ("higher", "lower"))


def run(status: str, **values: float) -> dict:
    return {"status": status, "values": values}


def test_every_run_ok_the_trial_is_feasible_and_scores_the_mean_over_seeds():
    sc = score([run("ok", flock_order_mean=0.5), run("ok", flock_order_mean=0.7),
                run("ok", flock_order_mean=0.9)], ORDER)
    assert sc.feasible and sc.told == [pytest.approx(0.7)]
    assert sc.counts == {"ok": 3, "aborted": 0, "failed": 0, "interrupted": 0, "missing": 0}


def test_an_aborted_run_makes_the_trial_infeasible_and_is_never_averaged_away():
    sc = score([run("ok", flock_order_mean=0.9), run("aborted", flock_order_mean=0.99),
                run("failed")], ORDER)
    assert not sc.feasible and sc.not_ok == 2
    assert sc.told == [0.9]                        # the ok run only: the aborted one's value is not used
    assert sc.counts["aborted"] == 1 and sc.counts["failed"] == 1


@pytest.mark.parametrize(("objective", "worst"), [(ORDER, [-math.inf]), (TWO, [-math.inf, math.inf])])
def test_a_trial_whose_runs_all_abort_is_told_the_worst_value_in_each_direction(objective, worst):
    sc = score([run("aborted"), run("aborted"), {"status": "missing", "values": {}}], objective)
    assert sc.told == worst and sc.not_ok == 3 and not sc.feasible
    assert sc.counts["aborted"] == 2 and sc.counts["missing"] == 1


def test_an_ok_run_without_a_value_of_the_metric_counts_against_the_trial():
    sc = score([run("ok", flock_order_mean=0.8), run("ok", flock_order_mean=float("nan"))], ORDER)
    assert not sc.feasible and sc.not_ok == 1 and sc.told == [0.8]
    np.testing.assert_array_equal(sc.values["flock_order_mean"], [0.8])


def test_directions_come_from_the_declaration_then_the_catalog_and_can_be_given():
    assert resolve(["flock_order_mean", "min_separation_m"], [], FLOCKING).directions == ("higher", "higher")
    assert resolve(["wait_s_mean"], [], FLOCKING).directions == ("lower",)      # declared default
    assert resolve(["order_mean"], ["higher"], FLOCKING).optuna_directions == ["maximize"]


@pytest.mark.parametrize(("metrics", "directions", "says"), [
    (["flock_order_max"], [], "unknown metric 'flock_order_max' for algo flocking"),
    (["delivery_time_mean"], [], "unknown metric"),
    (["wall_time_s"], [], "unknown metric"),                 # a machine figure, not a result
    (["order_mean"], [], "no better direction"),
    (["order_mean"], ["up"], "got 'up'"),
    (["min_separation_m", "order_mean"], ["higher"], "1 direction(s) for 2"),
    ([], [], "name the metric"),
])
def test_an_objective_the_tuner_cannot_optimise_is_refused_naming_it(metrics, directions, says):
    with pytest.raises(ObjectiveError) as err:
        resolve(metrics, directions, FLOCKING)
    assert says in str(err.value)
