"""Studies at their edges: a trial whose runs all abort, determinism, two invocations on one study,
the Ray launcher (a local cluster) and the sim_px4 backend."""

from __future__ import annotations

import json
import math
import os
import secrets
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import optuna
import pandas as pd
import pytest

from tests.conftest import ROOT
from tests.tune.helpers import STUDY, trials, tune

SMALL = ["hydra.sweeper.n_trials=2", "hydra.sweeper.seeds=2", "hydra.sweeper.heldout_seeds=1"]


def test_a_trial_whose_runs_all_abort_scores_the_penalty_and_shows_as_such(tmp_path):
    root = tmp_path / "sweep"
    proc = tune(root, *SMALL, "run.timeouts_s.EXECUTION=1")       # every flight aborts: EXECUTION overruns
    assert proc.returncode == 0, proc.stderr[-3000:]               # aborted runs are a truthful record
    table = trials(root)
    assert list(table["state"]) == ["penalized", "penalized"]
    assert (table["runs_aborted"] == 2).all() and (table["runs_ok"] == 0).all()
    assert (table["success_rate"] == 0).all()
    assert (table["flock_order_mean_score"] == -math.inf).all()    # higher is better: the worst value
    assert table["flock_order_mean_n"].eq(0).all() and table["flock_order_mean_mean"].isna().all()
    study = optuna.load_study(study_name="tune", storage=f"sqlite:///{root / 'study.db'}")
    assert [t.constraints for t in study.trials] == [{"runs_not_ok": 2.0}] * 2
    assert study.best_trials == []                                 # a penalized trial is never an answer
    assert "no feasible trial" in proc.stdout
    assert not (root / "tune" / "best.json").exists() and not list(root.glob("heldout*"))


@pytest.mark.slow
def test_same_seeds_and_sampler_seed_give_the_same_trials_table(tmp_path):
    for name in ("a", "b"):
        proc = tune(tmp_path / name, *SMALL)
        assert proc.returncode == 0, proc.stderr[-3000:]
    pd.testing.assert_frame_equal(trials(tmp_path / "a"), trials(tmp_path / "b"))
    for table in ("heldout.csv", "best_algo.yaml"):
        a, b = ((tmp_path / n / "tune" / table).read_text() for n in ("a", "b"))
        assert a.replace(str(tmp_path / "a"), "") == b.replace(str(tmp_path / "b"), "")


