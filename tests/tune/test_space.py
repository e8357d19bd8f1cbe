"""Hydra's sweep syntax read as Optuna's search space: every form the tuner accepts, and each one it
refuses named in one line."""

from __future__ import annotations

import pytest
from optuna.distributions import CategoricalDistribution, FloatDistribution, IntDistribution

from swarmbox.tune.space import SpaceError, parse


def test_each_sweep_form_becomes_its_distribution_and_the_rest_is_fixed():
    space = parse({"algo.params.v_flock": "interval(2,6)"},
                  ["algo=flocking", "algo.params.p_rep=interval(0.1,2)",
                   "algo.params.C_frict=tag(log,interval(0.01,0.5))", "algo.params.n=tag(int,interval(1,10))",
                   "algo.params.k=range(2,10,2)", "algo.params.mode=choice(a,b)", "algo.params.x=0.5,1.5",
                   "+run.extra=3"])
    d = space.distributions()
    assert d["algo.params.v_flock"] == FloatDistribution(2.0, 6.0)
    assert d["algo.params.p_rep"] == FloatDistribution(0.1, 2.0)
    assert d["algo.params.C_frict"] == FloatDistribution(0.01, 0.5, log=True)
    assert d["algo.params.n"] == IntDistribution(1, 10)
    assert d["algo.params.k"] == IntDistribution(2, 8, step=2)          # range's stop is excluded
    assert d["algo.params.mode"] == CategoricalDistribution(("a", "b"))
    assert d["algo.params.x"] == CategoricalDistribution(("0.5", "1.5"))   # values as written
    assert space.fixed == ("algo=flocking", "+run.extra=3")


def test_a_job_gets_the_fixed_overrides_and_one_value_per_dimension_in_full_precision():
    space = parse(None, ["algo=flocking", "algo.params.p_rep=interval(0.1,2)", "algo.params.k=range(1,4)"])
    overrides = space.overrides({"algo.params.p_rep": 0.123456789012345, "algo.params.k": 3})
    assert overrides == ["algo=flocking", "algo.params.p_rep=0.123456789012345", "algo.params.k=3"]


def test_a_later_override_of_a_key_replaces_the_earlier_one():
    space = parse({"algo.params.p_rep": "interval(0.1,2)"}, ["algo.params.p_rep=0.7"])
    assert space.dimensions == () and space.fixed == ("algo.params.p_rep=0.7",)


@pytest.mark.parametrize(("override", "says"), [
    ("a=interval(2,1)", "low < high"),
    ("a=tag(log,interval(0,1))", "log interval needs low > 0"),
    ("a=tag(sqrt,interval(1,2))", "unknown tag"),
    ("a=range(3,3)", "empty"),
    ("a=range(3,4)", "one value"),
    ("a=choice(1,1)", "two values"),
    ("a=interval(1,", "interval(1,"),
])
def test_a_space_the_tuner_cannot_search_is_refused_naming_it(override, says):
    with pytest.raises(SpaceError) as err:
        parse(None, [override])
    assert says in str(err.value) and "\n" not in str(err.value)
