"""The faster paths of a sweep's per-run analysis equal what they replaced, exactly: the unified times
for far-apart node ids, the overall network stats, the swarm timeline from one layout, the Theil-Sen
fit, the categories kept in order, a small run read without the thread pool, the execution window, time
orders and progress events from arrays, distinct nodes and missing drop reasons in the flow, and the
workers' memory settings."""

from __future__ import annotations

import platform
import subprocess
import sys

import numpy as np
import pandas as pd
import pyarrow as pa
import pytest

from swarmbox.analysis import flow, load, metrics, network, unify
from swarmbox.analysis.load import GROUND, load_run
from swarmbox.analysis.report import ANALYZED_COLUMNS, SCALAR_COLUMNS
from swarmbox.analysis.unify import T
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


@pytest.mark.parametrize("columns", [None, SCALAR_COLUMNS])
def test_small_run_read_without_the_pool_loads_the_same(make_run, monkeypatch, columns):
    """One file after another or by the pool: the same tables, problems (in the same order) and verdict,
    with a corrupt file and a missing one among them."""
    path = make_run(skip_files=("drone_1/state",))
    (path / "logs" / "drone_0" / "events.parquet").write_bytes(b"not parquet")
    pools = []

    class CountingPool(load.ThreadPoolExecutor):
        def __init__(self, *args, **kwargs) -> None:
            pools.append(1)
            super().__init__(*args, **kwargs)

    monkeypatch.setattr(load, "ThreadPoolExecutor", CountingPool)
    serial = load_run(path, columns)
    assert not pools   # a few hundred kB: read in this thread
    monkeypatch.setattr(load, "_POOL_BYTES", 0)
    pooled = load_run(path, columns)
    assert pools
    assert serial.problems == pooled.problems and len(serial.problems) >= 2
    assert serial.incomplete and pooled.incomplete and serial.nodes == pooled.nodes
    for name, frame in pooled.tables.items():
        pd.testing.assert_frame_equal(serial.tables[name], frame, check_exact=True)


def _old_exec_window(stages: pd.DataFrame, t_last: float) -> metrics.ExecWindow | None:
    ground = stages[stages["node"] == GROUND].sort_values(T)
    starts = ground.loc[ground["stage"] == metrics.EXECUTION, T]
    if starts.empty:
        return None
    start = float(starts.iloc[0])
    after = ground[(ground[T] > start) & (ground["stage"] != metrics.EXECUTION)]
    if after.empty:
        return metrics.ExecWindow(start, max(start, t_last), False)
    return metrics.ExecWindow(start, float(after[T].iloc[0]), True)


@pytest.mark.parametrize("seed", range(8))
def test_exec_window_equals_the_sorted_frame(seed):
    """Stage entries of the ground and of drones, shuffled, with equal and unknown times; some with no
    EXECUTION, or none after it."""
    rng = np.random.default_rng(seed)
    n = int(rng.integers(0, 12))
    stages = pd.DataFrame({T: rng.integers(0, 6, n) * 0.5, "stage": rng.integers(1, 6, n).astype("int8"),
                           "node": rng.choice([GROUND, 0, 1], n).astype("int16")})
    stages.loc[rng.random(n) < 0.15, T] = np.nan
    for t_last in (1.0, 9.0):
        got, expected = metrics.exec_window(stages, t_last), _old_exec_window(stages, t_last)
        assert (got is None and expected is None) or (
            np.array_equal([got.start, got.end], [expected.start, expected.end], equal_nan=True)
            and got.complete == expected.complete)


def _old_time_order(t: np.ndarray) -> np.ndarray:
    known = ~np.isnan(t)
    return np.concatenate([np.flatnonzero(known)[np.argsort(t[known], kind="quicksort")],
                           np.flatnonzero(~known)])


@pytest.mark.parametrize("t", [[], [np.nan], [0.5], [0.0, 0.1, 0.2], [0.0, 0.1, 0.1, 0.2], [0.2, 0.1],
                               [0.0, np.nan, 0.2], [0.3, 0.1, 0.1, np.nan, 0.0]])
def test_time_order_of_increasing_times_is_theirs(t):
    t = np.asarray(t, dtype="float64")
    np.testing.assert_array_equal(np.arange(len(t))[metrics._time_order(t)], _old_time_order(t))


def test_progress_events_from_arrays_equal_the_text_filter():
    names = ["exec_complete", "exec_incomplete", "exec_completed", "", None, "takeoff"]
    rng = np.random.default_rng(0)
    events = pd.DataFrame({"kind": rng.choice(["progress", "marker", "", None], 200),
                           "name": rng.choice(np.asarray(names, dtype=object), 200)}).astype("str")
    events.loc[rng.random(200) < 0.1, "kind"] = np.nan
    expected = (events["kind"] == "progress") & events["name"].isin(["exec_complete", "exec_incomplete"])
    np.testing.assert_array_equal(metrics._is_progress(events), expected.to_numpy())
    assert expected.any()


@pytest.mark.skipif(platform.libc_ver()[0] != "glibc", reason="the settings are glibc's")
def test_worker_keeps_freed_memory_from_one_allocator():
    """In a fresh process, as a sweep's worker starts: Arrow then allocates from the tuned malloc."""
    code = ("import pyarrow as pa; from swarmbox.analysis.parallel import _keep_freed_memory; "
            "_keep_freed_memory(); print(pa.default_memory_pool().backend_name)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "system"


@pytest.mark.parametrize("values", [[], [3], [-1, -1, 0, 0, 0, 2, 2, -2], [2, 0, 2, 1, 0, 0, 1],
                                    [1.0, np.nan, np.nan, 0.0, 1.0]])
def test_distinct_values_of_runs_equal_pandas_unique(values):
    """Long runs (as loaded), no runs at all, and unknown values (NaN never equals itself)."""
    values = np.asarray(values, dtype="float64" if any(np.isnan(v) for v in values) else "int16")
    np.testing.assert_array_equal(flow._distinct(values), pd.unique(values))


def test_text_without_any_word_equals_the_taken_one():
    words = pa.array(["loss", "queue"])
    for codes in (np.full(5, -1), np.zeros(0, dtype=np.int64)):
        got = pd.Series(flow._text(codes, words))
        expected = pd.Series(pd.array(words.take(pa.array(codes, mask=codes < 0)), dtype="str"))
        pd.testing.assert_series_equal(got, expected, check_exact=True)
    assert flow._text(np.array([1, -1]), words).tolist()[0] == "queue"
