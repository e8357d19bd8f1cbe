"""Run and sweep directories are claimed: one process writes into a directory at a time, and a
command never removes a directory it did not create."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path

from tests.conftest import sweep_job

ROOT = Path(__file__).resolve().parents[2]


def held(flag: Path) -> list[str]:
    """A run that stays in flight until ``flag`` exists (whatever the machine's load)."""
    return ["algo=hover", "mission=hover", "algo.drone._target_=tests.run.algos.WaitingDrone",
            f"+algo.params.flag={flag}", "algo.params.hover_s=1", "run.hook_timeout_s=null"]


def swarmbox(*args: str, wait: bool = True):
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    cmd = [sys.executable, "-m", "swarmbox.run", *args]
    if not wait:
        return subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
    return subprocess.run(cmd, capture_output=True, text=True, env=env, timeout=300)


def wait_for(path: Path | Callable[[], Path], proc: subprocess.Popen, timeout_s: float = 120.0) -> None:
    """Wait until ``path`` exists (a callable is asked again each time: a job dir named on creation)."""
    where = path if callable(path) else (lambda: path)
    deadline = time.monotonic() + timeout_s
    while not where().exists():
        assert proc.poll() is None, proc.communicate()
        assert time.monotonic() < deadline, f"{where()} never appeared"
        time.sleep(0.05)


def test_a_second_sweep_into_the_same_directory_is_refused_and_the_first_finishes_intact(tmp_path):
    sweep, flag = tmp_path / "study", tmp_path / "go"
    first = swarmbox("-m", *held(flag), "seed=0,1", f"hydra.sweep.dir={sweep}", "~hydra.callbacks.analyze",
                     wait=False)
    try:
        wait_for(lambda: sweep_job(sweep, 0) / "config.yaml", first)   # the first job flies
        second = swarmbox("-m", *held(flag), "seed=0,1", f"hydra.sweep.dir={sweep}",
                          "~hydra.callbacks.analyze")
        flag.touch()
        out, err = first.communicate(timeout=300)
    finally:
        first.kill()
    assert second.returncode == 2, second.stdout + second.stderr
    assert second.stderr.strip().count("\n") == 0 and not second.stdout.strip()
    assert f"{sweep} is being written by another sweep (pid {first.pid})" in second.stderr
    assert first.returncode == 0, out + err
    summary = json.loads((sweep / "sweep.json").read_text())
    assert summary["counts"] == {"ok": 2}
    for seed in (0, 1):
        manifest = json.loads((sweep_job(sweep, seed) / "run.json").read_text())
        assert manifest["status"] == "ok" and manifest["overrides"][-1] == f"seed={seed}"
    assert not (sweep / ".sweep.claim").exists() and not (sweep_job(sweep, 0) / ".claim").exists()


def test_a_second_run_into_a_run_directory_being_written_is_refused(tmp_path):
    run_dir, flag = tmp_path / "run", tmp_path / "go"
    first = swarmbox(*held(flag), f"run.out_dir={run_dir}", "run.progress=false", wait=False)
    try:
        wait_for(run_dir / "config.yaml", first)
        second = swarmbox(*held(flag), f"run.out_dir={run_dir}", "run.progress=false")
        flag.touch()
        first.communicate(timeout=300)
    finally:
        first.kill()
    assert second.returncode == 2
    assert second.stderr.strip() == (f"error: {run_dir} is being written by another run (pid {first.pid}); "
                                     "refusing to write into it")
    assert json.loads((run_dir / "run.json").read_text())["status"] == "ok"


def test_a_refused_command_keeps_the_users_empty_directory(tmp_path):
    mine = tmp_path / "mine"
    mine.mkdir()
    proc = swarmbox(f"hydra.run.dir={mine}", "network.loss_prob=1.5")
    assert proc.returncode == 2 and "network.loss_prob" in proc.stderr
    assert mine.is_dir() and not list(mine.iterdir())
    made = tmp_path / "made"
    proc = swarmbox(f"hydra.run.dir={made}", "network.loss_prob=1.5")
    assert proc.returncode == 2 and not made.exists()   # the one Hydra made for it is gone


def test_a_directory_that_cannot_be_made_is_refused_in_one_line(tmp_path):
    blocker = tmp_path / "file"
    blocker.write_text("")
    run = swarmbox(f"hydra.run.dir={blocker}/run")
    assert run.returncode == 2 and not run.stdout
    assert run.stderr == (f"error: run directory {blocker}/run (hydra.run.dir) cannot be written: "
                          "Not a directory (nothing was run or written)\n")
    sweep = swarmbox("-m", f"hydra.sweep.dir={blocker}/sweep", "seed=0,1")
    assert sweep.returncode == 2 and not sweep.stdout
    assert sweep.stderr == (f"error: sweep directory {blocker}/sweep (hydra.sweep.dir) cannot be written: "
                            "Not a directory (nothing was run or written)\n")
