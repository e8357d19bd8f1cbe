"""``hydra/launcher=swarmbox``: the joblib launcher's jobs, records and exit codes, with the sweep's
context written once per launch (``swarmbox/run/launcher.py``).

Real subprocesses of the command line, each launcher on the same input (the context file goes to a
``TMPDIR`` of the test's own, so that its removal can be checked); then, in this process, Hydra's
conformance suites for launchers and the context file's life in a worker.
"""

import json
import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import pyarrow as pa
import pyarrow.parquet as pq
import pytest
from hydra.core.singleton import Singleton
from hydra.test_utils.launcher_common_tests import BatchedSweeperTestSuite, LauncherTestSuite
from hydra.types import HydraContext
from hydra.version import VersionBase
from omegaconf import OmegaConf
from omegaconf.basecontainer import BaseContainer
from packaging.version import Version

from hydra_plugins.swarmbox_launcher.launcher import SwarmBoxLauncher
from swarmbox.run import launcher
from swarmbox.run.launcher import CONTEXT_PREFIX, LaunchContext, load_context, write_context
from tests.conftest import ROOT

HOVER = ("algo=hover", "mission=hover")
SLOW = ("algo.drone._target_=tests.run.algos.SlowDrone", "+algo.params.delay_s=0.005")   # ~5 s a run
CONTEXT_LINE = re.compile(rf"Job context: (\S*{CONTEXT_PREFIX}\S*) \(")


def command(tmp_path: Path, name: str, *args: str) -> tuple[list[str], dict[str, str]]:
    """The sweep command with ``hydra/launcher=name`` (2 workers) and its environment (own TMPDIR)."""
    tmp = tmp_path / f"tmp-{name}"
    tmp.mkdir()
    cmd = [sys.executable, "-m", "swarmbox.run", "-m", f"hydra/launcher={name}", "hydra.launcher.n_jobs=2",
           *HOVER, *args, f"hydra.sweep.dir={tmp_path / name}", "~hydra.callbacks.analyze",
           "hydra.sweep.subdir=${hydra.job.num}"]   # job dirs by number: these tests compare job order
    return cmd, {**os.environ, "TMPDIR": str(tmp)}


def sweep(tmp_path: Path, name: str, *args: str) -> subprocess.CompletedProcess:
    cmd, env = command(tmp_path, name, *args)
    return subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, timeout=300, env=env)


def manifests(sweep_dir: Path) -> dict[str, dict]:
    return {p.parent.name: json.loads(p.read_text()) for p in sweep_dir.glob("*/run.json")}


def bitwise(table: pa.Table) -> pa.Table:
    """Float columns as their bit patterns: ``Table.equals`` holds NaN unequal to itself, and the
    logs hold NaN for values not set (a hover's yaw setpoint, GNSS columns without a sample)."""
    ints = {8: pa.int64(), 4: pa.int32()}
    columns = [c.combine_chunks().view(ints[c.type.byte_width]) if pa.types.is_floating(c.type) else c
               for c in table.columns]
    return pa.table(columns, names=table.column_names)


def assert_context_file_removed(proc_output: str, tmp_dir: Path) -> None:
    """The launch named its context file in our TMPDIR, and nothing of it is left there."""
    written = CONTEXT_LINE.findall(proc_output)
    assert written and all(Path(p).parent == tmp_dir for p in written), proc_output[-2000:]
    assert not any(Path(p).exists() for p in written)
    assert not list(tmp_dir.glob(f"{CONTEXT_PREFIX}*"))


