"""The array versions of clock unification, connectivity, workload, grouped quantiles and categorical
loading equal the pandas code they replaced, kept here (``_old_*``) as oracles; exact equality."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from swarmbox.analysis import metrics, network, unify
from swarmbox.analysis.load import NET, load_run
from swarmbox.analysis.report import ANALYZED_COLUMNS
from swarmbox.analysis.unify import T


def _old_to_unified(t_local: pd.Series, node: pd.Series, clocks: pd.DataFrame) -> pd.Series:
    idx = clocks.set_index("node")
    node = node.astype("int64")
    off = node.map(idx["offset_s"]).fillna(0.0).astype("float64")
    drift = node.map(idx["drift_ppm"]).fillna(0.0).astype("float64") * 1e-6
    return (t_local.astype("float64") - off) / (1.0 + drift)


def _old_connectivity(flow: pd.DataFrame, nodes: list[int], window_s: float) -> pd.DataFrame:
    nodes = sorted(n for n in nodes if n != NET)
    got = flow[flow["delivered"]]
    w = np.floor(got["t_recv"] / window_s).astype("int64")
    pairs = pd.DataFrame({"w": w, "a": np.minimum(got["src"], got["dst"]),
                          "b": np.maximum(got["src"], got["dst"])}).drop_duplicates()
    grouped = dict(tuple(pairs.groupby("w")))
    rows = []
    for win in range(int(w.min()), int(w.max()) + 1):
        part = grouped.get(win)
        edges = set(zip(part["a"].tolist(), part["b"].tolist(), strict=True)) if part is not None else set()
        rows.append({T: (win + 1) * window_s, "connectivity": network.algebraic_connectivity(nodes, edges)})
    return pd.DataFrame(rows)


def _old_completion(mine: pd.DataFrame) -> float:
    mine = mine.sort_values(T)
    if mine.empty or mine["name"].iloc[-1] != "exec_complete":
        return np.nan
    last_incomplete = mine.loc[mine["name"] == "exec_incomplete", T]
    done = mine[mine["name"] == "exec_complete"]
    if len(last_incomplete):
        done = done[done[T] > last_incomplete.iloc[-1]]
    return float(done[T].iloc[0])


def _old_workload(state: pd.DataFrame, events: pd.DataFrame, drones: list[int], window) -> pd.DataFrame:
    inside = dict(tuple(metrics.within(state, window).groupby("node", sort=False)))
    named = events["name"].isin(["exec_complete", "exec_incomplete"])
    progress = dict(tuple(events[(events["kind"] == "progress") & named].groupby("node", sort=False)))
    rows = []
    for drone in drones:
        mine = inside.get(drone, state.iloc[0:0]).sort_values(T)
        true = mine[["true_n", "true_e", "true_d"]].to_numpy(dtype="float64")
        truth = len(true) and np.isfinite(true).all()
        pos = true if truth else mine[["pos_n", "pos_e", "pos_d"]].to_numpy(dtype="float64")
        step = np.diff(pos, axis=0)
        step = step[np.isfinite(step).all(axis=1)]
        dist = (float(np.hypot(step[:, 0], step[:, 1]).sum()), float(np.linalg.norm(step, axis=1).sum())) \
            if len(pos) > 1 else (0.0, 0.0)
        t_done = _old_completion(progress.get(drone, events.iloc[0:0]))
        busy = window.duration
        if not np.isnan(t_done):
            busy = float(np.clip(t_done - window.start, 0, window.duration))
        rows.append({"drone": drone, "distance_h_m": dist[0], "distance_3d_m": dist[1],
                     "position_source": "truth" if truth else "estimate", "t_complete_u": t_done,
                     "completed": not np.isnan(t_done), "busy_s": busy, "utilization": busy / window.duration,
                     "idle_s": window.duration - busy})
    return pd.DataFrame(rows)


@pytest.fixture(scope="module")
def runs(tmp_path_factory, formation_run):
    """A real run (lossy wifi, skewed clock) and a synthetic one with loss, delay and clock offsets."""
    from tests.analysis.synthetic import Scenario, build_run

    clocks = {"drone_2": (0.5, 100.0), "drone_1": (-0.2, -30.0)}
    synthetic = build_run(tmp_path_factory.mktemp("syn") / "run",
                          Scenario(drop_every={1: 4}, extra_delay_ticks={3: 2}, clocks=clocks))
    out = []
    for path in (formation_run, synthetic):
        run = load_run(path, ANALYZED_COLUMNS)
        clocks = unify.unify(run)
        out.append((run, clocks, network.message_flow(run.tables["messages"], 0.025)))
    return out


def test_window_minima_of_all_pairs_equal_the_per_pair_grouping(runs):
    for run, _, _ in runs:
        samples = unify.clock_samples(run.tables["messages"])
        wins = unify.all_window_minima(samples, 5.0)
        pairs = {(min(a, b), max(a, b)) for a, b in zip(samples["a"], samples["b"], strict=True) if a != b}
        assert sorted(wins) == sorted(pairs) and len(wins) >= 4
        for (a, b), win in wins.items():
            fwd = samples[(samples["a"] == a) & (samples["b"] == b)]
            bwd = samples[(samples["a"] == b) & (samples["b"] == a)]
            pd.testing.assert_frame_equal(win, unify.window_minima(fwd, bwd, 5.0), check_exact=True)


def test_unified_times_equal_the_mapped_ones(runs):
    for run, clocks, _ in runs:
        clocks = clocks[clocks["node"] != 0].sample(frac=1.0, random_state=0)   # a node without a clock
        clocks.loc[clocks.index[0], "drift_ppm"] = np.nan
        for frame in run.tables.values():
            got = unify.to_unified(frame["t_s"], frame["node"], clocks)
            pd.testing.assert_series_equal(got, _old_to_unified(frame["t_s"], frame["node"], clocks),
                                           check_exact=True, check_names=False)
    nothing = clocks.iloc[:0]   # no estimate at all: local time is kept
    pd.testing.assert_series_equal(unify.to_unified(frame["t_s"], frame["node"], nothing),
                                   _old_to_unified(frame["t_s"], frame["node"], nothing),
                                   check_exact=True, check_names=False)


@pytest.mark.parametrize("window_s", [1.0, 0.3])
def test_connectivity_equals_the_window_loop(runs, window_s):
    for run, _, flow in runs:
        got = network.connectivity_timeline(flow, run.nodes, window_s)
        pd.testing.assert_frame_equal(got, _old_connectivity(flow, run.nodes, window_s), check_exact=True)
        gappy = flow[(flow["t_recv"] < 3.0) | (flow["t_recv"] > 6.0)]   # windows with no edge at all
        pd.testing.assert_frame_equal(network.connectivity_timeline(gappy, run.nodes, window_s),
                                      _old_connectivity(gappy, run.nodes, window_s), check_exact=True)


@pytest.mark.parametrize("seed", range(4))
def test_completion_equals_the_sorted_frame(seed):
    """Random complete/incomplete sequences with equal times (ties), unsorted, short and long."""
    rng = np.random.default_rng(seed)
    for n in (0, 1, 3, 15, 40):
        events = pd.DataFrame({T: rng.integers(0, 8, n) * 0.5, "kind": "progress", "node": 1,
                               "name": rng.choice(["exec_complete", "exec_incomplete"], n, p=[0.7, 0.3])})
        try:
            expected = _old_completion(events)
        except IndexError:   # the final complete event ties with an incomplete one: both refuse
            with pytest.raises(IndexError):
                metrics.completion_time(events, 1)
            continue
        got = metrics.completion_time(events, 1)
        assert got == expected or (np.isnan(got) and np.isnan(expected))


def test_workload_equals_the_per_drone_frames(runs):
    """Also with the rows shuffled, a drone without samples, one without truth and out-of-order ids."""
    for run, _, _ in runs:
        state, events = run.tables["state"], run.tables["events"]
        window = metrics.exec_window(run.tables["stages"], float(state[T].max()))
        shuffled = state.sample(frac=1.0, random_state=1)
        shuffled.loc[shuffled["node"] == run.drones[0], "true_n"] = np.nan
        drones = [*reversed(run.drones), 77]
        for frame in (state, shuffled):
            pd.testing.assert_frame_equal(metrics.drone_workload(frame, events, drones, window),
                                          _old_workload(frame, events, drones, window), check_exact=True)


def test_grouped_quantiles_equal_one_call_per_quantile():
    rng = np.random.default_rng(3)
    n = 3000
    frame = pd.DataFrame({"src": rng.integers(0, 6, n), "dst": rng.integers(0, 3, n),
                          "delivered": rng.random(n) < 0.9, "counted": True, "nbytes": 10.0,
                          "latency_ms": rng.exponential(5.0, n)})
    frame["lost"] = ~frame["delivered"]
    frame.loc[frame["src"] == 5, "delivered"] = False      # a group with no latency at all
    frame.loc[frame.index[:50], "latency_ms"] = np.nan     # latencies the quantiles skip
    for keys in (["src"], ["src", "dst"]):
        got = network.grouped_stats(frame, keys, 10.0)
        lat = frame[frame["delivered"]].groupby(keys)["latency_ms"]
        for q, col in ((0.5, "latency_ms_p50"), (0.95, "latency_ms_p95")):
            pd.testing.assert_series_equal(got[col], lat.quantile(q).reindex(got.index).rename(col),
                                           check_exact=True)
    assert network.grouped_stats(frame.iloc[:0], ["src"], 1.0).empty


def test_categories_in_order_of_first_appearance(make_run):
    """Whatever the order (and unused words) of a file's dictionary, the loaded categories are the words
    in order of first appearance, as when every file is read as text."""
    run_dir = make_run(drop_every={1: 4})
    path = run_dir / "logs" / "drone_0" / "messages.parquet"
    table = pq.read_table(path)
    words = ["zzz", "recv", "send", "drop"]   # not the order of appearance; "zzz" never appears
    kind = pa.DictionaryArray.from_arrays(pa.array([words.index(k) for k in table["kind"].to_pylist()],
                                                   pa.int32()), pa.array(words))
    pq.write_table(table.set_column(table.column_names.index("kind"), "kind", kind), path)
    frame = load_run(run_dir).tables["messages"]
    text = pd.concat([pq.read_table(p, columns=["kind"]).to_pandas()["kind"].astype("str")
                      for p in sorted((run_dir / "logs").glob("*/messages.parquet"))])   # as loaded
    assert list(frame["kind"].cat.categories) == list(pd.unique(text))
    assert frame["kind"].astype("str").tolist() == text.tolist()
