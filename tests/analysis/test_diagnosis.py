"""Onset-agnostic diagnosis on synthetic runs: tick assignment, the detector, clock robustness, and
that nothing the analyzer outputs depends on the fault events."""

from __future__ import annotations

import io
import shutil

import numpy as np
import pandas as pd
import pyarrow.parquet as pq
import pytest

from swarmbox.analysis import anomaly, detection, diagnosis_plots, scoring
from swarmbox.analysis import diagnosis as dg
from swarmbox.analysis.load import load_run
from swarmbox.analysis.unify import T, unify

N = 6
#: Small constant GNSS biases give the healthy drones a spread (IQR > 0); drone 2 drifts north at
#: 1 m/s from tick 300 (7.5 s); the fault event says so.
DRIFT = {"n_drones": N, "speeds_m_s": (1.0,) * N, "complete_ticks": {}, "ticks": 440,
         "ground_stages": {1: 0, 2: 20, 3: 40, 4: 420, 5: 430},
         "gnss_bias_m": {0: 0.1, 1: -0.1, 3: 0.2, 4: -0.2, 5: 0.05},
         "gnss_drift": (2, 300, 1.0), "fault": ("gps_drift", 300, 2)}


def diagnosed(run_dir, opts=None):
    run = load_run(run_dir)
    unify(run)
    series = dg.drone_series(run, opts)
    return run, series, dg.scan(series, opts)


def test_samples_go_to_the_nearest_tick():
    t = np.array([0.0249999, 0.0250001, 0.0374, 0.0376, -0.000003])
    assert dg.nearest_tick(t, 0.025).tolist() == [1, 1, 1, 2, 0]


def test_tukey_rule_matches_the_per_window_outlier_test():
    rng = np.random.default_rng(3)
    mat = rng.normal(size=(200, 9))
    mat[rng.random(mat.shape) < 0.1] = np.nan
    mat[::7, 4] += 6.0
    score, med, _ = dg.outlier_matrix(mat, 0.5)
    for i, row in enumerate(mat):
        want, fences = anomaly.outlier_scores(row, anomaly.OutlierTest(1.5, 0.5))
        np.testing.assert_allclose(score[i], want, equal_nan=True)
        assert med[i] == pytest.approx(fences["median"])


def test_paper_rule_is_upper_tail_at_2_5_iqr_with_an_absolute_gate():
    row = np.array([[0.0, 1.0, 2.0, 3.0, 4.0, 40.0, -40.0]])
    tukey, _, _ = dg.outlier_matrix(row, 1.0, "tukey")
    paper, _, _ = dg.outlier_matrix(row, 1.0, "paper")
    assert np.isfinite(tukey[0, 5]) and np.isfinite(tukey[0, 6])
    assert np.isfinite(paper[0, 5]) and np.isnan(paper[0, 6])
    q1, q3 = np.quantile(row, [0.25, 0.75])
    assert paper[0, 5] == pytest.approx((40.0 - (q3 + 2.5 * (q3 - q1))) / (q3 - q1))
    gated, _, _ = dg.outlier_matrix(row, 50.0, "paper")
    assert np.isnan(gated).all()


def test_an_alarm_needs_persistent_flags_and_is_stamped_when_confirmed():
    flags = np.array([1, 0, 1, 1, 1, 1, 0, 1, 1, 0], dtype=bool)
    assert dg._episodes(flags, 3) == [(4, 5)]
    assert dg._episodes(flags, 1) == [(0, 0), (2, 5), (7, 8)]


def test_drift_is_found_on_the_right_drone_metric_and_time(make_run):
    run_dir = make_run(**DRIFT)
    run, series, alarms = diagnosed(run_dir)
    first = dg.finding(alarms)
    assert first["detected"] and first["drone"] == 2 and first["metric"] == "disc_n_m"
    # swarm median 0.075 m: |disc - median| >= 1.5 m from tick 363 (63 ticks of 1 m/s drift), the
    # fourth consecutive flag confirms the alarm at tick 366
    assert first["t_u"] == pytest.approx(366 * 0.025)
    assert first["value"] == pytest.approx(66 * 0.025)
    (truth,) = scoring.ground_truth(run.tables["events"])
    graded = scoring.score_alarms(alarms, truth, dg.scan_span(run), N)
    assert graded["detected"] and graded["localized"] and graded["false_alarms"] == 0
    assert graded["t_f_s"] == pytest.approx(66 * 0.025)


