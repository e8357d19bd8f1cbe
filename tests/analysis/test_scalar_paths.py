"""The faster paths of a sweep's per-run analysis equal what they replaced, exactly: the unified times
for far-apart node ids, the overall network stats, the swarm timeline from one layout, the Theil-Sen
fit, the categories kept in order, ``reason`` read as a dictionary and the release of read buffers."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from swarmbox.analysis import load, metrics, network, unify
from swarmbox.analysis.load import load_run
from swarmbox.analysis.report import ANALYZED_COLUMNS
from swarmbox.record.broadcast import BROADCAST
from tests.analysis.test_array_paths import _old_to_unified


@pytest.fixture(scope="module")
def real(formation_run):
    run = load_run(formation_run, ANALYZED_COLUMNS)
    unify.unify(run)
    return run


def test_unified_times_for_node_ids_too_far_apart_for_a_table():
    t = pd.Series(np.linspace(0.0, 9.0, 10))
    node = pd.Series([0, 1, 2, 10**9, 10**9, -1, -2, 5, 0, 10**9], dtype="int64")
    clocks = pd.DataFrame({"node": [10**9, 0, -1, 2], "offset_s": [0.5, -0.2, 0.0, np.nan],
                           "drift_ppm": [30.0, -10.0, 0.0, 5.0]})
    pd.testing.assert_series_equal(unify.to_unified(t, node, clocks), _old_to_unified(t, node, clocks),
                                   check_exact=True, check_names=False)


def _old_overall_stats(flow: pd.DataFrame) -> dict[str, float]:
    names = ["loss_ratio", "latency_ms_mean", "latency_ms_p50", "latency_ms_p95", "latency_ms_max"]
    row = network.grouped_stats(flow.assign(_all=0), ["_all"], 0.0).iloc[0]
    return {k: float(row[k]) for k in names}


def test_overall_stats_equal_one_group_of_every_message(real):
    flow = network.message_flow(real.tables["messages"], 0.025)
    assert flow["lost"].any()
    odd = flow.copy()
    odd.loc[odd.index[:40], "latency_ms"] = np.nan            # latencies the statistics skip
    cases = [flow, odd, flow.assign(delivered=False), flow.assign(counted=False, lost=False)]
    for case in cases:
        got, expected = network.overall_stats(case), _old_overall_stats(case)
        assert list(got) == list(expected)
        for key, value in expected.items():
            assert got[key] == value or (np.isnan(got[key]) and np.isnan(value)), key


def test_swarm_timeline_equals_separation_and_order(real):
    """Rows shuffled and repeated, a drone without truth, one without samples at some ticks."""
    state = real.tables["state"]
    drones = real.drones
    messy = pd.concat([state, state.sample(50, random_state=0)]).sample(frac=1.0, random_state=1)
    lossy = state[~((state["node"] == drones[0]) & (state["tick"] % 7 == 0))]
    no_truth = state.assign(true_n=state["true_n"].where(state["node"] != drones[-1]))
    for frame in (state, messy, lossy, no_truth):
        got = metrics.swarm_timeline(frame, drones)
        ticks = pd.Index(got["tick"])
        sep = metrics.separation_by_tick(frame, drones).reindex(ticks).to_numpy()
        order = metrics.order_by_tick(frame, drones).reindex(ticks).to_numpy()
        np.testing.assert_array_equal(got["separation_m"].to_numpy(), sep)
        np.testing.assert_array_equal(got["order"].to_numpy(), order)
    assert metrics.swarm_timeline(no_truth, drones)["separation_m"].notna().any()


def test_last_samples_drop_only_repeats(real):
    state = real.tables["state"]
    assert metrics._last_samples(state) is state   # the loader's order: nothing can repeat
    messy = pd.concat([state, state.iloc[:30].assign(pos_n=1.0)]).sample(frac=1.0, random_state=2)
    pd.testing.assert_frame_equal(metrics._last_samples(messy),
                                  messy.drop_duplicates(["node", "tick"], keep="last"), check_exact=True)


def _old_one_way(win: pd.DataFrame, typical_delay_s: float) -> float | None:
    if win["fwd"].notna().any():
        return float(win["fwd"].min()) - typical_delay_s
    if win["bwd"].notna().any():
        return typical_delay_s - float(win["bwd"].min())
    return None


@pytest.mark.parametrize("seed", range(4))
def test_one_way_estimates_equal_the_frame_ones(seed):
    rng = np.random.default_rng(seed)
    opts = unify.ClockOptions()
    for heard in ("fwd", "bwd", "none", "both"):
        win = pd.DataFrame({c: rng.normal(0.01, 0.002, 30) for c in ("fwd", "bwd", "t_mid")})
        win.loc[rng.random(30) < 0.3, "fwd"] = np.nan
        if heard != "both":
            win.loc[:, [c for c in ("fwd", "bwd") if c != heard]] = np.nan
        for given in (win, {c: win[c].to_numpy() for c in win}):
            got = unify.one_way_estimate(0, 1, given, opts, 0.004)
            expected = _old_one_way(win, 0.004)
            assert (got is None and expected is None) or got.offset_s == expected


@pytest.mark.parametrize("values", [["a", "b", "a", "c"], ["b", "a", "b"], ["a", "a", "b", "c", "b"], []])
@pytest.mark.parametrize("extra", [[], ["zzz"]])
def test_categories_end_in_order_of_first_appearance(values, extra):
    """Already in order (the shortcut), shuffled, with an unused word (missing values arrive filled)."""
    series = pd.Series(pd.Categorical(values, categories=sorted(set(values) | set(extra))))
    got = load._first_seen(series)
    assert list(got.cat.categories) == list(pd.unique(pd.Series(values, dtype=object)))
    assert got.astype(object).tolist() == values


def test_reason_read_as_dictionary_equals_the_text(formation_run, monkeypatch):
    """Broadcast rows' destination lists are decoded for the expansion; the frame is the same."""
    files = sorted((formation_run / "logs").glob("*/messages.parquet"))
    assert any((pq.read_table(f, columns=["dst"])["dst"].to_numpy() == BROADCAST).any() for f in files)
    got = load_run(formation_run, ANALYZED_COLUMNS).tables["messages"]
    monkeypatch.setitem(load._READ_AS_DICTIONARY, "messages", ("kind", "type"))
    expected = load_run(formation_run, ANALYZED_COLUMNS).tables["messages"]
    pd.testing.assert_frame_equal(got, expected, check_exact=True)


@pytest.mark.parametrize(("limit", "released"), [(0, 1), (1 << 40, 0)])
def test_read_buffers_released_only_after_a_large_read(formation_run, monkeypatch, limit, released):
    calls = []

    class Pool:
        def release_unused(self) -> None:
            calls.append(1)

    monkeypatch.setattr(load, "_RELEASE_BYTES", limit)
    monkeypatch.setattr(pa, "default_memory_pool", Pool)
    load_run(formation_run, ANALYZED_COLUMNS)
    assert len(calls) == released

