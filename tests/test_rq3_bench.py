"""The diagnosis benchmark's generator (experiments/rq3_faults/sweep.py) and its committed data.

The plan is a pure function of its seed counts; the committed rows are that plan's runs, with the
calibration seeds (which chose the tuned settings) apart from the report seeds (which every table
is measured on); a sweep resumes without flying a finished run again; a composed run has every
truth scored and a swarm-wide fault is scored against an alarm on any drone (real short runs).
"""

import importlib.util
import sys
from pathlib import Path

import pandas as pd
import pytest

ROOT = Path(__file__).resolve().parents[1]
HERE = ROOT / "experiments" / "rq3_faults"
BENCH = HERE / "bench"


def load(name: str):
    sys.path.insert(0, str(HERE))
    spec = importlib.util.spec_from_file_location(f"rq3_{name}", HERE / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.fixture(scope="module")
def sweep():
    return load("sweep")


def test_the_plan_is_deterministic_and_a_smaller_plan_is_part_of_it(sweep):
    plan = sweep.bench_plan()
    pd.testing.assert_frame_equal(plan, sweep.bench_plan())
    assert plan["run"].is_unique
    small = sweep.bench_plan({"single": 2, "composed": 1})
    # the same run name always has the same overrides (targets are drawn from the name)
    merged = small.merge(plan, on="run", suffixes=("_small", ""))
    assert len(merged) == len(small) and (merged["overrides_small"] == merged["overrides"]).all()


def test_calibration_and_report_seeds_are_disjoint_in_the_plan_and_in_the_committed_rows(sweep):
    plan = sweep.bench_plan()
    calib = set(plan.loc[plan["split"] == "calibration", "seed"])
    report = set(plan.loc[plan["split"] == "report", "seed"])
    assert calib == sweep.calibration_seeds() and calib.isdisjoint(report)
    rows = pd.read_csv(BENCH / "bench_runs.csv", usecols=["run", "seed", "split", "part"])
    assert set(rows.loc[rows["split"] == "calibration", "seed"]) <= calib
    assert set(rows.loc[rows["split"] == "report", "seed"]).isdisjoint(calib)
    # the committed rows are exactly the plan's runs, each on the side the plan put it
    sides = rows.drop_duplicates("run").merge(plan, on="run", suffixes=("", "_plan"))
    assert len(sides) == len(plan) == rows["run"].nunique()
    assert (sides["split"] == sides["split_plan"]).all() and (sides["seed"] == sides["seed_plan"]).all()


def test_a_sweep_scores_every_truth_and_resumes_without_flying_again(sweep, tmp_path):
    plan = sweep.bench_plan({"composed": 1, "swarm": 1})
    names = ["n9/ideal/composed/drift+latency/s1000", "n9/ideal/swarm/gps_noise_all/s1000"]
    mini = plan[plan["run"].isin(names)].reset_index(drop=True)
    leftover = tmp_path / names[1] / "logs"          # an interrupted run: logs, no run.json
    leftover.mkdir(parents=True)
    (leftover / "half.parquet").write_bytes(b"x")
    first = sweep.sweep(mini, tmp_path)
    assert [line.split()[0] for line in first] == ["flown", "flown"]
    assert not (leftover / "half.parquet").exists()
    stamps = {n: (tmp_path / n / "run.json").stat().st_mtime_ns for n in names}

    rows = sweep.collect(tmp_path)
    default = rows[(rows["detector"] == "swarmbox") & (rows["rule"] == "tukey")
                   & (rows["threshold_scale"] == 1)]
    composed = default[default["run"] == names[0]].sort_values("truth")
    targets = [int(t) for t in composed["target"]]
    assert list(composed["fault"]) == ["gps_drift", "latency"] and len(set(targets)) == 2
    assert composed["detected"].all() and composed["localized"].all()
    assert (composed["part"] == "composed").all() and (composed["status"] == "ok").all()
    [swarm] = default[default["run"] == names[1]].to_dict("records")
    assert swarm["fault"] == "gps_noise" and pd.isna(swarm["target"])       # one swarm-wide truth
    assert swarm["detected"] and swarm["first_drone"] in range(9)

    second = sweep.sweep(mini, tmp_path)
    assert [line.split()[0] for line in second] == ["kept", "kept"]
    assert {n: (tmp_path / n / "run.json").stat().st_mtime_ns for n in names} == stamps
