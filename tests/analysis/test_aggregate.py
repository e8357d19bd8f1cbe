"""Aggregates across tasks (rliable methodology): scores within a task, IQM with a stratified bootstrap,
probability of improvement, performance profiles; and their place in a real sweep's analysis."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from swarmbox.analysis import aggregate
from swarmbox.analysis.cli import analyze_main
from tests.conftest import run_config


def frame(rows: list[tuple[str, str, float, str]]) -> pd.DataFrame:
    return pd.DataFrame(rows, columns=["algo", "task", "m", "status"])


HAND = frame([("A", "t1", 10, "ok"), ("B", "t1", 20, "ok"), ("A", "t2", 30, "ok"), ("B", "t2", 15, "ok"),
              ("A", "t3", 5, "ok"), ("B", "t3", 5, "ok"), ("A", "t4", 7, "ok"), ("B", "t4", 1, "failed")])


def test_scores_within_a_task_and_a_failure_scores_zero():
    s = aggregate.scores(HAND, "m", "lower", "algo", "task")
    got = dict(zip(zip(s["algorithm"], s["task"], strict=True), s["score"], strict=True))
    assert got == {("A", "t1"): 1.0, ("B", "t1"): 0.0, ("A", "t2"): 0.0, ("B", "t2"): 1.0,
                   ("A", "t3"): 1.0, ("B", "t3"): 1.0, ("A", "t4"): 1.0, ("B", "t4"): 0.0}
    higher = aggregate.scores(HAND, "m", "higher", "algo", "task")
    assert higher.loc[(higher["algorithm"] == "A") & (higher["task"] == "t1"), "score"].item() == 0.0


def test_iqm_probability_of_improvement_and_profiles_by_hand():
    iqm, improve, profiles = aggregate.aggregate(HAND, {"m": "lower"}, "algo", "task", n_boot=500)
    a = iqm.set_index("algorithm").loc["A"]
    assert a["iqm"] == pytest.approx(1.0)               # [1, 0, 1, 1]: the middle half is [1, 1]
    assert iqm.set_index("algorithm").loc["B", "iqm"] == pytest.approx(0.5)   # [0, 1, 1, 0]
    assert a["n_tasks"] == 4 and a["resampled"] == "tasks"
    p = improve.set_index(["x", "y"])["p_improvement"]
    assert p[("A", "B")] == pytest.approx((1 + 0 + 0.5 + 1) / 4) and p[("B", "A")] == pytest.approx(1.5 / 4)
    share = profiles[(profiles["algorithm"] == "B") & np.isclose(profiles["tau"], 0.5)]["share_above"].item()
    assert share == 0.5


def test_the_bootstrap_keeps_every_task_and_is_seeded():
    """Two runs per task, equal within a task: resampling runs within tasks leaves the IQM unchanged."""
    rows = [(a, t, v, "ok") for a, base in (("A", 0.0), ("B", 1.0))
            for t, v in (("t1", 10 + base), ("t2", 20 - base)) for _ in (0, 1)]
    iqm, _, _ = aggregate.aggregate(frame(rows), {"m": "lower"}, "algo", "task", n_boot=300)
    a = iqm.set_index("algorithm").loc["A"]
    assert a["resampled"] == "runs within tasks" and a["ci_low"] == a["ci_high"] == pytest.approx(a["iqm"])
    values = np.random.default_rng(0).random((3, 8))      # three algorithms: scores between 0 and 1
    spread = frame([(a, f"t{k}", values[i, k], "ok") for i, a in enumerate("ABC") for k in range(8)])
    again, _, _ = aggregate.aggregate(spread, {"m": "lower"}, "algo", "task", seed=1, n_boot=300)
    other, _, _ = aggregate.aggregate(spread, {"m": "lower"}, "algo", "task", seed=2, n_boot=300)
    first, _, _ = aggregate.aggregate(spread, {"m": "lower"}, "algo", "task", seed=1, n_boot=300)
    pd.testing.assert_frame_equal(again, first)
    assert not again[["ci_low", "ci_high"]].equals(other[["ci_low", "ci_high"]])


def test_only_tasks_every_algorithm_ran_are_aggregated():
    extra = pd.concat([HAND, frame([("A", "t5", 1.0, "ok")])])
    iqm, _, _ = aggregate.aggregate(extra, {"m": "lower"}, "algo", "task", n_boot=50)
    assert set(iqm["n_tasks"]) == {4}


@pytest.fixture(scope="module")
def two_levels(tmp_path_factory) -> Path:
    """hover_s 1 vs 2 (the compared factor) on two networks (the tasks), two seeds each."""
    root = tmp_path_factory.mktemp("agg") / "sweep"
    jobs = [(h, loss, s) for h in (1, 2) for loss in ("0", "0.2") for s in (0, 1)]
    for job, (hover, loss, seed) in enumerate(jobs):
        run_config(root / str(job), ["algo=hover", f"algo.params.hover_s={hover}",
                                     f"network.loss_prob={loss}", f"seed={seed}"])
    return root


def test_a_sweep_over_tasks_writes_the_aggregates(two_levels):
    code = analyze_main([str(two_levels), "--group-by", "algo.params.hover_s", "--workers", "1",
                         "--n-boot", "200"])
    assert code == 0
    tables = two_levels / "tables"
    iqm = pd.read_csv(tables / "aggregate_iqm.csv", dtype={"algorithm": str})
    iqm = iqm.set_index(["metric", "algorithm"])
    assert iqm.loc[("mission_duration_s", "1"), "iqm"] == pytest.approx(1.0, abs=0.05)   # 1 s less hovering
    assert iqm.loc[("mission_duration_s", "1"), "n_tasks"] == 2
    assert iqm.loc[("mission_duration_s", "1"), "resampled"] == "runs within tasks"
    improve = pd.read_csv(tables / "aggregate_improvement.csv", dtype={"x": str, "y": str})
    p = improve.set_index(["metric", "x", "y"])["p_improvement"]
    assert p[("mission_duration_s", "1", "2")] == 1.0
    assert (two_levels / "figures" / "aggregate.png").is_file() and (tables / "aggregate_iqm.md").is_file()


def test_each_seed_as_a_dataset_and_an_unknown_task_key(two_levels, tmp_path, capsys):
    """The RQ4 presets' ``tasks: [seed]``: a task per seed."""
    out = tmp_path / "by_seed"
    assert analyze_main([str(two_levels), "--group-by", "algo.params.hover_s", "--tasks", "seed",
                         "--out", str(out), "--no-figures", "--workers", "1", "--n-boot", "50"]) == 0
    iqm = pd.read_csv(out / "tables" / "aggregate_iqm.csv")
    assert set(iqm["n_tasks"]) == {2} and set(iqm["n_runs"]) == {4}     # seeds 0, 1; two networks each
    assert analyze_main([str(two_levels), "--tasks", "dataset", "--out", str(tmp_path / "x"),
                         "--workers", "1"]) == 2
    assert "dataset" in capsys.readouterr().err and not (tmp_path / "x").exists()
