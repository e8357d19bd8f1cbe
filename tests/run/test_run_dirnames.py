"""Run directories are named by what differs between runs, never carry a secret, and stay usable paths."""

import json
import os
import subprocess
import sys

import pytest

from swarmbox.run.dirname import EMPTY, MAX_CHARS, override_dirname
from tests.conftest import ROOT

HOVER = ["algo=hover", "mission=hover", "algo.params.hover_s=1"]


def swarmbox_run(*args, cwd, timeout=300):
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    return subprocess.run([sys.executable, "-m", "swarmbox.cli", "run", *args], cwd=cwd, capture_output=True,
                          text=True, timeout=timeout, env=env)


def test_name_is_the_sorted_overrides_as_hydra_joins_them():
    assert override_dirname(["seed=3", "fault=gps_drift", "+algo.params.x=1"]) == \
        "+algo.params.x=1,fault=gps_drift,seed=3"
    assert override_dirname([]) == EMPTY


@pytest.mark.parametrize("secret", ["run.net.key=s3cret", "backend.signing_key=s3cret", "+my.api_key=s3cret",
                                    "algo.params.KEY=s3cret", "~run.net.key"])
def test_secrets_never_reach_the_name(secret):
    assert override_dirname(["seed=1", secret]) == "seed=1"


def test_hydra_options_and_excluded_keys_are_left_out_but_seed_is_kept():
    name = override_dirname(["hydra.sweep.dir=x", "hydra/launcher=joblib", "run.resume=true", "seed=0",
                             "algo=hover"], exclude_keys=["run.resume"])
    assert name == "algo=hover,seed=0"


def test_names_are_filesystem_safe():
    name = override_dirname(["fault.targets=[2,3]", "mission.file=/tmp/a b/m.yaml", "x='q'", "y=a:b*c?"])
    assert name == "fault.targets=_2,3_,mission.file=_tmp_ab_m.yaml,x=_q_,y=a_b_c_"
    assert "/" not in name and "\\" not in name


def test_long_values_give_way_to_digests_so_the_short_ones_stay_readable():
    long = ["+algo.params.delay_s=0.002", "algo.drone._target_=tests.run.algos.SlowDrone" + "X" * 100,
            "algo.params.hover_s=1", "algo=hover", "mission=hover"]
    a, b = override_dirname([*long, "seed=2"]), override_dirname([*long, "seed=3"])
    assert len(a) <= MAX_CHARS and a.endswith(",mission=hover,seed=2") and b.endswith("seed=3")
    assert "algo.drone._target_=#" in a and "+algo.params.delay_s=0.002" in a


def test_long_names_are_bounded_and_stay_distinct():
    same = ", ".join(f"{i}: [{i}, 0]" for i in range(59))
    a = override_dirname([f"mission.initial_positions={{{same}, 59: [59, 0]}}"])
    b = override_dirname([f"mission.initial_positions={{{same}, 59: [59, 1]}}"])
    assert len(a) <= MAX_CHARS and len(b) <= MAX_CHARS and a != b
    many = [f"algo.params.p{i}=1" for i in range(40)]    # short values only: cut, ending in a digest
    c, d = override_dirname([*many, "seed=1"]), override_dirname([*many, "seed=2"])
    assert len(c) == len(d) == MAX_CHARS and c != d and c[:MAX_CHARS - 11] == d[:MAX_CHARS - 11]


@pytest.mark.slow
def test_three_fault_runs_get_three_names_without_the_key(tmp_path):
    for fault in ("gps_drift", "packet_loss", "latency"):
        proc = swarmbox_run(*HOVER, f"fault={fault}", "fault.targets=[1]", "seed=2", "run.net.key=topsecret",
                            cwd=tmp_path)
        assert proc.returncode == 0, proc.stderr[-2000:]
    runs = sorted((tmp_path / "results" / "runs").iterdir())
    names = [r.name.split("_", 2)[2] for r in runs]          # <date>_<time>_<overrides>
    assert sorted(names) == sorted(
        f"algo.params.hover_s=1,algo=hover,fault.targets=_1_,fault={f},mission=hover,seed=2"
        for f in ("gps_drift", "packet_loss", "latency"))
    assert all("topsecret" not in str(p) for p in tmp_path.rglob("*"))
    assert {json.loads((r / "run.json").read_text())["choices"]["fault"] for r in runs} == \
        {"gps_drift", "packet_loss", "latency"}


def test_sweep_jobs_are_named_by_their_overrides_and_resume_finds_them(tmp_path):
    sweep = tmp_path / "study"
    args = ["-m", *HOVER, "seed=0,1", f"hydra.sweep.dir={sweep}", "~hydra.callbacks.analyze"]
    first = swarmbox_run(*args, cwd=tmp_path)
    assert first.returncode == 0, first.stderr[-2000:]
    jobs = {p.parent.name: json.loads(p.read_text())["seed"] for p in sweep.glob("*/run.json")}
    assert jobs == {f"algo.params.hover_s=1,algo=hover,mission=hover,seed={s}": s for s in (0, 1)}
    again = swarmbox_run(*args, "run.resume=true", "run.progress=false", cwd=tmp_path)
    assert again.returncode == 0, again.stderr[-2000:]
    assert again.stdout.count("SKIP") == 2 and sorted(p.name for p in sweep.iterdir() if p.is_dir()) == \
        sorted(jobs)
