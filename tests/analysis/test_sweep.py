"""Sweep tables: runs, summary with bootstrap CIs, paired comparison, ranks, bad runs skipped."""

from __future__ import annotations

import json
import shutil

import numpy as np
import pandas as pd
import pytest

from swarmbox.analysis import sweep
from swarmbox.analysis.sweep import SweepOptions, analyze_sweep
from tests.analysis.synthetic import Scenario, build_run

OPTS = SweepOptions(n_boot=500)


@pytest.fixture(scope="module")
def result(sweep_dir):
    return analyze_sweep(sweep_dir, OPTS)


def test_one_row_per_run_with_choices_from_the_manifest(result):
    runs = result.runs
    assert len(runs) == 10 and result.problems.empty
    assert sorted(runs["algo"].unique()) == ["fast", "slow"]
    assert {"mission", "topology", "backend", "network", "fault"} <= set(result.choice_columns)
    assert sorted(runs.loc[runs["algo"] == "fast", "seed"]) == [0, 1, 2, 3, 4]


def test_summary_mean_and_ci(result):
    s = result.summary.set_index(["algo", "metric"])
    fast = s.loc[("fast", "mission_duration_s")]
    durations = [(300 + 8 * seed - 40) * 0.025 for seed in range(5)]   # 6.5 ... 7.3 s
    assert fast["n"] == 5
    assert fast["mean"] == pytest.approx(np.mean(durations))
    assert fast["median"] == pytest.approx(np.median(durations))
    assert fast["std"] == pytest.approx(np.std(durations, ddof=1))
    assert min(durations) <= fast["ci_low"] < fast["mean"] < fast["ci_high"] <= max(durations)
    assert s.loc[("slow", "mission_duration_s"), "mean"] == pytest.approx(np.mean(durations) + 1.0)
    assert fast["direction"] == "lower" and fast["unit"] == "s"


def test_constant_metric_has_a_degenerate_ci(result):
    row = result.summary.set_index(["algo", "metric"]).loc[("fast", "min_separation_m")]
    assert row["ci_low"] == pytest.approx(row["mean"]) == pytest.approx(row["ci_high"])


def test_paired_comparison(result):
    p = result.paired.set_index("metric")
    assert set(result.paired["a"]) == {"fast"} and set(result.paired["b"]) == {"slow"}
    row = p.loc["mission_duration_s"]
    assert row["n_pairs"] == 5
    assert row["diff_mean"] == pytest.approx(1.0)
    assert row["ci_low"] == pytest.approx(1.0) and row["ci_high"] == pytest.approx(1.0)
    assert row["p_wilcoxon"] == pytest.approx(1 / 16)   # 5 pairs, all positive: exact 2 / 2^5
    assert row["better"] == "fast"
    assert p.loc["busy_s_mean", "diff_mean"] == pytest.approx(1.0)
    assert p.loc["min_separation_m", "p_wilcoxon"] == 1.0 and p.loc["min_separation_m", "better"] == ""


def test_ranks(result):
    r = result.ranks.set_index("group")
    assert r.loc["fast", "mission_duration_s"] == 1 and r.loc["slow", "mission_duration_s"] == 2
    assert r.loc["fast", "min_separation_m"] == 1 == r.loc["slow", "min_separation_m"]   # tie


def test_rerun_gives_identical_numbers(sweep_dir, result):
    again = analyze_sweep(sweep_dir, OPTS)
    pd.testing.assert_frame_equal(result.summary, again.summary)
    pd.testing.assert_frame_equal(result.paired, again.paired)


def test_bootstrap_is_seeded_per_cell():
    values = np.array([1.0, 2.0, 4.0, 8.0, 16.0, 32.0, 3.3, 5.7, 0.1, 11.0])
    a = sweep.bootstrap_ci(values, sweep._rng(0, "g", "m"), 1000, 0.95)
    b = sweep.bootstrap_ci(values, sweep._rng(0, "g", "m"), 1000, 0.95)
    c = sweep.bootstrap_ci(values, sweep._rng(1, "g", "m"), 1000, 0.95)
    assert a == b and a != c
    assert np.isnan(sweep.bootstrap_ci(values[:1], sweep._rng(0, "g"), 10, 0.95)).all()


