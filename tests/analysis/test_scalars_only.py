"""The sweep's scalars-only analysis gives exactly the scalars of the full analysis (real runs)."""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from swarmbox.analysis.identity import run_identity
from swarmbox.analysis.load import load_run
from swarmbox.analysis.report import ANALYZED_COLUMNS, AnalysisOptions, RunAnalysis, analyze_run
from swarmbox.analysis.sweep import _analyze_one


@pytest.fixture(scope="module")
def fault_run(tmp_path_factory) -> Path:
    """A real formation run on wifi with extra latency and packet loss on drone 2 from t = 30 s."""
    from tests.conftest import run_config

    run_dir = tmp_path_factory.mktemp("real") / "fault"
    manifest = run_config(run_dir, ("algo=formation", "mission=formation", "fault=[latency,packet_loss]",
                                    "fault.targets=[2]", "network=wifi"))
    assert manifest["status"] == "ok", manifest["reason"]
    return run_dir


def _same(a: dict, b: dict) -> None:
    assert list(a) == list(b)
    for key in a:
        assert a[key] == b[key] or (math.isnan(a[key]) and math.isnan(b[key])), key


def _both(run_dir: Path) -> tuple[RunAnalysis, RunAnalysis]:
    """Full and scalars-only analyses of a run, checked equal, and the sweep's row checked against them."""
    full = analyze_run(load_run(run_dir, ANALYZED_COLUMNS))
    only = analyze_run(load_run(run_dir, ANALYZED_COLUMNS), AnalysisOptions(scalars_only=True))
    _same(full.scalars, only.scalars)
    assert full.directions == only.directions and full.problems == only.problems
    row = _analyze_one(run_dir, run_dir.parent, AnalysisOptions())["row"]
    _same({key: row[key] for key in full.scalars}, full.scalars)
    identity = run_identity(full.run.manifest)          # choices and the other overrides
    assert len(row) == len(full.scalars) + 3 + len(identity)   # run, status, seed
    assert {k: row[k] for k in identity} == identity
    return full, only


def test_without_a_fault(formation_run):
    full, only = _both(formation_run)
    assert full.onset is None and full.scalars["loss_ratio"] > 0
    assert len(full.links) and len(full.timeline) and "latency_ms_mean" in full.agents
    assert only.links.empty and only.timeline.empty and only.flags.empty and only.markers.empty
    assert list(only.agents.columns) == ["agent", "tx_bytes_per_s", "rx_bytes_per_s"]
    assert only.drones["tx_bytes_per_s"].equals(full.drones["tx_bytes_per_s"])


def test_with_a_fault(fault_run):
    full, only = _both(fault_run)
    assert full.onset is not None and full.onset.target == 2
    assert math.isfinite(full.scalars["anomaly_t_f_s"]) and "latency_ms_sigma_a" in full.scalars
    assert len(only.timeline) and len(only.flags) and only.diagnosis.equals(full.diagnosis)


def test_with_a_given_onset_on_a_synthetic_run(make_run):
    run_dir = make_run(drop_every={1: 3}, extra_delay_ticks={1: 4})
    opts = AnalysisOptions(fault_onset_u=3.0, fault_target=1)
    full = analyze_run(run_dir, opts)
    only = analyze_run(run_dir, AnalysisOptions(fault_onset_u=3.0, fault_target=1, scalars_only=True))
    _same(full.scalars, only.scalars)
    assert full.scalars["anomaly_is_target"] == 1.0