@pytest.mark.slow
def test_diagnosis_is_unchanged_when_a_node_clock_is_offset(make_run):
    _, _, ref = diagnosed(make_run(**DRIFT))
    assert len(ref)
    for offset_s in (3e-6, -3e-6, 0.2, -0.2):
        run, _, got = diagnosed(make_run(**DRIFT, clocks={"drone_2": (offset_s, 0.0)}))
        assert run.manifest["clocks"]["drone_2"]["offset_s"] == offset_s
        pd.testing.assert_frame_equal(got, ref, check_exact=False, atol=1e-9)


def _strip_fault_events(run_dir, out):
    shutil.copytree(run_dir, out)
    path = out / "logs" / "ground" / "events.parquet"
    table = pq.read_table(path)
    keep = pd.Series(table.column("kind").to_pylist()) != "fault"
    pq.write_table(table.filter(keep.to_numpy()), path)
    return out


def _png(fig) -> bytes:
    buf = io.BytesIO()
    fig.savefig(buf, format="png", metadata={"Software": None})
    return buf.getvalue()


@pytest.mark.slow
def test_analyzer_output_does_not_depend_on_the_fault_events(make_run, tmp_path):
    full = make_run(**DRIFT)
    blind = _strip_fault_events(full, tmp_path / "blind")
    run_f, series_f, alarms_f = diagnosed(full)
    run_b, series_b, alarms_b = diagnosed(blind)
    assert scoring.ground_truth(run_b.tables["events"]) == []
    pd.testing.assert_frame_equal(alarms_f, alarms_b)
    pd.testing.assert_frame_equal(series_f.tidy(), series_b.tidy())
    blind_figure = diagnosis_plots.timeline(series_b, alarms_b)
    assert _png(diagnosis_plots.timeline(series_f, alarms_f)) == _png(blind_figure)
    analyzer_columns = ["detector", "rule", "threshold_scale", "alarms", "first_alarm_drone",
                        "first_alarm_metric", "scan_s", "n_drones"]
    rows_f, rows_b = (detection.evaluate_run(d, [dg.DiagnosisOptions()]) for d in (full, blind))
    pd.testing.assert_frame_equal(rows_f[analyzer_columns], rows_b[analyzer_columns])
    assert rows_f.loc[0, "detected"] and rows_f.loc[0, "fault"] == "gps_drift"
    assert rows_b.loc[0, "fault"] == "none"
    (truth,) = scoring.ground_truth(run_f.tables["events"])
    overlay = diagnosis_plots.timeline(series_f, alarms_f, truth=truth)
    extra = [a for a in overlay.axes[0].get_children() if a.get_gid() == diagnosis_plots.TRUTH_GID]
    assert len(extra) == 1 and extra[0].get_label().startswith("ground truth: gps_drift on drone 2")


def test_false_alarms_count_merged_incidents_in_healthy_time_only():
    alarms = pd.DataFrame({T: [1.0, 1.5, 5.0, 12.0, 30.0], "metric": ["a", "b", "a", "a", "a"],
                           "drone": [0, 0, 0, 1, 1], "value": 1.0, "score": 2.0, "median": 0.0, "iqr": 1.0,
                           "end_u": [2.0, 2.5, 5.0, 13.0, 31.0]})
    inc = scoring.incidents(alarms)
    assert inc[T].tolist() == [1.0, 5.0, 12.0, 30.0]          # 1.0 and 1.5 overlap on drone 0
    truth = scoring.Truth("latency", 1, 10.0, 15.0)
    # fault window 10-15 s + 10 s of grace: the alarm at 12 s is the detection, 30 s is healthy again
    assert scoring.false_alarms(inc[T].to_numpy(), (0.0, 40.0), [truth]) == 3
    assert scoring.healthy_time((0.0, 40.0), [truth]) == pytest.approx(25.0)
    graded = scoring.score_alarms(alarms, truth, (0.0, 40.0), 2)
    assert graded["detected"] and graded["localized"] and graded["t_f_s"] == pytest.approx(2.0)
    assert graded["healthy_drone_h"] == pytest.approx(50.0 / 3600)


@pytest.mark.parametrize("error_s", [3e-6, -3e-6])
def test_series_ignore_microsecond_clock_estimation_errors(make_run, error_s):
    """The clock estimate of a node is off by microseconds: its samples must stay in their ticks."""
    run = load_run(make_run(**DRIFT))
    unify(run)
    ref = dg.drone_series(run)
    for name in ("state", "messages"):
        frame = run.tables[name]
        run.tables[name] = frame.assign(**{T: frame[T] + np.where(frame["node"] == 2, error_s, 0.0)})
    got = dg.drone_series(run)
    for metric, mat in ref.values.items():
        np.testing.assert_allclose(got.values[metric], mat, atol=1e-9, err_msg=metric)