@pytest.mark.slow
def test_same_runs_and_identical_logs_as_the_joblib_launcher(tmp_path):
    procs = {name: sweep(tmp_path, name, "seed=range(4)") for name in ("joblib", "swarmbox")}
    for name, proc in procs.items():
        assert proc.returncode == 0, f"{name}: {proc.stderr[-3000:]}"
    ours, theirs = manifests(tmp_path / "swarmbox"), manifests(tmp_path / "joblib")
    assert sorted(ours) == ["0", "1", "2", "3"]
    for job, m in ours.items():
        assert m["status"] == theirs[job]["status"] == "ok"
        assert (m["seed"], m["choices"], m["overrides"]) == (
            theirs[job]["seed"], theirs[job]["choices"], theirs[job]["overrides"])
        assert m["seed"] == int(job)                      # same job order
    logs = sorted(p.relative_to(tmp_path / "joblib") for p in (tmp_path / "joblib").rglob("*.parquet"))
    assert len(logs) > 40
    assert logs == sorted(p.relative_to(tmp_path / "swarmbox")
                          for p in (tmp_path / "swarmbox").rglob("*.parquet"))
    for rel in logs:
        a, b = pq.read_table(tmp_path / "joblib" / rel), pq.read_table(tmp_path / "swarmbox" / rel)
        assert bitwise(a).equals(bitwise(b)), rel
    assert "SwarmBox launcher: Joblib.Parallel(n_jobs=2," in procs["swarmbox"].stdout
    assert_context_file_removed(procs["swarmbox"].stdout, tmp_path / "tmp-swarmbox")


@pytest.mark.slow
def test_a_failing_run_is_reported_the_others_finish_and_the_exit_code_is_joblibs(tmp_path):
    crash = ("algo.drone._target_=tests.run.algos.CrashingDrone,swarmbox.algorithms.hover.HoverDrone",
             "seed=0,1")                                  # jobs 0, 1 crash; 2, 3 fly after them
    procs = {name: sweep(tmp_path, name, *crash) for name in ("joblib", "swarmbox")}
    expected = {"0": "failed", "1": "failed", "2": "ok", "3": "ok"}
    for name in procs:
        assert {job: m["status"] for job, m in manifests(tmp_path / name).items()} == expected, name
    ours = procs["swarmbox"]
    assert ours.returncode == procs["joblib"].returncode == 1
    assert ours.stderr.count("deliberate failure") >= 2
    assert "4 runs (2 failed, 2 ok)" in ours.stdout
    assert_context_file_removed(ours.stdout, tmp_path / "tmp-swarmbox")


def interrupt_mid_sweep(tmp_path: Path, name: str) -> tuple[int, str]:
    """Ctrl-C on a terminal (SIGINT to the whole process group) while jobs 2 and 3 fly (~5 s runs)."""
    cmd, env = command(tmp_path, name, "seed=range(6)", *SLOW)
    proc = subprocess.Popen(cmd, cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            env=env, start_new_session=True)
    runs = tmp_path / name
    deadline = time.monotonic() + 120
    while not all((runs / j / "config.yaml").exists() for j in ("2", "3")) and proc.poll() is None:
        assert time.monotonic() < deadline
        time.sleep(0.02)
    time.sleep(0.5)
    os.killpg(proc.pid, signal.SIGINT)
    out, err = proc.communicate(timeout=60)
    return proc.returncode, out + err


@pytest.mark.slow
def test_ctrl_c_stops_the_sweep_cleanly_where_joblib_breaks_off(tmp_path):
    """Both keep the finished runs, record the flying ones as interrupted and start nothing more.
    joblib's workers see a bare KeyboardInterrupt and the sweep breaks off with a traceback; the
    swarmbox launcher's workers handle the signal as a lone process does, so the flying runs finish
    their files, the sweep writes its summary and exits 130."""
    results = {name: interrupt_mid_sweep(tmp_path, name) for name in ("joblib", "swarmbox")}
    assert results["joblib"][0] != 0
    code, output = results["swarmbox"]
    assert code == 130 and "Traceback" not in output, output[-3000:]
    summary = json.loads((tmp_path / "swarmbox" / "sweep.json").read_text())
    assert summary["interrupted_by"] == "SIGINT" and summary["counts"] == {"interrupted": 2, "ok": 2}
    for name in results:
        statuses = {job: m["status"] for job, m in manifests(tmp_path / name).items()}
        assert {statuses.pop("0"), statuses.pop("1")} == {"ok"}, name
        assert statuses and set(statuses) <= {"2", "3"} and set(statuses.values()) == {"interrupted"}, name
        assert not (tmp_path / name / "4").exists()
    assert_context_file_removed(results["swarmbox"][1], tmp_path / "tmp-swarmbox")


