"""A fast tuning study on the command line (two flocking gains, two objectives, short flights): its
trials table, the objective computed in the worker against ``swarmbox analyze``, the held-out
re-evaluation, the best-parameters YAML, Optuna's figures, and a resume that continues the same study."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys

import optuna
import pandas as pd
import pytest
import yaml

from tests.conftest import ROOT
from tests.tune.helpers import trials, tune

METRICS = ("flock_order_mean", "flock_min_separation_m_min")


@pytest.fixture(scope="module")
def study(tmp_path_factory):
    root = tmp_path_factory.mktemp("study") / "sweep"
    proc = tune(root)
    assert proc.returncode == 0, proc.stderr[-3000:]
    return root


def objectives(root, pattern):
    return {p.parent.name: json.loads(p.read_text()) for p in sorted(root.glob(f"{pattern}/objective.json"))}


def test_each_trial_row_has_its_parameters_scores_and_run_counts(study):
    table = trials(study)
    assert list(table["trial"]) == [0, 1] and set(table["state"]) == {"ok"}
    assert table["algo.params.p_rep"].between(0.2, 2).all()
    assert table["algo.params.C_frict"].between(0.01, 0.5).all()
    assert (table["runs_attempted"] == 2).all() and (table["runs_ok"] == 2).all()
    assert (table[["runs_aborted", "runs_failed", "runs_interrupted", "runs_missing"]] == 0).all().all()
    runs = objectives(study, "trial*")
    for row in table.itertuples():
        for m in METRICS:
            seeds = [runs[f"trial{row.trial:04d}_seed{s}"]["values"][m] for s in (0, 1)]
            assert getattr(row, f"{m}_score") == pytest.approx(sum(seeds) / 2, rel=1e-12)
            assert getattr(row, f"{m}_mean") == pytest.approx(sum(seeds) / 2, rel=1e-12)
            assert getattr(row, f"{m}_n") == 2


def test_the_objective_computed_in_the_worker_is_what_swarmbox_analyze_says(study, tmp_path):
    run = study / "trial0001_seed1"
    copy = tmp_path / "run"
    shutil.copytree(run, copy)   # analyzed as a lone flight, away from the study
    proc = subprocess.run([sys.executable, "-m", "swarmbox.analyze", str(copy), "--no-figures"], cwd=ROOT,
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr[-2000:]
    table = pd.read_csv(copy / "tables" / "metrics.csv").set_index("metric")["value"]
    worker = json.loads((run / "objective.json").read_text())
    assert worker["status"] == "ok" and worker["seed"] == 1
    for m in METRICS:
        assert worker["values"][m] == pytest.approx(table[m], rel=1e-12, abs=0)


def test_the_best_is_flown_again_on_held_out_seeds_disjoint_from_the_tuning_seeds(study):
    seeds = {name: json.loads((study / name / "run.json").read_text())["seed"]
             for name in objectives(study, "*_seed*")}
    tuning = {s for name, s in seeds.items() if name.startswith("trial")}
    held = {s for name, s in seeds.items() if name.startswith("heldout")}
    assert tuning == {0, 1} and held == {1000, 1001, 1002, 1003, 1004} and not tuning & held
    best = json.loads((study / "tune" / "best.json").read_text())
    heldout = pd.read_csv(study / "tune" / "heldout.csv").set_index("seeds")
    assert set(heldout["trial"]) == {best["trial"]}
    row = heldout.loc["held-out"]
    assert row["runs_attempted"] == 5 and row["runs_ok"] == 5 and row["seed_range"] == "1000..1004"
    runs = objectives(study, f"heldout{best['trial']:04d}_seed*")
    for m in METRICS:
        values = [r["values"][m] for r in runs.values()]
        assert row[f"{m}_mean"] == pytest.approx(sum(values) / 5, rel=1e-12) and row[f"{m}_n"] == 5
        assert row[f"{m}_ci_low"] <= row[f"{m}_mean"] <= row[f"{m}_ci_high"]   # a CI over 5 seeds


def test_the_best_is_the_feasible_pareto_trial_best_in_the_first_objective(study):
    table = trials(study)
    best = json.loads((study / "tune" / "best.json").read_text())
    front = optuna.load_study(study_name="tune", storage=f"sqlite:///{study / 'study.db'}").best_trials
    assert best["trial"] in {t.number for t in front}
    assert best["trial"] == max(front, key=lambda t: t.values[0]).number
    row = table.set_index("trial").loc[best["trial"]]
    assert best["params"] == {"algo.params.p_rep": row["algo.params.p_rep"],
                              "algo.params.C_frict": row["algo.params.C_frict"]}


def test_the_best_algo_yaml_is_ready_to_use(study, tmp_path):
    best = json.loads((study / "tune" / "best.json").read_text())
    (tmp_path / "conf" / "algo").mkdir(parents=True)
    shutil.copy(study / "tune" / "best_algo.yaml", tmp_path / "conf" / "algo" / "tuned.yaml")
    proc = subprocess.run([sys.executable, "-m", "swarmbox.run", "--config-dir", str(tmp_path / "conf"),
                           "algo=tuned", "--cfg", "job"], cwd=ROOT, capture_output=True, text=True,
                          timeout=120)
    assert proc.returncode == 0, proc.stderr[-2000:]
    cfg = yaml.safe_load(proc.stdout)
    assert cfg["mission"]["name"] == "flocking" and cfg["algo"]["params"]["flock_s"] == 5
    assert cfg["algo"]["params"]["p_rep"] == best["params"]["algo.params.p_rep"]
    assert cfg["algo"]["params"]["C_frict"] == best["params"]["algo.params.C_frict"]


def test_optunas_figures_are_written_per_objective(study):
    for m in METRICS:
        for name in ("history", "importance", "contour"):
            path = study / "tune" / "figures" / f"{name}_{m}.png"
            assert path.stat().st_size > 5_000, path


def test_a_resumed_study_continues_and_flies_again_only_what_had_not_finished(study, tmp_path):
    root = tmp_path / "sweep"
    shutil.copytree(study, root)
    before = trials(root)
    flown = {p.parent.name: p.stat().st_mtime_ns for p in root.glob("*/run.json")}
    stored = optuna.load_study(study_name="tune", storage=f"sqlite:///{root / 'study.db'}")
    orphan = stored.ask({"algo.params.p_rep": optuna.distributions.FloatDistribution(0.2, 2),
                         "algo.params.C_frict": optuna.distributions.FloatDistribution(0.01, 0.5, log=True)})
    proc = tune(root, "run.resume=true", "hydra.sweeper.n_trials=3")   # a study killed mid-trial
    assert proc.returncode == 0, proc.stderr[-3000:]
    after = trials(root)
    assert len(after) == 4
    pd.testing.assert_frame_equal(after.iloc[:2], before, check_dtype=False)   # earlier trials unchanged
    assert after.loc[2, "state"] == "stopped" and after.loc[3, "resumes"] == orphan.number == 2
    assert after.loc[3, "algo.params.p_rep"] == orphan.params["algo.params.p_rep"]
    again = {p.parent.name: p.stat().st_mtime_ns for p in root.glob("*/run.json") if p.parent.name in flown}
    assert again == flown                                       # nothing that had finished is flown again
    assert {p.parent.name for p in root.glob("trial0003_seed*/run.json")} == {"trial0003_seed0",
                                                                             "trial0003_seed1"}


def test_a_study_in_a_directory_that_holds_one_needs_resume(study):
    mtime = (study / "study.db").stat().st_mtime_ns
    proc = tune(study)
    assert proc.returncode == 2
    assert proc.stderr.strip().splitlines()[-1] == (
        f"error: {study / 'study.db'} holds a study: continue it with run.resume=true, or choose another "
        "hydra.sweep.dir (nothing was run or written)")
    assert (study / "study.db").stat().st_mtime_ns == mtime


def test_a_resume_with_another_objective_is_refused_and_changes_nothing(study):
    before = {p.name: p.stat().st_mtime_ns for p in study.iterdir()}
    proc = tune(study, "run.resume=true", "hydra.sweeper.objective=flock_order_mean")
    assert proc.returncode == 2
    assert proc.stderr.strip().splitlines()[-1] == (
        f"error: {study / 'study.db'}: study 'tune' was started with another directions, objective "
        "(directions=['higher', 'higher'], objective=['flock_order_mean', 'flock_min_separation_m_min']); "
        "resume it with the same settings or choose another hydra.sweep.dir (nothing was run or written)")
    assert {p.name: p.stat().st_mtime_ns for p in study.iterdir()} == before
