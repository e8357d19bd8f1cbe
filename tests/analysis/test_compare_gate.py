"""The regression gate's holes, closed: undirected metrics, min_separation_m's direction and the
tolerance file that travels with a baseline."""

import pandas as pd
import pytest

from swarmbox.analysis.cli import compare_main
from swarmbox.analysis.compare import NO_COMMON_ROW, Tolerance, compare, load_config, verdict

BASE = pd.DataFrame({"algo": ["a", "a", "a", "a"],
                     "metric": ["sim_time_s", "busy_s_mean", "min_separation_m", "mission_duration_s"],
                     "mean": [100.0, 20.0, 3.0, 50.0], "direction": ["", "", "higher", "lower"]})


def write(tmp_path, name, frame):
    path = tmp_path / name
    path.parent.mkdir(parents=True, exist_ok=True)
    frame.to_csv(path, index=False)
    return path


def scaled(metric, factor):
    cur = BASE.copy()
    cur.loc[cur["metric"] == metric, "mean"] *= factor
    return cur


@pytest.mark.parametrize("metric", ["sim_time_s", "busy_s_mean"])
def test_an_undirected_metric_tripled_is_a_regression(tmp_path, metric):
    base = write(tmp_path, "base/summary.csv", BASE)
    cur = write(tmp_path, "cur/summary.csv", scaled(metric, 3.0))
    assert compare_main([str(base), str(cur)]) == 1
    assert compare_main([str(base), str(write(tmp_path, "same/summary.csv", BASE))]) == 0


def test_informational_metrics_are_reported_not_failed(tmp_path, capsys):
    base = write(tmp_path, "base/summary.csv", BASE)
    cur = write(tmp_path, "cur/summary.csv", scaled("busy_s_mean", 3.0))
    tol = tmp_path / "tol.yaml"
    tol.write_text("metrics:\n  busy_s_mean: {informational: true}\n")
    assert compare_main([str(base), str(cur), "--config", str(tol)]) == 0
    assert "info" in capsys.readouterr().out
    # informational covers only the change of an undirected metric, not a real regression
    cur2 = write(tmp_path, "cur2/summary.csv", scaled("mission_duration_s", 2.0))
    tol.write_text("metrics:\n  mission_duration_s: {informational: true}\n")
    assert compare_main([str(base), str(cur2), "--config", str(tol)]) == 1


def test_the_tolerance_file_beside_the_baseline_is_used(tmp_path, capsys):
    base = write(tmp_path, "base/summary.csv", BASE)
    cur = write(tmp_path, "cur/summary.csv", scaled("sim_time_s", 3.0))
    (tmp_path / "base" / "tolerances.yaml").write_text("metrics:\n  sim_time_s: {informational: true}\n")
    assert compare_main([str(base), str(cur)]) == 0
    assert "tolerances: " in capsys.readouterr().out


def test_a_drop_in_separation_is_worse_and_a_rise_better():
    cfg = load_config(None)
    base = BASE.rename(columns={"mean": "value"}).drop(columns="direction")  # direction from the catalog
    for factor, expected in ((0.5, "worse"), (2.0, "better")):
        cur = scaled("min_separation_m", factor).rename(columns={"mean": "value"}).drop(columns="direction")
        out = compare(base, cur, cfg).set_index("metric")
        assert out.loc["min_separation_m", "direction"] == "higher"
        assert out.loc["min_separation_m", "verdict"] == expected


def test_verdicts_at_the_tolerance_edge():
    tol = Tolerance(rtol=0.1, atol=0.0)
    assert verdict(10.0, 11.0, tol) == "ok" and verdict(10.0, 11.01, tol) == "changed"
    assert verdict(10.0, 11.01, Tolerance(0.1, 0.0, informational=True)) == "info"
    assert verdict(10.0, 8.0, Tolerance(0.1, 0.0, direction="higher")) == "worse"


