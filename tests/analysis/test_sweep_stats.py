"""Statistics that cannot mislead: no CI below n = 5, machine figures never ranked, pairs only by seed."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
from scipy import stats

from swarmbox.analysis import sweep
from swarmbox.analysis.sweep import MIN_N_CI, SweepOptions, analyze_sweep, summary_wide
from tests.analysis.conftest import sweep_scenarios
from tests.analysis.synthetic import build_run


@pytest.fixture(scope="module")
def small_sweep(tmp_path_factory):
    """fast: seeds 0-2; slow: seeds 2-4 -> 3 runs per group, one seed (2) in common."""
    root = tmp_path_factory.mktemp("small")
    for i, (name, sc) in enumerate(sweep_scenarios()):
        algo, seed = name.split("_")
        if (algo == "fast" and int(seed) <= 2) or (algo == "slow" and int(seed) >= 2):
            build_run(root / str(i), sc)
    return analyze_sweep(root, SweepOptions(n_boot=200))


def test_fewer_than_five_runs_get_no_ci_and_a_note(small_sweep):
    row = small_sweep.summary.set_index(["algo", "metric"]).loc[("fast", "mission_duration_s")]
    assert row["n"] == 3 and np.isnan(row["ci_low"]) and np.isnan(row["ci_high"])
    assert row["note"] == f"n=3 < {MIN_N_CI}: no CI"
    wide = summary_wide(small_sweep.summary, ("algo",)).set_index("metric")
    assert "(n=3, no CI)" in wide.loc["mission_duration_s", "fast"]


def test_pairs_only_where_seeds_pair(small_sweep):
    p = small_sweep.paired.set_index("metric").loc["mission_duration_s"]
    assert p["n_pairs"] == 1                       # only seed 2 is in both groups
    assert np.isnan(p["ci_low"]) and np.isnan(p["p_wilcoxon"]) and p["better"] == ""
    assert "no test" in p["note"]


def test_machine_figures_are_reported_but_never_ranked_or_compared(small_sweep):
    res = small_sweep
    machine = res.summary[res.summary["metric"].isin(sweep.MACHINE_METRICS)]
    assert len(machine) and set(machine["kind"]) == {"machine"} and set(machine["direction"]) == {""}
    assert not set(sweep.MACHINE_METRICS) & set(res.ranks.columns)
    assert not set(sweep.MACHINE_METRICS) & set(res.paired["metric"])
    order = list(summary_wide(res.summary, ("algo",))["metric"])
    assert order[-len(set(machine["metric"])):] == sorted(set(machine["metric"]), key=order.index)


def test_ci_is_scipys_bca_bootstrap():
    values = np.array([3.1, 2.7, 4.4, 3.9, 3.0, 5.2, 2.2])
    lo, hi = sweep.bootstrap_ci(values, sweep._rng(0, "g", "m"), 1000, 0.95)
    ref = stats.bootstrap((values,), np.mean, n_resamples=1000, method="BCa",
                          random_state=sweep._rng(0, "g", "m")).confidence_interval
    assert (lo, hi) == pytest.approx((ref.low, ref.high))
    assert lo < values.mean() < hi


@pytest.mark.slow
def test_parallel_analysis_gives_the_same_tables_and_reports_progress(sweep_dir):
    seen = []
    serial = analyze_sweep(sweep_dir, SweepOptions(n_boot=200), workers=1)
    parallel = analyze_sweep(sweep_dir, SweepOptions(n_boot=200), workers=2,
                             progress=lambda done, total: seen.append((done, total)))
    assert seen[-1] == (10, 10) and [d for d, _ in seen] == list(range(1, 11))
    for name in ("runs", "summary", "paired", "ranks"):
        pd.testing.assert_frame_equal(getattr(serial, name), getattr(parallel, name))
