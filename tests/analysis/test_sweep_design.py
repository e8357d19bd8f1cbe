"""Real sweeps (short hover flights): groups from every swept override, pairs only within a configuration,
run counts in every summary, and a gate that sees lost runs."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pandas as pd
import pytest

from swarmbox.analysis.cli import analyze_main, compare_main
from swarmbox.analysis.identity import comparable_pairs, design
from swarmbox.analysis.outputs import write_sweep
from swarmbox.analysis.sweep import SweepInputError, SweepOptions, analyze_sweep
from tests.conftest import run_config

HOVER = ("algo=hover", "algo.params.hover_s=1")
SEEDS = range(10)
OPTS = SweepOptions(n_boot=200)


def _crash(swarm) -> None:
    def boom(_):
        raise RuntimeError("deliberate failure")

    swarm.schedule(1.0, boom)


def fly(root: Path, levels=("0", "0.2"), seeds=SEEDS, crash=lambda level, seed: False) -> Path:
    """``-m network.loss_prob=<levels> 'seed=range(..)'``, one directory per job (names carry nothing)."""
    for job, (level, seed) in enumerate((lv, s) for lv in levels for s in seeds):
        overrides = [*HOVER, f"network.loss_prob={level}", f"seed={seed}"]
        run_config(root / str(job), overrides, _crash if crash(level, seed) else None)
    return root


@pytest.fixture(scope="module")
def loss_sweep(tmp_path_factory) -> Path:
    return fly(tmp_path_factory.mktemp("loss") / "sweep")


@pytest.fixture(scope="module")
def loss_result(loss_sweep):
    result = analyze_sweep(loss_sweep, OPTS, workers=1)
    write_sweep(result, loss_sweep, with_figures=False)
    return result


def test_a_swept_plain_value_is_the_compared_factor_with_ten_pairs(loss_result):
    res = loss_result
    assert res.group_by == ("network.loss_prob",) and res.design.strata == ()
    counts = res.summary[res.summary["metric"] == "runs_attempted"].set_index("network.loss_prob")["mean"]
    assert counts.to_dict() == {"0": 10, "0.2": 10}            # two groups, not one pooled mean
    loss = res.paired.set_index("metric").loc["loss_ratio"]
    assert (loss["a"], loss["b"], loss["n_pairs"]) == ("0", "0.2", 10)   # not 10 x 10 = 100
    assert set(res.paired["n_pairs"]) == {10}
    assert 0.1 < loss["ci_low"] <= loss["diff_mean"] <= loss["ci_high"] < 0.3
    assert loss["better"] == "0"


def test_every_group_carries_its_run_counts(loss_result):
    s = loss_result.summary.set_index(["network.loss_prob", "metric"])
    for level in ("0", "0.2"):
        assert s.loc[(level, "runs_ok"), "mean"] == 10 and s.loc[(level, "success_rate"), "mean"] == 1.0
        assert s.loc[(level, "runs_failed"), "mean"] == 0 == s.loc[(level, "runs_aborted"), "mean"]
        assert s.loc[(level, "success_rate"), "direction"] == "higher"
        assert s.loc[(level, "mission_duration_s"), "n_runs"] == 10


def test_nineteen_failed_runs_against_a_full_baseline_are_a_regression(loss_sweep, loss_result, tmp_path,
                                                                       capsys):
    """Acceptance: 19 of 20 runs fail; the gate names the run counts and the success rate."""
    current = fly(tmp_path / "current", crash=lambda level, seed: (level, seed) != ("0", 0))
    assert analyze_main([str(current), "--no-figures", "--n-boot", "50", "--workers", "1"]) == 0
    capsys.readouterr()
    code = compare_main([str(loss_sweep / "tables" / "summary.csv"), str(current / "tables" / "summary.csv")])
    out = capsys.readouterr().out
    assert code == 1
    verdict = out.strip().splitlines()[-1]
    assert verdict.startswith("REGRESSION: runs_ok, runs_failed, success_rate"), verdict
    summary = pd.read_csv(current / "tables" / "summary.csv", dtype={"network.loss_prob": str})
    rate = summary.set_index(["network.loss_prob", "metric"])["mean"]
    assert rate[("0", "success_rate")] == pytest.approx(0.1) and rate[("0.2", "success_rate")] == 0.0


def test_same_configuration_and_seed_twice_is_refused(loss_sweep, tmp_path, capsys):
    root = tmp_path / "dup"
    for job in ("0", "1", "10"):     # jobs 0 and 10: seed 0 at loss 0 and at loss 0.2
        shutil.copytree(loss_sweep / job, root / job)
    shutil.copytree(loss_sweep / "0", root / "again")
    with pytest.raises(SweepInputError, match="same configuration and seed"):
        analyze_sweep(root, OPTS, workers=1)
    assert analyze_main([str(root), "--no-figures", "--workers", "1"]) == 2
    assert not (root / "tables").exists()
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "again" in err[0] and err[0].startswith("error:")   # before any analysis


def test_group_by_any_override_key(loss_result):
    runs, identity = loss_result.runs, loss_result.choice_columns
    d = design(runs, identity, ("algo",))
    assert d.keys == ("algo", "network.loss_prob")             # the swept key stays a stratum
    pairs, warnings = comparable_pairs(runs, d)
    assert pairs == [] and warnings == []                      # one algorithm: nothing to pair
    assert design(runs, identity, ("network.loss_prob",)).keys == ("network.loss_prob",)
    with pytest.raises(SweepInputError, match="network.loss"):
        design(runs, identity, ("network.loss",))


def test_runs_differing_in_the_mission_are_not_ranked_against_each_other(tmp_path, capsys):
    """The README's ``-m algo=hover,formation``: each algorithm flies its own mission."""
    root = tmp_path / "two"
    formation = ("algo=formation", "algo.params.start_s=3", "algo.params.complete_after_s=5")
    for job, (overrides, seed) in enumerate((o, s) for o in (HOVER, formation) for s in (0, 1)):
        assert run_config(root / str(job), [*overrides, f"seed={seed}"])["status"] == "ok"
    assert analyze_main([str(root), "--no-figures", "--workers", "1", "--n-boot", "50"]) == 0
    out = capsys.readouterr().out
    assert "not comparable: algo formation and hover also differ in " in out
    assert "mission (formation: formation; hover: hover)" in out
    ranks = pd.read_csv(root / "tables" / "ranks.csv")
    assert list(ranks.columns) == ["note"] and "not comparable" in ranks["note"].iloc[0]
    paired = pd.read_csv(root / "tables" / "paired.csv")
    assert len(paired) == 1 and paired["n_pairs"].iloc[0] == 0
    assert "mission (formation: formation; hover: hover)" in paired["note"][0]
    summary = pd.read_csv(root / "tables" / "summary.csv")
    assert {"algo", "mission"} <= set(summary.columns)
    assert json.loads((root / "0" / "run.json").read_text())["choices"]["mission"] == "hover"