@pytest.mark.parametrize("direction", ["higher", "lower"])
def test_relative_tolerance_of_a_negative_baseline(direction):
    """tol = rtol * |b|: a negative baseline gets the same band as a positive one."""
    tol = Tolerance(rtol=0.05, atol=0.0, direction=direction)
    away = -10.6 if direction == "higher" else -9.4      # 6 % the wrong way
    assert verdict(-10.0, -10.4 if direction == "higher" else -9.6, tol) == "ok"   # 4 %: within
    assert verdict(-10.0, away, tol) == "worse"
    assert verdict(-10.0, -10.0 - (away + 10.0), tol) == "better"
    assert verdict(-10.0, -10.6, Tolerance(0.05, 0.0)) == "changed"
    assert verdict(-10.0, -10.4, Tolerance(0.05, 0.0)) == "ok"


def test_tables_with_no_row_in_common_are_refused_in_one_line(tmp_path, capsys):
    base = write(tmp_path, "base/summary.csv", BASE)
    other = write(tmp_path, "other/summary.csv", BASE.assign(algo="b"))
    assert compare_main([str(base), str(other)]) == 2
    captured = capsys.readouterr()
    assert captured.err.strip() == f"error: {NO_COMMON_ROW}"
    assert NO_COMMON_ROW == "no (group, metric) in common — is this the baseline for this sweep?"
    assert "REGRESSION" not in captured.out
    keyed = write(tmp_path, "keyed/summary.csv", BASE.assign(mission="m"))     # another sweep's design
    assert compare_main([str(base), str(keyed)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith(f"error: {NO_COMMON_ROW} (") and "'mission'" in err[0]


def test_run_counts_and_fewer_values_are_regressions(tmp_path, capsys):
    names = ["runs_attempted", "runs_ok", "runs_failed", "success_rate"]
    counts = pd.DataFrame({"algo": "a", "metric": names, "n": 20, "mean": [20.0, 20.0, 0.0, 1.0],
                           "direction": ""})
    base = pd.concat([counts, BASE.assign(n=20)])
    cur = pd.concat([counts.assign(mean=[20.0, 19.0, 1.0, 0.95]), BASE.assign(n=20)])
    base_p, cur_p = write(tmp_path, "b/summary.csv", base), write(tmp_path, "c/summary.csv", cur)
    assert compare_main([str(base_p), str(cur_p)]) == 1       # one run of twenty lost
    last = capsys.readouterr().out.strip().splitlines()[-1]
    assert last == "REGRESSION: runs_ok, runs_failed, success_rate"
    fewer = pd.concat([counts, BASE.assign(n=[20, 20, 20, 12])])
    assert compare_main([str(base_p), str(write(tmp_path, "f/summary.csv", fewer))]) == 1
    assert "REGRESSION: mission_duration_s" in capsys.readouterr().out
    assert compare_main([str(cur_p), str(base_p)]) == 0       # more runs ok: better


def test_exact_and_float_noise_modes(tmp_path):
    tol = tmp_path / "tol.yaml"
    tol.write_text("metrics:\n  mission_duration_s: {mode: exact}\n  sim_time_s: {mode: float-noise}\n")
    cfg = load_config(tol)
    assert cfg.tolerance("mission_duration_s", "").rtol == 0.0 == cfg.tolerance("mission_duration_s", "").atol
    assert verdict(50.0, 50.0 + 1e-6, cfg.tolerance("mission_duration_s", "")) == "worse"
    assert verdict(100.0, 100.0 * (1 + 1e-12), cfg.tolerance("sim_time_s", "")) == "ok"
    assert verdict(100.0, 100.001, cfg.tolerance("sim_time_s", "")) == "changed"
    tol.write_text("metrics:\n  sim_time_s: {mode: exact, rtol: 0.1}\n")
    with pytest.raises(ValueError, match="mode must be one of"):
        load_config(tol)