def test_bad_runs_are_reported_skipped_and_counted(sweep_dir, tmp_path):
    root = tmp_path / "sweep"
    shutil.copytree(sweep_dir, root)
    fast = json.loads((root / "0" / "run.json").read_text())       # algo fast, seed 0
    failed = root / "failed"
    failed.mkdir()
    (failed / "run.json").write_text(json.dumps(fast | {"status": "failed", "reason": "boom", "seed": 7}))
    build_run(root / "partial", Scenario(skip_files=("drone_2/state",), seed=8,
                                         choices={"algo": "fast", "mission": "synthetic"}))
    (root / "garbled").mkdir()
    (root / "garbled" / "run.json").write_text("{")
    (root / "killed" / "logs" / "drone_0").mkdir(parents=True)           # killed: no run.json
    (root / "killed" / "logs" / "drone_0" / "state.parquet.partial").write_bytes(b"PAR1")
    build_run(root / "aborted", Scenario(ticks=400, seed=9, choices={"algo": "fast", "mission": "synthetic"}))
    (root / "aborted" / "run.json").write_text(json.dumps(fast | {"status": "aborted", "seed": 9}))
    res = analyze_sweep(root, OPTS)
    skipped = res.problems[res.problems["severity"] == "skipped"]
    assert sorted(skipped["run"]) == ["failed", "garbled", "killed", "partial"]
    assert "no run.json" in skipped.set_index("run").loc["killed", "problem"]
    assert "boom" in skipped.set_index("run").loc["failed", "problem"]
    assert len(res.runs) == 13 and (res.runs["status"] == "aborted").sum() == 1   # garbled, killed: no row
    s = res.summary.set_index(["algo", "metric"])
    counts = {m: s.loc[("fast", m), "mean"] for m in ("runs_attempted", "runs_ok", "runs_aborted",
                                                      "runs_failed", "runs_interrupted", "success_rate")}
    assert counts == {"runs_attempted": 8, "runs_ok": 6, "runs_aborted": 1, "runs_failed": 1,
                      "runs_interrupted": 0, "success_rate": 6 / 8}
    duration = s.loc[("fast", "mission_duration_s")]
    assert duration["n"] == 5 and duration["n_runs"] == 8   # aborted, failed, partial: no value
    assert "3 of 8 runs without a value" in duration["note"]
    assert s.loc[("slow", "success_rate"), "mean"] == 1.0


def test_group_by_unknown_column_is_refused(sweep_dir):
    with pytest.raises(sweep.SweepInputError, match="planner"):
        analyze_sweep(sweep_dir, SweepOptions(group_by=("planner",), n_boot=10))


def test_an_abort_never_enters_a_mission_window_metric(sweep_dir, tmp_path):
    """Even when aborted runs are asked for, their shortened mission window is not a fast mission."""
    root = tmp_path / "sweep"
    shutil.copytree(sweep_dir, root)
    fast = json.loads((root / "0" / "run.json").read_text())
    short = Scenario(ticks=400, seed=9, ground_stages={1: 0, 2: 20, 3: 40, 4: 60, 5: 390},
                     choices={"algo": "fast", "mission": "synthetic"})     # EXECUTION 0.5 s: an early end
    build_run(root / "aborted", short)
    (root / "aborted" / "run.json").write_text(json.dumps(fast | {"status": "aborted", "seed": 9}))
    s = analyze_sweep(root, SweepOptions(statuses=("ok", "aborted"), n_boot=50)).summary
    s = s.set_index(["algo", "metric"])
    assert s.loc[("fast", "mission_duration_s"), "n"] == 5          # the aborted run is not in it
    assert s.loc[("fast", "mission_duration_s"), "mean"] == pytest.approx(np.mean(
        [(300 + 8 * seed - 40) * 0.025 for seed in range(5)]))
    assert s.loc[("fast", "min_separation_m"), "n"] == 6            # asked for: other metrics include it
    assert s.loc[("fast", "runs_aborted"), "mean"] == 1 and s.loc[("fast", "success_rate"), "mean"] == 5 / 6
