"""The regression gate's holes, closed: undirected metrics, min_separation_m's direction and the
tolerance file that travels with a baseline."""

import pandas as pd
import pytest

from swarmbox.analysis.cli import compare_main
from swarmbox.analysis.compare import Tolerance, compare, load_config, verdict

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