@pytest.mark.slow
def test_a_second_invocation_on_a_running_study_is_refused_and_the_study_is_intact(tmp_path):
    root = tmp_path / "sweep"
    first = subprocess.Popen([sys.executable, "-m", "swarmbox.run", "-m", *STUDY, f"hydra.sweep.dir={root}",
                              "hydra.sweeper.n_trials=3"], cwd=ROOT, stdout=subprocess.PIPE,
                             stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + 300
        while not list(root.glob("trial0000_seed*/run.json")) and time.monotonic() < deadline:
            time.sleep(0.2)
        second = tune(root, "hydra.sweeper.n_trials=3", "run.resume=true")
        out, err = first.communicate(timeout=600)
    finally:
        first.kill()
    assert first.returncode == 0, err[-3000:]
    assert second.returncode == 2
    assert "is being written by another sweep" in second.stderr
    table = trials(root)
    assert list(table["trial"]) == [0, 1, 2] and set(table["state"]) == {"ok"}
    assert (table["runs_ok"] == 2).all()


def extras_python(plugin: str, extra: str) -> str:
    """The interpreter of an environment with a launcher extra: this one, or SWARMBOX_EXTRAS_PYTHON."""
    python = os.environ.get("SWARMBOX_EXTRAS_PYTHON", sys.executable)
    found = subprocess.run([python, "-c", f"import hydra_plugins.{plugin}, optuna"], capture_output=True,
                           check=False)
    if found.returncode:
        pytest.skip(f"needs pip install -e '.[test,{extra}]' (or SWARMBOX_EXTRAS_PYTHON naming such a venv)")
    return python


#: the study without its launcher settings
BASE = [o for o in STUDY if not o.startswith(("hydra/launcher=", "hydra.launcher."))]


@pytest.mark.slow
def test_the_ray_launcher_on_a_local_cluster_gives_the_same_study(tmp_path):
    python = extras_python("hydra_ray_launcher", "ray")
    joblib = tune(tmp_path / "joblib", *SMALL)
    assert joblib.returncode == 0, joblib.stderr[-3000:]
    temp_root = Path(tempfile.mkdtemp(prefix="sbray-"))
    env = {**os.environ, "PYTHONPATH": str(ROOT), "RAY_USAGE_STATS_ENABLED": "0", "RAY_AUTH_MODE": "token",
           "RAY_AUTH_TOKEN": secrets.token_hex(32), "RAY_TMPDIR": str(temp_root)}
    try:
        ray = subprocess.run([python, "-m", "swarmbox.run", "-m", *BASE, "hydra/launcher=ray",
                              "+hydra.launcher.ray.init.num_cpus=2",
                              "+hydra.launcher.ray.init.include_dashboard=false",
                              f"hydra.sweep.dir={tmp_path / 'ray'}", *SMALL],
                             cwd=ROOT, capture_output=True, text=True, timeout=900, env=env)
    finally:
        shutil.rmtree(temp_root, ignore_errors=True)
    assert ray.returncode == 0, ray.stderr[-3000:]
    assert "Ray Launcher is launching" in ray.stdout + ray.stderr
    pd.testing.assert_frame_equal(trials(tmp_path / "joblib"), trials(tmp_path / "ray"))
    assert (tmp_path / "ray" / "tune" / "best.json").is_file()


@pytest.mark.slow
def test_the_submitit_local_executor_gives_the_same_study(tmp_path):
    python = extras_python("hydra_submitit_launcher", "slurm")
    joblib = tune(tmp_path / "joblib", *SMALL)
    assert joblib.returncode == 0, joblib.stderr[-3000:]
    sub = tune(tmp_path / "sub", *SMALL, "hydra/launcher=submitit_local", "hydra.launcher.timeout_min=10",
               base=BASE, python=python)
    assert sub.returncode == 0, sub.stderr[-3000:]
    assert (tmp_path / "sub" / ".submitit").is_dir()                  # the runs went through submitit
    pd.testing.assert_frame_equal(trials(tmp_path / "joblib"), trials(tmp_path / "sub"))


@pytest.mark.slow
def test_trials_asked_in_batches_fly_together_and_the_study_stops_at_n_trials(tmp_path):
    proc = tune(tmp_path / "sweep", "hydra.sweeper.n_trials=3", "hydra.sweeper.batch_trials=2",
                "hydra.sweeper.sampler=random", "hydra.sweeper.seeds=2", "hydra.sweeper.heldout_seeds=1")
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert "is launching 4 jobs" in proc.stdout and "is launching 2 jobs" in proc.stdout   # 2 trials, then 1
    table = trials(tmp_path / "sweep")
    assert list(table["trial"]) == [0, 1, 2] and set(table["state"]) == {"ok"}


@pytest.mark.slow
def test_a_study_on_the_sim_px4_backend(tmp_path):
    root = tmp_path / "sweep"
    proc = tune(root, "backend=sim_px4", "hydra.sweeper.n_trials=1", "hydra.sweeper.seeds=2",
                "hydra.sweeper.heldout_seeds=1")
    assert proc.returncode == 0, proc.stderr[-3000:]
    runs = [json.loads(p.read_text()) for p in root.glob("*/run.json")]
    assert len(runs) == 3 and {r["choices"]["backend"] for r in runs} == {"sim_px4"}
    table = trials(root)
    assert list(table["state"]) == ["ok"] and table.loc[0, "runs_ok"] == 2
    assert json.loads((root / "tune" / "best.json").read_text())["trial"] == 0


@pytest.mark.slow
def test_a_study_stopped_by_ctrl_c_resumes_and_flies_no_finished_run_again(tmp_path):
    root = tmp_path / "sweep"
    proc = subprocess.Popen([sys.executable, "-m", "swarmbox.run", "-m", *STUDY, f"hydra.sweep.dir={root}",
                             "hydra.sweeper.n_trials=3"], cwd=ROOT, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, start_new_session=True)
    try:
        deadline = time.monotonic() + 300
        while not (root / "trial0001_seed0").exists() and time.monotonic() < deadline:
            time.sleep(0.1)
        os.killpg(proc.pid, signal.SIGINT)            # Ctrl-C: the process group, as a terminal does
        proc.communicate(timeout=300)
    finally:
        proc.kill()
    assert proc.returncode == 130
    stored = optuna.load_study(study_name="tune", storage=f"sqlite:///{root / 'study.db'}")
    finished = {t.number for t in stored.trials if t.state.name == "COMPLETE"}
    flying = {t.number for t in stored.trials if t.state.name == "RUNNING"}
    assert 0 in finished and flying                   # stopped mid-trial
    kept = {p.parent.name: p.stat().st_mtime_ns for p in root.glob("*/run.json")
            if json.loads(p.read_text())["status"] == "ok"}
    assert not (root / "tune").exists()               # no results from a study that did not finish
    again = tune(root, "hydra.sweeper.n_trials=3", "run.resume=true")
    assert again.returncode == 0, again.stderr[-3000:]
    table = trials(root).set_index("trial")
    assert (table["state"] == "ok").sum() == 3
    assert set(table.index[table["state"] == "stopped"]) == flying
    assert set(table["resumes"].dropna().astype(int)) == flying           # their parameters asked again
    now = {p.parent.name: p.stat().st_mtime_ns for p in root.glob("*/run.json") if p.parent.name in kept}
    assert now == kept                              # no finished run flown again
