"""Figure content: what is drawn, not only that a file appeared."""

from __future__ import annotations

import pandas as pd
import pytest
from matplotlib.figure import Figure

from swarmbox.analysis import figures
from swarmbox.analysis.report import analyze_run


@pytest.fixture(scope="module")
def analysis(tmp_path_factory):
    from tests.analysis.synthetic import Scenario, build_run

    path = build_run(tmp_path_factory.mktemp("fig") / "run",
                     Scenario(gnss_drift=(2, 200, 1.0), fault=("gps_drift", 200, 2)))
    return analyze_run(path)


def test_trajectory_plot_has_one_line_per_drone(analysis):
    fig = figures.trajectories(analysis.run.tables["state"])
    ax = fig.axes[0]
    lines = ax.get_lines()
    assert [line.get_label() for line in lines] == ["drone 0", "drone 1", "drone 2", "drone 3"]
    east, north = lines[3].get_data()
    assert east[0] == pytest.approx(15.0) and north.max() == pytest.approx(60.0)   # x = East, y = North
    assert [t.get_text() for t in ax.texts] == ["0", "1", "2", "3"]                # start labels
    assert ax.get_aspect() == 1.0


def test_trajectories_on_a_given_axes(analysis):
    fig = Figure()
    ax = fig.add_subplot()
    assert figures.trajectories(analysis.run.tables["state"], ax=ax) is fig


def test_timeline_marks_onset_and_detection(analysis):
    diag = analysis.diagnosis.set_index("metric").loc["disc_n_m"]
    fig = figures.timeline(analysis.timeline, metric="disc_n_m", onset=analysis.onset.t_u,
                           detection=analysis.onset.t_u + diag["t_f_s"], target=2)
    labels = [line.get_label() for line in fig.axes[0].get_lines()]
    assert labels == ["drone 0", "drone 1", "drone 2 (target)", "drone 3", "fault onset", "first anomaly"]
    onset_line = fig.axes[0].get_lines()[4]
    assert onset_line.get_xdata()[0] == pytest.approx(5.0)


def test_comm_graph_labels_every_link(analysis):
    fig = figures.comm_graph(analysis.links)
    texts = [t.get_text() for t in fig.axes[0].texts]
    assert sum("G>d" in t for t in texts) == 4 and "G" in texts


SUMMARY = pd.DataFrame({
    "algo": ["a", "b", "c"] * 2,
    "metric": ["mission_duration_s"] * 3 + ["utilization_mean"] * 3,
    "mean": [10.0, 20.0, 15.0, 0.2, 0.6, 0.4],
    "direction": ["lower"] * 3 + ["higher"] * 3,
})


def test_normalization_makes_better_darker():
    score, means = figures.normalized(SUMMARY)
    assert score["mission_duration_s"].to_dict() == pytest.approx({"a": 1.0, "b": 0.0, "c": 0.5})
    assert score["utilization_mean"].to_dict() == pytest.approx({"a": 0.0, "b": 1.0, "c": 0.5})
    assert means.loc["b", "mission_duration_s"] == 20.0


def test_noise_level_differences_are_ties():
    summary = SUMMARY.assign(mean=[10.0, 10.0 + 1e-9, 10.0, 0.2, 0.6, 0.4])
    score, _ = figures.normalized(summary)
    assert score["mission_duration_s"].tolist() == [0.5, 0.5, 0.5]


def test_heatmap_cells_and_annotations():
    fig = figures.heatmap(SUMMARY)
    ax = fig.axes[0]
    assert [t.get_text() for t in ax.get_xticklabels()] == ["mission_duration_s", "utilization_mean"]
    assert "20" in [t.get_text() for t in ax.texts]
    assert ax.collections[0].get_array().reshape(3, 2)[0].tolist() == pytest.approx([1.0, 0.0])


def test_boxplots_one_panel_per_metric():
    runs = pd.DataFrame({"algo": ["a"] * 3 + ["b"] * 3, "m1": [1, 2, 3, 4, 5, 6.0],
                         "m2": [0, 0, 1, 1, 2, 2.0]})
    fig = figures.boxplots(runs, metrics=["m1", "m2"])
    visible = [ax for ax in fig.axes if ax.get_visible()]
    assert [ax.get_title() for ax in visible] == ["m1", "m2"]
    assert [t.get_text() for t in visible[0].get_xticklabels()] == ["a", "b"]
