"""The analyzer at swarm scale: neighbour queries without N x N, summary figures, projected loading."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
from scipy.spatial.distance import pdist

from swarmbox.analysis import figures, metrics, network
from swarmbox.analysis.unify import T


def _state(n_drones: int, n_ticks: int, seed: int = 0) -> pd.DataFrame:
    rng = np.random.default_rng(seed)
    rows = n_drones * n_ticks
    pos = rng.uniform(0, 100, size=(rows, 3))
    return pd.DataFrame({
        "node": np.repeat(np.arange(n_drones), n_ticks).astype("int16"),
        "tick": np.tile(np.arange(n_ticks), n_drones), T: np.tile(np.arange(n_ticks) * 0.025, n_drones),
        "true_n": pos[:, 0], "true_e": pos[:, 1], "true_d": pos[:, 2],
        "pos_n": pos[:, 0], "pos_e": pos[:, 1], "pos_d": pos[:, 2],
        "vel_n": 1.0, "vel_e": 0.0, "vel_d": 0.0,
    })


def test_separation_equals_the_brute_force_minimum():
    state = _state(60, 25)
    sep = metrics.separation_by_tick(state, list(range(60)))
    for tick, rows in state.groupby("tick"):
        assert sep[tick] == pytest.approx(pdist(rows[["true_n", "true_e", "true_d"]].to_numpy()).min())


def test_separation_skips_a_drone_without_a_sample_and_needs_two():
    state = _state(3, 4)
    state = state[~((state["node"] == 2) & (state["tick"] == 1))]
    sep = metrics.separation_by_tick(state, [0, 1, 2])
    rows = state[state["tick"] == 1]
    assert sep[1] == pytest.approx(pdist(rows[["true_n", "true_e", "true_d"]].to_numpy()).min())
    one = metrics.separation_by_tick(state[state["node"] == 0], [0])
    assert one.isna().all()


def test_separation_of_1000_drones_stays_small_in_memory():
    import tracemalloc

    state = _state(1000, 40)
    tracemalloc.start()
    sep = metrics.separation_by_tick(state, list(range(1000)))
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    assert len(sep) == 40 and sep.notna().all()
    assert peak < 50e6   # the dense ticks x N x N x 3 array would need 40 x 1000 x 1000 x 24 B = 960 MB


def test_trajectories_of_a_large_swarm_are_a_density_with_sampled_tracks():
    state = _state(200, 30)
    fig = figures.trajectories(state)
    ax = fig.axes[0]
    labels = [t.get_text() for t in ax.get_legend().get_texts()]
    assert sorted(labels) == ["12 sampled tracks", "start (200 drones)"]
    assert len(ax.get_lines()) == 13          # 12 tracks + the legend proxy, not 200 lines
    assert not ax.texts                       # no 200 start labels


def test_timeline_of_a_large_swarm_is_a_band_with_the_target():
    rng = np.random.default_rng(1)
    frame = pd.DataFrame({"metric": "disc_n_m", "drone": np.repeat(np.arange(100), 10),
                          T: np.tile(np.arange(10) * 0.5, 100), "value": rng.normal(size=1000)})
    fig = figures.timeline(frame, metric="disc_n_m", target=7)
    labels = [t.get_text() for t in fig.axes[0].get_legend().get_texts()]
    assert sorted(labels) == ["5-95 %", "drone 7 (target)", "median of 100 drones", "min-max"]
    median = fig.axes[0].get_lines()[0].get_ydata()
    np.testing.assert_allclose(median, frame.groupby(T)["value"].median().to_numpy())


def test_connectivity_of_a_star_and_of_a_split_graph():
    nodes = [-1, *range(5)]
    assert network.algebraic_connectivity(nodes, {(-1, i) for i in range(5)}) == pytest.approx(1.0)
    assert network.algebraic_connectivity(nodes, {(-1, 0), (1, 2)}) == 0.0
