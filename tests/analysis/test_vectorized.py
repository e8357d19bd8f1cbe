"""Whole-run array versions of per-window / per-tick loops give the loops' results exactly.

The loops are kept here as the oracles: outlier detection one window at a time
(:func:`anomaly.outlier_scores`), and the k-d tree nearest pair per tick (:func:`metrics.nearest_gap`).
"""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from swarmbox.analysis import anomaly, metrics
from swarmbox.analysis.report import analyze_run
from swarmbox.analysis.unify import T


def reference_detect(timeline: pd.DataFrame, tests: dict[str, anomaly.OutlierTest]) -> pd.DataFrame:
    rows = []
    timeline = timeline[timeline["metric"].isin(list(tests))]
    for (metric, t_u), group in timeline.groupby(["metric", T], sort=True):
        scores, fences = anomaly.outlier_scores(group["value"].to_numpy(), tests[metric])
        for drone, value, score in zip(group["drone"], group["value"], scores, strict=True):
            if not np.isnan(score):
                stats = {k: float(fences[k]) for k in ("median", "iqr", "lo", "hi")}
                rows.append({T: t_u, "metric": metric, "drone": int(drone), "value": float(value),
                             "score": float(score), **stats})
    cols = [T, "metric", "drone", "value", "score", "median", "iqr", "lo", "hi"]
    return pd.DataFrame(rows, columns=cols)


def random_timeline(seed: int, windows: int = 300, drones: int = 7) -> pd.DataFrame:
    rng = np.random.default_rng(seed)
    rows = []
    for metric in ("latency_ms", "loss_ratio", "disc_n_m"):
        for w in range(windows):
            base = rng.normal(20, 3, drones).round(1)        # rounded: ties and zero IQRs happen
            base[rng.random(drones) < 0.1] = np.nan          # missing values
            if rng.random() < 0.3:
                base[rng.integers(drones)] += rng.choice([-40, 40])   # an outlier
            if rng.random() < 0.05:
                base[:] = 5.0                                 # IQR 0
            rows += [{T: (w + 1) * 0.5, "drone": d, "metric": metric, "value": v}
                     for d, v in enumerate(base) if not (rng.random() < 0.05)]
    return pd.DataFrame(rows)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_detect_equals_the_per_window_loop(seed):
    timeline = random_timeline(seed)
    tests = anomaly.default_tests(1.5, {"disc_n_m": 0.0})
    got = anomaly.detect(timeline, tests)
    assert len(got) > 50
    pd.testing.assert_frame_equal(got, reference_detect(timeline, tests), check_exact=True)


def test_detect_on_a_run_and_on_nothing(make_run):
    a = analyze_run(make_run(drop_every={1: 4}, extra_delay_ticks={3: 2}))
    tests = anomaly.default_tests()
    pd.testing.assert_frame_equal(anomaly.detect(a.timeline, tests), reference_detect(a.timeline, tests),
                                  check_exact=True)
    empty = random_timeline(0).iloc[:0]
    pd.testing.assert_frame_equal(anomaly.detect(empty, tests), reference_detect(empty, tests))


def _state(n: int, ticks: int, seed: int) -> pd.DataFrame:
    rng = np.random.default_rng(seed)
    rows = [{"node": d, "tick": t, "true_n": p[0], "true_e": p[1], "true_d": p[2]}
            for t in range(ticks) for d in range(n) for p in [rng.normal(0, 4, 3)] if rng.random() > 0.05]
    frame = pd.DataFrame(rows)
    frame.loc[frame.sample(frac=0.02, random_state=seed).index, "true_e"] = np.nan   # no truth sometimes
    frame["pos_n"], frame["pos_e"], frame["pos_d"] = frame["true_n"], frame["true_e"], frame["true_d"]
    return frame


@pytest.mark.parametrize("n", [2, 5, 16])
def test_dense_separation_equals_the_kd_tree(n):
    state = _state(n, 400, n)
    got = metrics.separation_by_tick(state, list(range(n)))
    ref = state.sort_values("tick", kind="stable")
    ticks = np.sort(ref["tick"].unique())
    pos = ref[["pos_n", "pos_e", "pos_d"]].to_numpy()
    expected = [metrics.nearest_gap(pos[(ref["tick"] == t).to_numpy()]) for t in ticks]
    np.testing.assert_allclose(got.to_numpy(), expected, rtol=1e-12, atol=0.0, equal_nan=True)
    assert got.index.tolist() == ticks.tolist()
