"""The RQ3 diagnosis (swarmbox.analysis.faults) on short runs with known injected faults."""

import math

import pytest

from swarmbox.analysis import faults as rq3
from tests.faults.helpers import HOVER

WINDOW = ("fault.onset_s=10", "fault.duration_s=20", "fault.targets=[2]", "network.latency_ms=1",
          "network.jitter_ms=1")


def rows_of(run_dir):
    diag = rq3.diagnose_run(run_dir)
    assert diag is not None
    return diag, diag.rows.set_index("detector")


def test_drift_swarmbox_detects_the_target_before_the_estimator_baseline(run):
    _, d = run(*HOVER, "fault=gps_drift", "fault.rate_m_s=3", *WINDOW)
    diag, rows = rows_of(d)
    sb, base = rows.loc["swarmbox"], rows.loc["baseline"]
    assert sb["detected"] and sb["is_target"] and sb["metric"] == "disc_n_m"
    assert 0.0 < sb["t_f_s"] < 2.0 and 1.5 <= sb["tau_d"] < 3.0
    assert base["detected"] and sb["t_f_s"] < base["t_f_s"] < 10.0
    assert sb["tau_d"] < base["tau_d"] and sb["sigma_a"] < base["sigma_a"]
    assert diag.onset.t_u == 10.0 and diag.params["rate_m_s"] == 3.0


def test_slow_drift_is_followed_by_the_estimator_and_only_swarmbox_sees_it(run):
    _, d = run(*HOVER, "fault=gps_drift", "fault.rate_m_s=1", *WINDOW)
    _, rows = rows_of(d)
    assert rows.loc["swarmbox", "detected"] and rows.loc["swarmbox", "is_target"]
    assert not rows.loc["baseline", "detected"]


@pytest.mark.slow
def test_latency_is_recovered_and_attributed(run):
    _, d = run(*HOVER, "fault=latency", "fault.latency_ms=15", *WINDOW)
    _, rows = rows_of(d)
    sb = rows.loc["swarmbox"]
    assert sb["detected"] and sb["is_target"] and sb["t_f_s"] == pytest.approx(0.025)
    assert sb["tau_d"] == pytest.approx(16.5, abs=0.6)           # 15 ms + the base 1-2 ms
    assert sb["measured"] == pytest.approx(15.0, abs=0.2)
    assert math.isfinite(sb["sigma_a"]) and sb["sigma_a"] > 0   # 4 drones: the outlier lifts q3


@pytest.mark.slow
def test_loss_is_recovered_and_attributed(run):
    _, d = run(*HOVER, "fault=packet_loss", "fault.loss_prob=0.4", *WINDOW)
    _, rows = rows_of(d)
    sb = rows.loc["swarmbox"]
    assert sb["detected"] and sb["is_target"] and sb["t_f_s"] == pytest.approx(2.5)
    assert sb["tau_d"] == pytest.approx(0.4, abs=0.06) and sb["measured"] == pytest.approx(0.4, abs=0.03)
    assert sb["sigma_a"] > 0       # (inf with 9 drones: the quartiles then exclude the one outlier)


@pytest.mark.slow
def test_tables_and_figures_from_a_sweep_directory(run, tmp_path):
    for loss in (0.2, 0.4):
        run(*HOVER, "fault=packet_loss", f"fault.loss_prob={loss}", *WINDOW, name=f"sweep/loss{loss}")
    run(*HOVER, "fault=gps_drift", "fault.rate_m_s=3", *WINDOW, name="sweep/drift3")
    run(*HOVER, name="sweep/nofault")
    assert rq3.main([str(tmp_path / "sweep"), "--out", str(tmp_path / "out"), "--jobs", "1"]) == 0
    runs = rq3.diagnose_sweep([tmp_path / "sweep"])
    assert len(runs) == 4 and set(runs["fault"]) == {"packet_loss", "gps_drift"}
    summary = rq3.summarize(runs)
    t5 = rq3.table5(summary)
    assert list(t5.columns) == ["metric", "20 %", "40 %"]
    assert t5.set_index("metric").loc["faulty drone identified"].tolist() == ["1/1", "1/1"]
    t2 = rq3.table2(summary)
    assert t2["drift_m_s"].tolist() == [3.0] and t2["SwarmBox on target"].tolist() == ["1/1"]
    for name in ("rq3_runs.csv", "rq3_summary.md", "rq3_table2.md", "rq3_table5.md",
                 "figures/rq3_timeline_gps_drift.png", "figures/rq3_timeline_packet_loss.png"):
        assert (tmp_path / "out" / name).is_file(), name
