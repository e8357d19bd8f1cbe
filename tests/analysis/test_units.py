"""Units: from the catalog or the algorithm's declaration, never guessed from a name; logged columns in
the schema's unit; figures that say what they draw (detectors apart, 90 % line, units, whole titles)."""

from __future__ import annotations

import math
import shutil

import numpy as np
import pandas as pd
import pytest
from matplotlib.backends.backend_agg import FigureCanvasAgg

from swarmbox.analysis import diagnosis_plots, figures
from swarmbox.analysis.catalog import declared_units, unit_of
from swarmbox.analysis.cli import EXIT_INCOMPLETE, analyze_main
from swarmbox.analysis.load import load_run
from swarmbox.api import DroneAlgorithm, Setpoint
from swarmbox.record.schema import TABLES
from tests.conftest import run_config, table

DELIVERY = {"algo": {"metrics": [
    {"name": "delivery_wait_s", "marker": "delivered", "measure": "since_exec_start",
     "agg": ["mean", "count"]},
    {"name": "formation_error_m", "marker": "f", "field": "error_m", "unit": "m", "agg": ["max", "count"]},
    {"name": "speed", "marker": "s", "field": "v", "agg": ["mean"]},
    {"name": "duplicate_deliveries", "marker": "duplicate", "agg": ["count", "sum"]},
]}}


def test_units_come_from_the_declaration_and_a_count_has_none():
    units = declared_units(DELIVERY)
    assert units == {"delivery_wait_s_mean": "s", "delivery_wait_s_count": "", "formation_error_m_max": "m",
                     "formation_error_m_count": "", "speed_mean": "", "duplicate_deliveries_count": "",
                     "duplicate_deliveries_sum": ""}
    assert figures.label("delivery_wait_s_count", units) == "delivery_wait_s_count"     # not "[s]"
    assert figures.label("delivery_wait_s_mean", units) == "delivery_wait_s_mean [s]"
    assert figures.label("undeclared_m_mean") == "undeclared_m_mean"                   # no guess
    assert unit_of("collision_events") == "" and unit_of("latency_ms_p95") == "ms"
    assert unit_of("latency_ms_tau_d") == "ms" and unit_of("disc_n_m_t_f_s") == "s"
    assert unit_of("runs_ok") == "" and unit_of("success_rate") == ""


class YawDrone(DroneAlgorithm):
    """Hovers at 2 m facing east (a quarter turn), then reports done."""

    def exec_loop(self, ctx):
        n, e, _ = ctx.home_ned_m
        return Setpoint.position(n, e, -2.0, math.pi / 2)

    def exec_complete(self, ctx):
        return ctx.stage_time_s > 6.0


def test_the_state_table_logs_yaw_in_radians(tmp_path):
    column = {c.name: c for c in TABLES["state"]}["yaw_rad"]
    assert column.unit == "rad"
    drone = "algo.drone._target_=tests.analysis.test_units.YawDrone"
    manifest = run_config(tmp_path / "yaw", ["algo=hover", drone])
    assert manifest["status"] == "ok", manifest["reason"]
    yaw = table(tmp_path / "yaw", "drone_0", "state")["yaw_rad"].to_numpy()
    assert yaw[0] == pytest.approx(0.0, abs=1e-9)
    assert yaw[-1] == pytest.approx(math.pi / 2, abs=0.02)      # 1.571, not 90 (degrees)
    assert np.nanmax(np.abs(yaw)) <= math.pi


def test_the_loader_refuses_a_run_that_still_holds_a_partial_file(tmp_path, capsys):
    run_dir = tmp_path / "run"
    assert run_config(run_dir, ["algo=hover", "algo.params.hover_s=1"])["status"] == "ok"
    assert not load_run(run_dir).incomplete
    state = run_dir / "logs" / "drone_1" / "state.parquet"
    shutil.copy(state, state.with_name("state.parquet.partial"))   # a writer that never finished
    run = load_run(run_dir)
    assert run.incomplete
    assert any("drone_1/state.parquet.partial" in p and "never finished" in p for p in run.problems)
    assert analyze_main([str(run_dir), "--no-figures"]) == EXIT_INCOMPLETE
    assert "incomplete run" in capsys.readouterr().err and not (run_dir / "tables").exists()


