"""The command line, as a user runs it: real subprocesses."""

import json
import subprocess
import sys

import pytest

from tests.conftest import ROOT


def swarmbox_run(*args, cwd=ROOT, timeout=300):
    return subprocess.run([sys.executable, "-m", "swarmbox.run", *args], cwd=cwd, capture_output=True,
                          text=True, timeout=timeout)


@pytest.mark.slow
def test_sweep_runs_every_job_in_its_own_directory(tmp_path):
    proc = swarmbox_run("-m", "algo=hover,formation", "seed=range(3)", "mission=hover",
                        f"hydra.sweep.dir={tmp_path}")
    assert proc.returncode == 0, proc.stderr[-3000:]
    manifests = [json.loads(p.read_text()) for p in sorted(tmp_path.glob("*/run.json"))]
    assert len(manifests) == 6
    combos = {(m["choices"]["algo"], m["seed"]) for m in manifests}
    assert combos == {(a, s) for a in ("hover", "formation") for s in range(3)}
    assert "sweep" in proc.stdout and "6 runs" in proc.stdout
    assert (tmp_path / "tables").is_dir() and (tmp_path / "figures").is_dir()  # analysed at the end


def test_joblib_launcher_runs_jobs_in_parallel_processes(tmp_path):
    proc = swarmbox_run("-m", "hydra/launcher=joblib", "algo=hover", "mission=hover", "seed=0,1",
                        f"hydra.sweep.dir={tmp_path}", "~hydra.callbacks.analyze")
    assert proc.returncode == 0, proc.stderr[-3000:]
    statuses = [json.loads(p.read_text())["status"] for p in tmp_path.glob("*/run.json")]
    assert statuses == ["ok", "ok"]


def test_misspelt_key_fails_before_the_run_and_names_it(tmp_path):
    proc = swarmbox_run("run.tick_hzz=20", f"run.out_dir={tmp_path / 'x'}")
    assert proc.returncode != 0
    assert "tick_hzz" in proc.stderr
    assert not (tmp_path / "x").exists()


def test_failed_run_exits_non_zero_but_a_sweep_continues(tmp_path):
    bad = "algo.drone._target_=tests.run.algos.CrashingDrone"
    single = swarmbox_run("algo=hover", "mission=hover", bad, f"run.out_dir={tmp_path / 'single'}")
    assert single.returncode == 1 and "deliberate failure" in single.stderr
    assert json.loads((tmp_path / "single" / "run.json").read_text())["status"] == "failed"
    sweep = swarmbox_run("-m", "algo=hover", "mission=hover", "algo.drone._target_=tests.run.algos."
                         "CrashingDrone,swarmbox.algorithms.hover.HoverDrone",
                         f"hydra.sweep.dir={tmp_path / 'sw'}",
                         "~hydra.callbacks.analyze")
    statuses = sorted(json.loads(p.read_text())["status"] for p in (tmp_path / "sw").glob("*/run.json"))
    assert statuses == ["failed", "ok"]
    assert sweep.returncode == 1


def test_a_finished_run_is_never_overwritten(tmp_path):
    out = tmp_path / "r"
    first = swarmbox_run("algo=hover", "mission=hover", f"run.out_dir={out}")
    assert first.returncode == 0
    before = (out / "run.json").read_text()
    second = swarmbox_run("algo=hover", "mission=hover", "seed=9", f"run.out_dir={out}")
    assert second.returncode == 2 and "refusing to overwrite" in second.stderr
    assert (out / "run.json").read_text() == before
