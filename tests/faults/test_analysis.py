"""Onset-agnostic diagnosis of short real runs with injected faults, scored against the truth."""

from __future__ import annotations

import shutil

import numpy as np
import pandas as pd
import pyarrow.parquet as pq
import pytest

from swarmbox.analysis import detection, scoring
from swarmbox.analysis import diagnosis as dg
from swarmbox.analysis.load import load_run
from swarmbox.analysis.unify import unify
from tests.faults.helpers import HOVER, node_dirs

WINDOW = ("fault.onset_s=10", "fault.duration_s=20", "fault.targets=[2]", "network.latency_ms=1",
          "network.jitter_ms=1")
DEFAULT = [dg.DiagnosisOptions()]


def graded(run_dir) -> pd.DataFrame:
    return detection.evaluate_run(run_dir, DEFAULT).set_index("detector")


def unified(run_dir):
    run = load_run(run_dir)
    unify(run)
    return run


def blind_diagnosis(run_dir):
    """What the analyzer says from the logs alone: its alarms (the fault events are never read)."""
    return dg.scan(dg.drone_series(unified(run_dir)))


@pytest.mark.slow
def test_drift_swarmbox_finds_the_target_before_the_estimator_baseline(run):
    _, d = run(*HOVER, "fault=gps_drift", "fault.rate_m_s=3", *WINDOW)
    rows = graded(d)
    sb, base = rows.loc["swarmbox"], rows.loc["baseline"]
    assert sb["detected"] and sb["localized"] and sb["metric"] == "disc_n_m" and sb["false_alarms"] == 0
    assert 0.0 < sb["t_f_s"] < 2.0 and 1.5 <= sb["tau_d"] < 3.0
    assert base["detected"] and sb["t_f_s"] < base["t_f_s"] < 10.0 and sb["tau_d"] < base["tau_d"]
    first = dg.finding(blind_diagnosis(d))
    assert first["drone"] == 2 and first["metric"] == "disc_n_m"


def _shift_clock(src, dst, node: int, offset_s: float):
    """Copy a run and move one node's clock by ``offset_s``: its own time stamps, and the sender's
    time every message it sent carries."""
    shutil.copytree(src, dst)
    for name in node_dirs(dst):
        for path in (dst / "logs" / name).glob("*.parquet"):
            frame = pq.read_table(path)
            df = frame.to_pandas()
            if name == f"drone_{node}":
                df["t_s"] = df["t_s"] + offset_s
            if "t_sent_s" in df and "src" in df:
                df["t_sent_s"] = df["t_sent_s"] + np.where(df["src"] == node, offset_s, 0.0)
            pq.write_table(frame.from_pandas(df, schema=frame.schema, preserve_index=False), path)
    return dst


@pytest.mark.slow
def test_drift_diagnosis_survives_shifting_a_node_clock(run, tmp_path):
    """+-3 us and +-200 ms on the faulty drone's log clock, clock estimation on: same drone, t_f,
    tau_d and Sigma_a."""
    _, d = run(*HOVER, "fault=gps_drift", "fault.rate_m_s=2", *WINDOW)
    ref = graded(d).loc["swarmbox"]
    assert ref["detected"] and ref["localized"]
    keys = ["first_alarm_drone", "first_alarm_metric", "t_f_s", "tau_d", "sigma_a"]
    for i, offset_s in enumerate((3e-6, -3e-6, 0.2, -0.2)):
        got = graded(_shift_clock(d, tmp_path / f"shift{i}", 2, offset_s)).loc["swarmbox"]
        for key in keys:
            assert got[key] == pytest.approx(ref[key], abs=1e-9), (offset_s, key)


@pytest.mark.slow
def test_latency_and_loss_are_found_and_recovered(run):
    _, d = run(*HOVER, "fault=[latency,packet_loss]", "fault.latency.latency_ms=15",
               "fault.packet_loss.loss_prob=0.4", *WINDOW)
    alarms = blind_diagnosis(d)
    assert set(alarms[alarms["drone"] == 2]["metric"]) >= {"latency_ms", "loss_ratio"}
    assert set(alarms["drone"]) == {2}
    truths = scoring.ground_truth(unified(d).tables["events"])
    assert [t.name for t in truths] == ["latency", "packet_loss"] and all(t.target == 2 for t in truths)
    lat = alarms[alarms["metric"] == "latency_ms"].iloc[0]
    assert lat["value"] == pytest.approx(16.5, abs=1.0)               # 15 ms + the base 1-2 ms
    assert 0.0 < lat["t_u"] - truths[0].onset_u <= 0.15              # 4 ticks to confirm
    loss = alarms[alarms["metric"] == "loss_ratio"].iloc[0]
    assert 0.0 < loss["t_u"] - truths[1].onset_u < 1.0               # a sliding window, not 2.5 s
    assert loss["value"] >= 0.05


def test_a_healthy_hover_raises_no_alarm(run, tmp_path):
    _, d = run(*HOVER, "algo.params.hover_s=8")
    rows = graded(d)
    assert rows.loc["swarmbox", "alarms"] == 0 and rows.loc["swarmbox", "false_alarms"] == 0
    assert rows.loc["swarmbox", "fault"] == "none" and rows.loc["swarmbox", "healthy_drone_h"] > 0
    # the report's false-alarm table carries the exact Poisson bound: 0 alarms in h hours -> ln(40) / h
    detection.write_report(rows.reset_index(), tmp_path / "report")
    fa = pd.read_csv(tmp_path / "report" / "false_alarms.csv").set_index("detector")
    hours = rows.loc["swarmbox", "healthy_drone_h"]
    assert fa.loc["swarmbox", "fa_ci_high"] == pytest.approx(np.log(40) / hours)


@pytest.mark.slow
def test_every_injected_fault_of_a_composed_run_is_scored(run):
    """fault=[latency,packet_loss] on one drone: one row per truth and detector, both found; the run's
    healthy flight and false alarms counted once."""
    _, d = run(*HOVER, "fault=[latency,packet_loss]", "fault.latency.latency_ms=15",
               "fault.packet_loss.loss_prob=0.4", *WINDOW)
    rows = detection.evaluate_run(d, DEFAULT)
    sb = rows[rows["detector"] == "swarmbox"].set_index("fault")
    assert list(sb.index) == ["latency", "packet_loss"] and list(sb["truth"]) == [0, 1]
    assert sb["detected"].all() and sb["localized"].all() and (sb["target"] == 2).all()
    assert sb.loc["packet_loss", "healthy_drone_h"] == 0 and sb.loc["latency", "healthy_drone_h"] > 0
    fa = detection.false_alarm_rates(rows)
    assert list(fa["runs"]) == [1, 1]                                 # one run per detector, not two
