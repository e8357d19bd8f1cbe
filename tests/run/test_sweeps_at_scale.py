"""Sweeps as a user runs them: progress with ETA, resume, and the Ray and Submitit launchers.

Real subprocesses of the command line; Ray starts a local cluster (127.0.0.1, no dashboard) and
Submitit runs its local executor, so the remote-launcher code paths run on any machine.
"""

import json
import os
import secrets
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import pandas as pd
import pytest

from tests.conftest import ROOT, sweep_job

HOVER = ("algo=hover", "algo.params.hover_s=1", "mission.max_sim_time_s=60")


def swarmbox_run(*args, cwd=ROOT, timeout=600, env=None):
    env = {**os.environ, "PYTHONPATH": str(ROOT), "RAY_USAGE_STATS_ENABLED": "0", **(env or {})}
    return subprocess.run([sys.executable, "-m", "swarmbox.cli", "run", *args], cwd=cwd, capture_output=True,
                          text=True, timeout=timeout, env=env)


def statuses(sweep_dir):
    """seed -> status of every job (jobs are named by their overrides)."""
    runs = [json.loads(p.read_text()) for p in sweep_dir.glob("*/run.json")]
    return {str(m["seed"]): m["status"] for m in runs}


@pytest.mark.slow
def test_sweep_shows_progress_and_resume_flies_only_the_rest(tmp_path):
    sweep = tmp_path / "study"
    args = ("-m", *HOVER, "seed=range(4)", f"hydra.sweep.dir={sweep}", "~hydra.callbacks.analyze")
    first = swarmbox_run(*args)
    assert first.returncode == 0, first.stderr[-3000:]
    assert "4/4 runs done, 0 failed" in first.stderr and "ETA" in first.stderr
    jobs = {s: sweep_job(sweep, s) for s in range(4)}
    kept = {d: (jobs[d] / "run.json").read_bytes() for d in (0, 1)}
    shutil.rmtree(jobs[2])                                      # never flown (interrupted before it)
    (jobs[3] / "run.json").write_text(json.dumps({"status": "failed", "overrides": []}))  # cut short
    again = swarmbox_run(*args, "run.resume=true")
    assert again.returncode == 0, again.stderr[-3000:]
    assert again.stdout.count("SKIP") == 2 and again.stdout.count("OK ") == 2
    assert "2/2 runs done, 0 failed, 2 skipped" in again.stderr
    assert {d: (jobs[d] / "run.json").read_bytes() for d in kept} == kept
    assert statuses(sweep) == {"0": "ok", "1": "ok", "2": "ok", "3": "ok"}
    assert (jobs[3] / "run.failed-1.json").is_file() and sweep_job(sweep, 2) == jobs[2]   # same name again


def comparable(table: pd.DataFrame) -> pd.DataFrame:
    """A summary without the machine figures (wall time, real-time factor differ run to run)."""
    return table[table["kind"] != "machine"].reset_index(drop=True)


def ray_env(temp_root: Path) -> dict[str, str]:
    """A throwaway local Ray cluster that leaves nothing behind (docs/scale-out.md, Ray): a token of
    its own in the environment (no ~/.ray/auth_token written, no token warning) and its session
    directories under ``temp_root`` (short: Ray's socket paths must fit in 107 bytes)."""
    return {"RAY_AUTH_MODE": "token", "RAY_AUTH_TOKEN": secrets.token_hex(32), "RAY_TMPDIR": str(temp_root)}


@pytest.mark.slow
def test_ray_launcher_gives_the_same_tables_as_joblib(tmp_path):
    pytest.importorskip("hydra_plugins.hydra_ray_launcher", reason="needs pip install -e '.[ray]'")
    common = ("-m", *HOVER, "seed=range(4)")
    joblib = swarmbox_run(*common, "hydra/launcher=joblib", "hydra.launcher.n_jobs=2",
                          f"hydra.sweep.dir={tmp_path / 'joblib'}")
    assert joblib.returncode == 0, joblib.stderr[-3000:]
    token_file = Path.home() / ".ray" / "auth_token"
    token_before = token_file.stat().st_mtime_ns if token_file.exists() else None
    temp_root = Path(tempfile.mkdtemp(prefix="sbray-"))
    try:
        ray = swarmbox_run(*common, "hydra/launcher=ray", "+hydra.launcher.ray.init.num_cpus=2",
                           "+hydra.launcher.ray.init.include_dashboard=false",
                           f"hydra.sweep.dir={tmp_path / 'ray'}", env=ray_env(temp_root))
        assert ray.returncode == 0, ray.stderr[-3000:]
        sessions = list(temp_root.glob("ray/session_*"))
    finally:
        shutil.rmtree(temp_root, ignore_errors=True)
    output = ray.stderr + ray.stdout
    assert "Ray Launcher is launching 4 jobs" in output
    assert sessions                                          # Ray kept its session files there
    assert "auth_token" not in output and "Token authentication is" not in output
    assert (token_file.stat().st_mtime_ns if token_file.exists() else None) == token_before
    a = pd.read_csv(tmp_path / "joblib" / "tables" / "summary.csv")
    b = pd.read_csv(tmp_path / "ray" / "tables" / "summary.csv")
    assert len(comparable(a)) > 10
    pd.testing.assert_frame_equal(comparable(a), comparable(b))


@pytest.mark.slow
def test_submitit_local_executor_flies_the_sweep(tmp_path):
    pytest.importorskip("hydra_plugins.hydra_submitit_launcher", reason="needs pip install -e '.[slurm]'")
    proc = swarmbox_run("-m", *HOVER, "seed=0,1", "hydra/launcher=submitit_local",
                        "hydra.launcher.timeout_min=10", f"hydra.sweep.dir={tmp_path / 'sub'}",
                        "~hydra.callbacks.analyze")
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert statuses(tmp_path / "sub") == {"0": "ok", "1": "ok"}
    assert (tmp_path / "sub" / ".submitit").is_dir()             # the jobs went through submitit
