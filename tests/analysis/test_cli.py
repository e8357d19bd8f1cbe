"""The command lines (analyze, compare) and the Hydra callback."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pandas as pd
import pytest
from omegaconf import OmegaConf

from swarmbox.analysis.callback import AnalyzeSweepCallback
from swarmbox.analysis.cli import analyze_main, compare_main

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def analyzed_sweep(sweep_dir, tmp_path_factory):
    root = tmp_path_factory.mktemp("cli") / "sweep"
    shutil.copytree(sweep_dir, root)
    assert analyze_main([str(root), "--n-boot", "300"]) == 0
    return root


def test_analyze_run_writes_tables_and_figures(make_run, capsys):
    run = make_run(fault=("gps_drift", 200, 2), gnss_drift=(2, 200, 1.0))
    assert analyze_main([str(run)]) == 0
    out = capsys.readouterr().out
    assert "mission_duration_s" in out and "disc_n_m" in out
    metrics = pd.read_csv(run / "tables" / "metrics.csv").set_index("metric")
    assert metrics.loc["mission_duration_s", "value"] == pytest.approx(15.0)
    for name in ("drones", "links", "clocks", "finding", "alarms", "scoring", "anomalies", "timeline",
                 "problems"):
        assert (run / "tables" / f"{name}.csv").is_file()
    for name in ("trajectories", "timeline_disc_n_m", "timeline_latency_ms", "comm_graph"):
        for ext in ("png", "svg"):
            assert (run / "figures" / f"{name}.{ext}").stat().st_size > 1000


def test_analyze_sweep_writes_benchmark_tables(analyzed_sweep, capsys):
    tables = analyzed_sweep / "tables"
    summary = pd.read_csv(tables / "summary.csv")
    assert {"algo", "metric", "mean", "ci_low", "ci_high", "direction"} <= set(summary.columns)
    assert set(summary["algo"]) == {"fast", "slow"}
    paired = pd.read_csv(tables / "paired.csv").set_index("metric")
    assert paired.loc["mission_duration_s", "diff_mean"] == pytest.approx(1.0)
    for name in ("runs.csv", "summary.md", "summary_wide.md", "paired.md", "ranks.csv", "problems.csv"):
        assert (tables / name).is_file()
    for name in ("heatmap", "boxplots"):
        assert (analyzed_sweep / "figures" / f"{name}.png").stat().st_size > 1000


def test_analyze_sweep_twice_gives_identical_files(analyzed_sweep, tmp_path):
    out = tmp_path / "again"
    assert analyze_main([str(analyzed_sweep), "--n-boot", "300", "--out", str(out), "--no-figures"]) == 0
    for name in ("summary.csv", "paired.csv", "ranks.csv"):
        assert (out / "tables" / name).read_bytes() == (analyzed_sweep / "tables" / name).read_bytes()


def test_analyze_bad_path(tmp_path, capsys):
    assert analyze_main([str(tmp_path / "nope")]) == 2
    assert analyze_main([str(tmp_path)]) == 2
    assert "no run directory" in capsys.readouterr().err


def _worse(src: Path, dst: Path, metric: str, factor: float) -> Path:
    frame = pd.read_csv(src)
    frame.loc[frame["metric"] == metric, "mean"] *= factor
    frame.to_csv(dst, index=False)
    return dst


def test_compare_identical_is_ok(analyzed_sweep, capsys):
    summary = analyzed_sweep / "tables" / "summary.csv"
    assert compare_main([str(summary), str(summary)]) == 0
    assert "OK" in capsys.readouterr().out


def test_compare_regression_and_improvement(analyzed_sweep, tmp_path, capsys):
    summary = analyzed_sweep / "tables" / "summary.csv"
    worse = _worse(summary, tmp_path / "worse.csv", "mission_duration_s", 1.2)     # lower is better
    assert compare_main([str(summary), str(worse)]) == 1
    out = capsys.readouterr().out
    assert "worse" in out and "mission_duration_s" in out and "REGRESSION" in out
    assert compare_main([str(worse), str(summary)]) == 0      # the other way round: better
    within = _worse(summary, tmp_path / "within.csv", "mission_duration_s", 1.01)   # inside 5 %
    assert compare_main([str(summary), str(within)]) == 0
    assert compare_main([str(summary), str(within), "--rtol", "0", "--atol", "0"]) == 1


def test_compare_tolerance_file(analyzed_sweep, tmp_path):
    summary = analyzed_sweep / "tables" / "summary.csv"
    worse = _worse(summary, tmp_path / "worse.csv", "mission_duration_s", 1.2)
    loose = tmp_path / "tol.yaml"
    loose.write_text("metrics:\n  mission_duration_s: {rtol: 0.5}\n")
    assert compare_main([str(summary), str(worse), "--config", str(loose)]) == 0
    flipped = tmp_path / "flip.yaml"
    flipped.write_text("metrics:\n  mission_duration_s: {direction: higher}\n")
    assert compare_main([str(summary), str(worse), "--config", str(flipped)]) == 0
    assert compare_main([str(summary), str(worse), "--ignore", "mission_duration_s"]) == 0


def test_compare_missing_metric(analyzed_sweep, tmp_path):
    summary = analyzed_sweep / "tables" / "summary.csv"
    frame = pd.read_csv(summary)
    partial = tmp_path / "partial.csv"
    frame[frame["metric"] != "loss_ratio"].to_csv(partial, index=False)
    assert compare_main([str(summary), str(partial)]) == 1
    assert compare_main([str(summary), str(partial), "--allow-missing"]) == 0
    assert compare_main([str(partial), str(summary)]) == 0      # a new metric is fine


def test_compare_bad_input(analyzed_sweep, tmp_path, capsys):
    summary = analyzed_sweep / "tables" / "summary.csv"
    junk = tmp_path / "junk.csv"
    junk.write_text("a,b\n1,2\n")
    bad_yaml = tmp_path / "bad.yaml"
    bad_yaml.write_text("metrics:\n  x: {rtol: fast}\n")
    assert compare_main([str(summary), str(tmp_path / "missing.csv")]) == 2
    assert compare_main([str(summary), str(junk)]) == 2
    assert compare_main([str(summary), str(summary), "--config", str(bad_yaml)]) == 2
    assert compare_main([str(summary)]) == 2
    err = capsys.readouterr().err
    assert "no such file" in err and "needs a 'metric' column" in err


def test_compare_run_metrics(make_run, tmp_path):
    run = make_run()
    assert analyze_main([str(run), "--no-figures"]) == 0
    metrics = run / "tables" / "metrics.csv"
    assert compare_main([str(metrics), str(metrics)]) == 0


def test_module_entry_points(analyzed_sweep):
    summary = analyzed_sweep / "tables" / "summary.csv"
    proc = subprocess.run([sys.executable, "-m", "swarmbox.compare", str(summary), str(summary)],
                          cwd=ROOT, capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr
    proc = subprocess.run([sys.executable, "-m", "swarmbox.analyze", str(analyzed_sweep / "missing")],
                          cwd=ROOT, capture_output=True, text=True)
    assert proc.returncode == 2 and "not a directory" in proc.stderr


def test_callback_analyzes_the_sweep_and_never_raises(sweep_dir, tmp_path, caplog):
    root = tmp_path / "sweep"
    shutil.copytree(sweep_dir, root)
    callback = AnalyzeSweepCallback(n_boot=50, figures=False)
    callback.on_multirun_end(OmegaConf.create({"hydra": {"sweep": {"dir": str(root)}}}))
    assert (root / "tables" / "summary.csv").is_file()
    callback.on_multirun_end(OmegaConf.create({"hydra": {}}))    # no sweep dir: logged, not raised
    assert "sweep analysis failed" in caplog.text


def test_callback_uses_every_core_whatever_the_load_the_sweep_left(monkeypatch):
    monkeypatch.setattr(os, "getloadavg", lambda: (2.0, 2.0, 2.0))   # a 2-core sweep just ended
    assert AnalyzeSweepCallback()._workers() == len(os.sched_getaffinity(0))
    assert AnalyzeSweepCallback(workers=1)._workers() == 1


def _analyze(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "swarmbox.analyze", *args, "--no-figures"], cwd=ROOT,
                          capture_output=True, text=True, timeout=300)


def test_truncated_table_makes_a_run_incomplete_unless_allowed(make_run):
    run = make_run()
    path = run / "logs" / "drone_1" / "messages.parquet"
    path.write_bytes(path.read_bytes()[: path.stat().st_size // 2])   # truncated
    refused = _analyze(str(run))
    assert refused.returncode == 3, refused.stderr
    assert "incomplete run" in refused.stderr and "drone_1/messages.parquet: unreadable" in refused.stderr
    assert not (run / "tables").exists()
    allowed = _analyze(str(run), "--allow-incomplete")
    assert allowed.returncode == 0, allowed.stderr
    assert "WARNING: incomplete run" in allowed.stderr and (run / "tables" / "metrics.csv").is_file()


def test_sweep_lists_every_skipped_directory_with_its_reason(sweep_dir, tmp_path):
    root = tmp_path / "sweep"
    shutil.copytree(sweep_dir, root)
    killed = root / "killed" / "logs" / "ground"
    killed.mkdir(parents=True)
    (killed / "stages.parquet.partial").write_bytes(b"PAR1")
    proc = _analyze(str(root), "--n-boot", "50")
    assert proc.returncode == 0, proc.stderr
    assert "skipped: killed: no run.json" in proc.stdout
    assert ", 1 skipped" in proc.stdout
