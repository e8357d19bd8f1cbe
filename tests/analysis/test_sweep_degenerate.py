"""Degenerate sweeps give tables that say what is missing, and the exit codes of docs/errors.md."""

from __future__ import annotations

import logging
from pathlib import Path

import pandas as pd
import pytest
from omegaconf import OmegaConf

from swarmbox.analysis.callback import AnalyzeSweepCallback
from swarmbox.analysis.cli import EXIT_NO_OK_RUN, EXIT_OK, analyze_main
from tests.analysis.test_sweep_design import HOVER, _crash
from tests.conftest import run_config

ABORTS = ("algo=hover", "algo.params.hover_s=30", "fault=link_cut", "fault.targets=[-1]", "fault.onset_s=3")
#: a declared mission metric whose marker never comes: NaN in every run
NEVER = "algo.metrics=[{name: never_m, marker: never, field: x, unit: m, agg: [mean, count]}]"
TABLES = ("summary.csv", "summary.md", "summary_wide.md", "paired.md", "ranks.md", "runs.csv", "problems.csv")


def sweep(root: Path, overrides, seeds=(0, 1), prepare=None) -> Path:
    for job, seed in enumerate(seeds):
        run_config(root / str(job), [*overrides, f"seed={seed}"], prepare)
    return root


def analyze(root: Path) -> tuple[int, pd.DataFrame]:
    code = analyze_main([str(root), "--workers", "1", "--n-boot", "50"])
    assert all((root / "tables" / name).is_file() for name in TABLES)
    return code, pd.read_csv(root / "tables" / "summary.csv").set_index("metric")


def test_all_aborted_sweep_gives_run_counts_and_exit_4(tmp_path, capsys):
    root = sweep(tmp_path / "aborted", ABORTS)
    code, summary = analyze(root)
    captured = capsys.readouterr()
    assert code == EXIT_NO_OK_RUN and "Traceback" not in captured.out + captured.err
    assert "no run ended ok" in captured.err
    assert summary.loc["runs_aborted", "mean"] == 2 and summary.loc["success_rate", "mean"] == 0
    duration = summary.loc["mission_duration_s"]
    assert duration["n"] == 0 and duration["n_runs"] == 2 and "no values" in duration["note"]
    assert "nothing to rank" in (root / "tables" / "ranks.md").read_text()
    assert "nothing to pair" in (root / "tables" / "paired.md").read_text()


def test_end_of_sweep_analysis_of_an_all_aborted_sweep_writes_tables(tmp_path, caplog):
    root = sweep(tmp_path / "aborted", ABORTS, seeds=(3,))
    config = OmegaConf.create({"hydra": {"sweep": {"dir": str(root)}}})
    with caplog.at_level(logging.WARNING):
        AnalyzeSweepCallback(n_boot=20, figures=True, workers=1).on_multirun_end(config)
    assert "no run ended ok" in caplog.text and "Traceback" not in caplog.text
    assert "sweep analysis failed" not in caplog.text
    summary = pd.read_csv(root / "tables" / "summary.csv").set_index("metric")
    assert summary.loc["runs_aborted", "mean"] == 1


def test_all_failed_sweep_gives_run_counts_and_exit_4(tmp_path, capsys):
    root = sweep(tmp_path / "failed", HOVER, prepare=_crash)
    code, summary = analyze(root)
    assert code == EXIT_NO_OK_RUN
    assert summary.loc["runs_failed", "mean"] == 2 and summary.loc["success_rate", "mean"] == 0
    assert summary.loc["success_rate", "ci_high"] < 0.9        # Wilson: 0 of 2 is not "anything goes"
    assert "deliberate failure" in capsys.readouterr().out    # each skipped run and why


def test_one_run_and_a_metric_that_is_nan_everywhere(tmp_path, capsys):
    root = sweep(tmp_path / "one", [*HOVER, NEVER], seeds=(0,))
    code, summary = analyze(root)
    assert code == EXIT_OK
    duration = summary.loc["mission_duration_s"]
    assert duration["n"] == 1 and "no CI" in duration["note"]
    never = summary.loc["never_m_mean"]
    assert never["n"] == 0 and never["note"].startswith("no values") and never["unit"] == "m"
    assert summary.loc["never_m_count", "mean"] == 0 and pd.isna(summary.loc["never_m_count", "unit"])
    wide = (root / "tables" / "summary_wide.md").read_text()
    assert "| never_m_mean | no values (1 runs) |" in wide
    assert "(n=1, no CI)" in wide
    assert "one group per stratum (hover): nothing to pair" in (root / "tables" / "paired.md").read_text()


@pytest.mark.parametrize("n, has_ci", [(4, False), (5, True)])
def test_ci_from_five_values_exactly(tmp_path, n, has_ci):
    """The n < 5 rule at its boundary, on real runs: 4 runs get no CI, 5 do."""
    root = sweep(tmp_path / f"n{n}", HOVER, seeds=range(n))
    _, summary = analyze(root)
    row = summary.loc["distance_3d_m_mean"]
    assert row["n"] == n
    assert pd.notna(row["ci_low"]) == has_ci and pd.notna(row["ci_high"]) == has_ci
    assert ("no CI" in str(row["note"])) != has_ci