# In-process: Hydra's conformance suites for launchers (as the joblib plugin runs them), the context
# file and a worker's cache of it.

@pytest.fixture
def hydra_compat_defaults(hydra_restore_singletons):
    """Hydra's suites expect its default version_base (a job changes into its directory); other tests
    in this process leave 1.3 in Hydra's singletons, which the launcher hands to its workers."""
    VersionBase.instance().setbase(Version("1.1"))


@pytest.mark.usefixtures("hydra_compat_defaults")
@pytest.mark.parametrize("launcher_name, overrides", [("swarmbox", [])])
class TestHydraLauncherSuite(LauncherTestSuite):
    """Jobs, overrides, configs and return values as Hydra expects of any launcher."""


@pytest.mark.usefixtures("hydra_compat_defaults")
@pytest.mark.parametrize("launcher_name, overrides", [("swarmbox", ["hydra.sweeper.max_batch_size=2"])])
class TestHydraBatchedSweep(BatchedSweeperTestSuite):
    """Three launches in one sweep: a context file each, read anew by the reused workers."""



def task(cfg):
    return cfg


@pytest.fixture
def hydra_globals(monkeypatch):
    """Whatever loading a context installs (Hydra's singletons, OmegaConf's resolvers), undone after."""
    monkeypatch.setattr(Singleton, "_instances", dict(Singleton._instances))
    monkeypatch.setattr(BaseContainer, "_resolvers", dict(BaseContainer._resolvers))
    monkeypatch.setattr(launcher, "_loaded", {})


def make_context(value: int) -> LaunchContext:
    return LaunchContext(HydraContext(config_loader=None, callbacks=None), OmegaConf.create({"value": value}),
                         task, Singleton.get_state())


def test_a_worker_reads_the_context_file_once_and_only_the_current_one(tmp_path, monkeypatch, hydra_globals):
    monkeypatch.setattr("tempfile.tempdir", str(tmp_path))
    first = write_context(make_context(1))
    assert first.parent == tmp_path and first.name.startswith(CONTEXT_PREFIX)
    assert first.stat().st_mode & 0o777 == 0o600          # pickles are code: this user's only
    context = load_context(str(first))
    assert context.config.value == 1 and context.task_function is task
    first.unlink()
    assert load_context(str(first)) is context             # the next jobs of the launch: no read
    second = write_context(make_context(2))
    assert load_context(str(second)).config.value == 2      # a new launch, a reused worker
    with pytest.raises(FileNotFoundError):
        load_context(str(first))                            # the previous launch is not kept


def test_the_context_file_is_removed_when_the_launch_fails(tmp_path, monkeypatch, hydra_globals):
    monkeypatch.setattr("tempfile.tempdir", str(tmp_path))
    failing = SwarmBoxLauncher(n_jobs=0)                     # Parallel refuses it once the file exists
    config = OmegaConf.create({"hydra": {"hydra_logging": {"version": 1, "root": None}, "verbose": False,
                                         "sweep": {"dir": str(tmp_path / "sweep")}}})
    failing.setup(hydra_context=HydraContext(config_loader=None, callbacks=None), task_function=task,
                  config=config)
    with pytest.raises(ValueError, match="n_jobs"):
        launcher.launch(failing, [["seed=0"]], initial_job_idx=0)
    assert not list(tmp_path.glob(f"{CONTEXT_PREFIX}*"))


def test_the_config_becomes_parallel_arguments_with_numbers_as_numbers_and_loky_always():
    settings = {"n_jobs": 2, "backend": "threading", "pre_dispatch": "8", "batch_size": "auto",
                "max_nbytes": "1M", "timeout": None}
    assert launcher.parallel_settings(settings) == {"n_jobs": 2, "backend": "loky", "pre_dispatch": 8,
                                           "batch_size": "auto", "max_nbytes": "1M", "timeout": None}
    assert settings["backend"] == "threading"              # the launcher's own config is left alone
    assert launcher.parallel_settings({"pre_dispatch": "2*n_jobs", "batch_size": "4"}) == {
        "pre_dispatch": "2*n_jobs", "batch_size": 4, "backend": "loky"}
