"""The single-run analysis diagnoses every run from its logs alone (the finding); the onset-based table
is written only against a truth, as scoring; per-metric minimum deviations move the alarm as they should.

Synthetic runs: drone 2's GNSS drifts north at 1 m/s from tick 200 (5.0 s), so its discrepancy is
t - 5 m: it passes the 1.5 m minimum deviation at 6.5 s and, held for 0.1 s (4 ticks of 25 ms), is an
alarm at 6.575 s with the value 1.575 m; a 3 m minimum deviation moves that to 8.075 s and 3.075 m.
"""

from __future__ import annotations

import pandas as pd
import pytest

from swarmbox.analysis import diagnosis as dg
from swarmbox.analysis.cli import analyze_main
from swarmbox.analysis.load import load_run
from swarmbox.analysis.report import AnalysisOptions, analyze_run
from swarmbox.analysis.unify import unify

DRIFT = {"gnss_drift": (2, 200, 1.0)}


def test_a_run_without_fault_events_gets_its_finding_and_no_scoring(make_run, capsys):
    run = make_run(**DRIFT)
    assert analyze_main([str(run), "--no-figures"]) == 0
    finding = pd.read_csv(run / "tables" / "finding.csv").iloc[0]
    assert finding["detected"] and finding["drone"] == 2 and finding["metric"] == "disc_n_m"
    assert finding["t_u"] == pytest.approx(6.575) and finding["value"] == pytest.approx(1.575)
    alarms = pd.read_csv(run / "tables" / "alarms.csv")
    assert len(alarms) == finding["alarms"] == 1
    assert not (run / "tables" / "scoring.csv").exists()
    out = capsys.readouterr().out
    assert "finding (from the logs alone)" in out and "scoring" not in out


def test_with_a_fault_event_the_same_finding_and_a_scoring_table(make_run):
    blind, told = make_run(**DRIFT), make_run(**DRIFT, fault=("gps_drift", 200, 2))
    for run in (blind, told):
        assert analyze_main([str(run), "--no-figures"]) == 0
    pd.testing.assert_frame_equal(pd.read_csv(told / "tables" / "finding.csv"),
                                  pd.read_csv(blind / "tables" / "finding.csv"))
    scoring = pd.read_csv(told / "tables" / "scoring.csv").set_index("metric")
    assert scoring.loc["any", "onset_u"] == pytest.approx(5.0) and scoring.loc["any", "is_target"]


def _first(run_dir, **min_deviation) -> dict:
    run = load_run(run_dir)
    unify(run)
    return dg.finding(dg.scan(dg.drone_series(run), dg.DiagnosisOptions(min_deviation=min_deviation)))


def test_per_metric_minimum_deviation_overrides_in_the_diagnosis(make_run):
    run = make_run(**DRIFT)
    base = _first(run)
    assert (base["drone"], base["metric"], base["t_u"]) == (2, "disc_n_m", pytest.approx(6.575))
    raised = _first(run, disc_n_m=3.0)
    assert raised["t_u"] == pytest.approx(8.075) and raised["value"] == pytest.approx(3.075)
    assert _first(run, disc_e_m=3.0, latency_ms=1000.0) == base   # other metrics' overrides: no effect
    assert not _first(run, disc_n_m=100.0)["detected"]
    # the run analysis passes its overrides to both diagnoses
    analysis = analyze_run(run, AnalysisOptions(min_deviation={"disc_n_m": 3.0}))
    assert analysis.finding.iloc[0]["t_u"] == pytest.approx(8.075)
    raised_opts = AnalysisOptions(min_deviation={"disc_n_m": 3.0})
    told = analyze_run(make_run(**DRIFT, fault=("gps_drift", 200, 2)), raised_opts)
    assert told.diagnosis.set_index("metric").loc["disc_n_m", "tau_d"] >= 3.0
