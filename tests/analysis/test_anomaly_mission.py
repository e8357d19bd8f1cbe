"""Outlier test, fault diagnosis (t_f, tau_d, Sigma_a) and marker-based mission metrics."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest

from swarmbox.analysis import anomaly, mission
from swarmbox.analysis.report import AnalysisOptions, analyze_run

TEST = anomaly.OutlierTest(k=1.5, min_deviation=0.0)


def test_upper_outlier_score_in_iqr_units():
    # q1 = 2, q3 = 4 (linear interpolation), IQR = 2, upper fence 7 -> (100 - 7) / 2
    scores, fences = anomaly.outlier_scores(np.array([1, 2, 3, 4, 100.0]), TEST)
    assert fences["hi"] == pytest.approx(7.0) and fences["lo"] == pytest.approx(-1.0)
    assert scores[4] == pytest.approx(46.5)
    assert np.isnan(scores[:4]).all()


def test_lower_tail_is_flagged_too():
    # sorted -50, 10, 11, 12, 13: q1 = 10, q3 = 12, lower fence 7 -> (7 + 50) / 2
    scores, _ = anomaly.outlier_scores(np.array([10, 11, 12, 13, -50.0]), TEST)
    assert scores[4] == pytest.approx(28.5)


def test_four_values_standard_quartiles():
    # q1 = 0, q3 = 2.5, IQR 2.5, upper fence 6.25 -> (10 - 6.25) / 2.5
    scores, _ = anomaly.outlier_scores(np.array([0, 0, 0, 10.0]), TEST)
    assert scores[3] == pytest.approx(1.5)


def test_zero_iqr_gives_infinite_score_above_min_deviation():
    values = np.array([0, 0, 0, 0, 0.2])
    scores, _ = anomaly.outlier_scores(values, anomaly.OutlierTest(1.5, 0.05))
    assert math.isinf(scores[4])
    scores, _ = anomaly.outlier_scores(values, anomaly.OutlierTest(1.5, 0.5))
    assert np.isnan(scores).all()   # noise below the minimum deviation


def test_too_few_drones_are_not_tested():
    scores, fences = anomaly.outlier_scores(np.array([0, 10.0]), anomaly.OutlierTest(min_n=3))
    assert np.isnan(scores).all() and fences == {}


def test_detect_picks_every_window():
    tl = pd.DataFrame({"t_u": [1.0] * 5 + [2.0] * 5, "drone": list(range(5)) * 2, "metric": "latency_ms",
                       "value": [1, 2, 3, 4, 100, 1, 1, 1, 1, 1.0]})
    flags = anomaly.detect(tl, {"latency_ms": TEST})
    assert flags[["t_u", "drone"]].values.tolist() == [[1.0, 4]]


def test_gps_drift_diagnosis(make_run):
    """Drone 2's GNSS drifts north at 1 m/s from tick 200 (5.0 s). In 0.5 s windows its mean
    discrepancy first reaches the 1.5 m minimum deviation in window [6.5, 7.0) (ticks 260..279,
    mean (269.5 - 200) * 0.025 = 1.7375 m): t_f = 7.0 - 5.0 = 2.0 s. With four drones at
    (0, 0, 0, x), q1 = 0 and q3 = x/4, so the upper fence is x/4 + 1.5 * x/4 and
    Sigma_a = (x - 5x/8) / (x/4) = 1.5 whatever x."""
    a = analyze_run(make_run(gnss_drift=(2, 200, 1.0), fault=("gps_drift", 200, 2)))
    assert a.onset.t_u == pytest.approx(5.0) and a.onset.target == 2
    row = a.diagnosis.set_index("metric").loc["disc_n_m"]
    assert row["t_f_s"] == pytest.approx(2.0)
    assert row["tau_d"] == pytest.approx(1.7375)
    assert row["sigma_a"] == pytest.approx(1.5) and row["drone"] == 2 and row["is_target"]
    assert a.scalars["anomaly_t_f_s"] == pytest.approx(2.0)
    assert a.scalars["anomaly_is_target"] == 1.0


def test_packet_loss_diagnosis(make_run):
    """Half of drone 1's Reports are lost from the start: in each 0.5 s window 10 of its 40
    messages (20 Heartbeats in, 20 Reports out) are lost -> tau_d = 0.25 at the first window.
    With five drones the four others are all 0, so q1 = q3 = 0, IQR = 0 and Sigma_a = inf
    (paper Table 5)."""
    a = analyze_run(make_run(n_drones=5, speeds_m_s=(1, 1, 1, 1, 1), drop_every={1: 2},
                             fault=("packet_loss", 0, 1)))
    row = a.diagnosis.set_index("metric").loc["loss_ratio"]
    assert row["t_f_s"] == pytest.approx(0.5)
    assert row["tau_d"] == pytest.approx(0.25)
    assert math.isinf(row["sigma_a"]) and row["is_target"]


def test_latency_diagnosis_with_given_onset(make_run):
    opts = AnalysisOptions(fault_onset_u=3.0, fault_target=3)
    a = analyze_run(make_run(extra_delay_ticks={3: 2}), opts)
    row = a.diagnosis.set_index("metric").loc["latency_ms"]
    assert row["t_f_s"] == pytest.approx(0.5)        # window [3.0, 3.5) ends 0.5 s after onset
    assert row["tau_d"] == pytest.approx(75.0) and row["is_target"]


def test_no_fault_no_diagnosis(make_run):
    a = analyze_run(make_run())
    assert a.onset is None and a.diagnosis.empty and a.flags.empty


MARKERS = [(-1, 120, "delivered", {"pkg": 1}), (-1, 200, "delivered", {"pkg": 2}),
           (0, 300, "formation_error", {"error_m": 0.5}), (1, 300, "formation_error", {"error_m": 1.5}),
           (1, 320, "formation_error", {"error_m": "bad"})]
SPECS = [
    {"name": "delivery_wait_s", "marker": "delivered", "node": "ground", "measure": "since_exec_start",
     "agg": ["mean", "max", "count"]},
    {"name": "formation_error_m", "marker": "formation_error", "node": "any", "field": "error_m",
     "agg": ["mean", "max", "last", "std"]},
    {"name": "d1_error_m", "marker": "formation_error", "node": "drone_1", "field": "error_m", "agg": "sum"},
    {"name": "none", "marker": "never", "agg": ["count", "mean"]},
]


def test_mission_metrics_from_markers(make_run):
    a = analyze_run(make_run(markers=MARKERS, algo_metrics=SPECS))
    s = a.scalars
    assert s["delivery_wait_s_mean"] == pytest.approx(2.0)   # (120 - 80) and (200 - 80) ticks: 1 s, 3 s
    assert s["delivery_wait_s_max"] == pytest.approx(3.0)
    assert s["delivery_wait_s_count"] == 2.0
    assert s["formation_error_m_mean"] == pytest.approx(1.0)
    assert s["formation_error_m_max"] == pytest.approx(1.5)
    assert s["formation_error_m_std"] == pytest.approx(0.5)
    assert s["d1_error_m_sum"] == pytest.approx(1.5)
    assert s["none_count"] == 0.0 and math.isnan(s["none_mean"])
    assert a.directions["delivery_wait_s_count"] == "higher"
    assert a.directions["delivery_wait_s_mean"] == "lower"
    assert len(a.markers) == 2 + 2 + 1


@pytest.mark.parametrize("entry", [
    {"marker": "x"}, {"name": "x", "marker": "x", "agg": ["median"]},
    {"name": "x", "marker": "x", "measure": "since_exec_start", "field": "f"},
    {"name": "x", "marker": "x", "node": "somewhere"}, {"name": "x", "marker": "x", "direction": "up"},
])
def test_bad_metric_specs_are_reported(entry):
    problems: list[str] = []
    assert mission.parse_specs({"algo": {"metrics": [entry]}}, problems) == []
    assert len(problems) == 1