def _clipped(fig) -> list[str]:
    """Texts of the titles that do not fit inside the figure."""
    FigureCanvasAgg(fig).draw()
    box = fig.bbox
    titles = [ax.title for ax in fig.axes if ax.get_visible()] + ([fig._suptitle] if fig._suptitle else [])
    out = []
    for t in titles:
        if t.get_text():
            e = t.get_window_extent()
            if e.x0 < box.x0 - 1 or e.x1 > box.x1 + 1 or e.y1 > box.y1 + 1:
                out.append(t.get_text())
    return out


def _detection_rates() -> pd.DataFrame:
    rows = []
    for fault in ("gps_bias", "latency"):
        for detector, rates in (("swarmbox", [0.2, 0.95, 1.0]), ("baseline", [0.0, 0.3, 0.6])):
            for n in (5, 36):
                rows += [{"fault": fault, "detector": detector, "n_drones": n, "network": "wifi",
                          "magnitude": m, "detection_rate": r}
                         for m, r in zip((1.0, 3.0, 10.0), rates, strict=True)]
    return pd.DataFrame(rows)


def test_detection_figure_tells_the_detectors_apart_and_labels_the_target_and_unit():
    fig = diagnosis_plots.detection_curves(_detection_rates())
    ax = fig.axes[0]
    lines = {line.get_label(): line for line in ax.get_lines()}
    swarm, base = lines["swarm analyzer, 5 drones, wifi"], lines["per-drone baseline, 5 drones, wifi"]
    assert swarm.get_color() != base.get_color() and swarm.get_marker() != base.get_marker()
    assert lines["swarm analyzer, 36 drones, wifi"].get_linestyle() != swarm.get_linestyle()
    legend = [t.get_text() for t in ax.get_legend().get_texts()]
    assert "per-drone baseline, 36 drones, wifi" in legend and "90 % detection" in legend
    assert lines["90 % detection"].get_ydata()[0] == 0.9 and any(t.get_text() == "90 %" for t in ax.texts)
    assert ax.get_xlabel() == "magnitude [m]" and fig.axes[1].get_xlabel() == "magnitude [ms]"
    assert _clipped(fig) == []


def test_sweep_figures_keep_whole_titles_and_show_n():
    summary = pd.DataFrame({
        "algo": ["a_rather_long_algorithm_name", "b_rather_long_algorithm_name"] * 3,
        "metric": ["mission_duration_s"] * 2 + ["runs_ok"] * 2 + ["runs_attempted"] * 2,
        "n": [4, 5, 5, 5, 5, 5], "mean": [10.0, 12.0, 5, 5, 5, 5],
        "direction": ["lower"] * 2 + ["higher"] * 4,
        "kind": ["metric"] * 2 + ["runs"] * 4})
    fig = figures.heatmap(summary, group_by=("algo",))
    ax = fig.axes[0]
    assert [t.get_text() for t in ax.get_xticklabels()] == [
        "a_rather_long_algorithm_name\n(5/5 runs ok)", "b_rather_long_algorithm_name\n(5/5 runs ok)"]
    assert "10\n(n=4)" in [t.get_text() for t in ax.texts]        # a mean on fewer values than runs ok
    assert "runs_ok" not in [t.get_text() for t in ax.get_yticklabels()]
    assert _clipped(fig) == []
    runs = pd.DataFrame({"algo": ["a"] * 3 + ["b"] * 3, "mission_duration_s": [1, 2, 3, 4, 5, 6.0],
                         **{f"constant_metric_number_{i}": [1.0] * 6 for i in range(8)}})
    fig = figures.boxplots(runs, metrics=list(runs.columns[1:]))
    assert "constant_metric_number_7 = 1" in fig.get_suptitle().replace("\n", " ") and _clipped(fig) == []


def test_heatmap_compares_only_within_a_stratum():
    summary = pd.DataFrame({"algo": ["a", "b", "a", "b"], "mission": ["m1", "m1", "m2", "m2"],
                            "metric": ["mission_duration_s"] * 4, "mean": [10.0, 20.0, 100.0, 50.0],
                            "direction": ["lower"] * 4, "n": [5] * 4})
    gap, _ = figures.gaps(summary, ("algo",), strata=("mission",))
    assert gap["mission_duration_s"].to_dict() == pytest.approx({"a/m1": 0.0, "b/m1": 0.5, "a/m2": 0.5,
                                                                 "b/m2": 0.0})
    alone = summary[(summary["algo"] == "a") | (summary["mission"] == "m1")].iloc[:3]   # m2: only a
    gap, _ = figures.gaps(alone, ("algo",), strata=("mission",))
    assert np.isnan(gap.loc["a/m2", "mission_duration_s"]) and gap.loc["b/m1", "mission_duration_s"] == 0.5
