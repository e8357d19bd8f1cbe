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
    assert "true positions" in ax.get_title()                                     # which positions


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
    assert fig.axes[0].get_ylabel() == "GNSS - estimate, north [m]" and fig.axes[0].get_title()


def test_comm_graph_labels_every_link(analysis):
    fig = figures.comm_graph(analysis.links)
    texts = [t.get_text() for t in fig.axes[0].texts]
    assert sum("G>d" in t for t in texts) == 4 and "G" in texts
    assert "latency" in fig.axes[1].get_ylabel()                    # the promised colour scale


SUMMARY = pd.DataFrame({
    "algo": ["a", "b", "c"] * 2,
    "metric": ["mission_duration_s"] * 3 + ["utilization_mean"] * 3,
    "mean": [10.0, 20.0, 15.0, 0.2, 0.6, 0.4],
    "direction": ["lower"] * 3 + ["higher"] * 3,
})


def test_gap_to_the_best_group():
    gap, means = figures.gaps(SUMMARY)
    assert gap["mission_duration_s"].to_dict() == pytest.approx({"a": 0.0, "b": 0.5, "c": 0.25})
    assert gap["utilization_mean"].to_dict() == pytest.approx({"a": 4 / 6, "b": 0.0, "c": 2 / 6})
    assert means.loc["b", "mission_duration_s"] == 20.0


def test_two_groups_keep_the_size_of_their_difference():
    two = pd.DataFrame({"algo": ["a", "b"], "metric": ["mission_duration_s"] * 2, "mean": [100.0, 103.0],
                        "direction": ["lower"] * 2, "n": [5, 5]})
    gap, _ = figures.gaps(two)
    assert gap["mission_duration_s"].to_dict() == pytest.approx({"a": 0.0, "b": 3 / 103})   # not 0 vs 1


def test_noise_level_differences_are_ties_and_machine_figures_are_left_out():
    summary = SUMMARY.assign(mean=[10.0, 10.0 + 1e-9, 10.0, 0.2, 0.6, 0.4])
    machine = pd.DataFrame({"algo": ["a", "b"], "metric": ["real_time_factor"] * 2, "mean": [50.0, 90.0],
                            "direction": ["higher"] * 2})
    gap, _ = figures.gaps(pd.concat([summary, machine]))
    assert gap["mission_duration_s"].tolist() == [0.0, 0.0, 0.0]
    assert "real_time_factor" not in gap.columns


def test_heatmap_cells_annotations_title_and_colour_scale():
    fig = figures.heatmap(SUMMARY.assign(n=5))
    ax = fig.axes[0]
    assert [t.get_text() for t in ax.get_yticklabels()] == ["mission_duration_s [s]", "utilization_mean"]
    assert [t.get_text() for t in ax.get_xticklabels()] == ["a", "b", "c"]
    assert "20" in [t.get_text() for t in ax.texts]
    assert ax.collections[0].get_array().reshape(2, 3)[0].tolist() == pytest.approx([0.0, 50.0, 25.0])
    assert "best" in ax.get_title() and "5" in ax.get_title()
    assert "gap to the best" in fig.axes[1].get_ylabel()           # the colour bar says what colour means


def test_boxplots_one_panel_per_varying_metric_with_units():
    runs = pd.DataFrame({"algo": ["a"] * 3 + ["b"] * 3, "m1": [1, 2, 3, 4, 5, 6.0],
                         "mission_duration_s": [0, 0, 1, 1, 2, 2.0], "collision_events": [0.0] * 6})
    fig = figures.boxplots(runs, metrics=["m1", "mission_duration_s", "collision_events"])
    visible = [ax for ax in fig.axes if ax.get_visible()]
    assert [ax.get_title() for ax in visible] == ["m1", "mission_duration_s"]
    assert visible[1].get_ylabel() == "mission_duration_s [s]"
    assert [t.get_text() for t in visible[0].get_xticklabels()] == ["a\n(n=3)", "b\n(n=3)"]
    assert not visible[0].patches                                    # n = 3: no quartile box
    assert "collision_events = 0" in fig.get_suptitle()


def test_heatmap_with_a_single_group_says_there_is_nothing_to_compare():
    fig = figures.heatmap(SUMMARY[SUMMARY["algo"] == "a"].assign(n=5))
    assert "nothing to compare" in fig.axes[0].texts[0].get_text()
