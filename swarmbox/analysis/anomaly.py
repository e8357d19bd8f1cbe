"""Cross-swarm anomaly detection and the diagnosis metrics of paper section 5.3 (t_f, tau_d, Sigma_a).

Outlier test, applied per monitored metric and per window to the values of *all* drones:

- quartiles q1, q3 and median by linear interpolation (``numpy.quantile``'s default);
  IQR = q3 - q1; Tukey fences lo = q1 - k*IQR, hi = q3 + k*IQR (k = 1.5 by default);
- a value v is an outlier when it lies outside a fence (both tails) **and** |v - median| is at least
  the metric's ``min_deviation`` (so that, when most drones agree exactly and IQR = 0, noise is not
  flagged);
- score = distance beyond the crossed fence in IQR units, (v - hi)/IQR or (lo - v)/IQR; +inf when
  IQR = 0 (then only the minimum deviation gates the flag);
- windows with fewer than ``min_n`` drones are not tested.

Diagnosis against a fault onset t0 (the first ``fault`` event named ``*_start``, or given): among
the flags in windows ending after t0, per metric and over all metrics (``any``):
t_f = window end of the first flag - t0; tau_d = the flagged value; Sigma_a = its score; ``drone`` = the
flagged drone (the highest score in that window; ties go to the larger deviation, then the lower id);
``is_target`` says whether it is the fault's target; ``target_t_f_s`` is t_f of the target's first flag.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from swarmbox.analysis.unify import T

_IQR_EPS = 1e-12


@dataclass(frozen=True, slots=True)
class OutlierTest:
    k: float = 1.5
    min_deviation: float = 0.0
    min_n: int = 3


def default_tests(k: float = 1.5, min_deviation: Mapping[str, float] | None = None) -> dict[str, OutlierTest]:
    """Monitored metrics with their minimum deviations (1 ms, 5 % loss, 1.5 m discrepancy),
    overridden per metric by ``min_deviation``."""
    tests = {
        "latency_ms": OutlierTest(k, 1.0), "loss_ratio": OutlierTest(k, 0.05),
        "disc_n_m": OutlierTest(k, 1.5), "disc_e_m": OutlierTest(k, 1.5), "disc_d_m": OutlierTest(k, 1.5),
    }
    for name, dev in (min_deviation or {}).items():
        tests[name] = OutlierTest(k, dev)
    return tests


@dataclass(frozen=True, slots=True)
class FaultOnset:
    t_u: float
    name: str = ""
    target: int | None = None
    extra: dict = field(default_factory=dict)


def outlier_scores(values: np.ndarray, test: OutlierTest) -> tuple[np.ndarray, dict[str, float]]:
    """Score of every value (NaN when not an outlier) and the fences used."""
    values = np.asarray(values, dtype="float64")
    scores = np.full(values.shape, np.nan)
    finite = values[np.isfinite(values)]
    if finite.size < max(test.min_n, 1):
        return scores, {}
    q1, med, q3 = np.quantile(finite, [0.25, 0.5, 0.75])
    iqr = q3 - q1
    lo, hi = q1 - test.k * iqr, q3 + test.k * iqr
    beyond = np.where(values > hi, values - hi, np.where(values < lo, lo - values, 0.0))
    flagged = (beyond > 0) & (np.abs(values - med) >= test.min_deviation) & np.isfinite(values)
    scores[flagged] = beyond[flagged] / iqr if iqr > _IQR_EPS else np.inf
    return scores, {"q1": q1, "median": med, "q3": q3, "iqr": iqr, "lo": lo, "hi": hi}


def _group_quantiles(values: np.ndarray, group: np.ndarray, n_groups: int,
                     qs: tuple[float, ...]) -> tuple[np.ndarray, list[np.ndarray]]:
    """Per group: the count of finite values and their quantiles, exactly as ``numpy.quantile``
    (linear method) computes them on each group alone, with one sort for all groups."""
    finite = np.isfinite(values)
    count = np.bincount(group, weights=finite, minlength=n_groups).astype("int64")
    order = np.lexsort((np.where(finite, values, np.inf), group))   # finite values first in a group
    ordered = np.where(finite, values, np.inf)[order]
    start = np.concatenate([[0], np.cumsum(np.bincount(group, minlength=n_groups))[:-1]])
    out = []
    last = np.maximum(count - 1, 0)
    for q in qs:
        virtual = last * q
        prev = np.minimum(np.floor(virtual), last).astype("int64")
        nxt = np.minimum(prev + 1, last)
        gamma = virtual - prev
        a = ordered[np.minimum(start + prev, len(ordered) - 1)] if len(ordered) else np.zeros(n_groups)
        b = ordered[np.minimum(start + nxt, len(ordered) - 1)] if len(ordered) else np.zeros(n_groups)
        diff = b - a
        out.append(np.where(gamma >= 0.5, b - diff * (1 - gamma), a + diff * gamma))   # numpy's _lerp
    return count, out


def _detect_metric(frame: pd.DataFrame, metric: str, test: OutlierTest) -> pd.DataFrame:
    """:func:`outlier_scores` of every window of one metric, all windows at once."""
    frame = frame[frame[T].notna()].sort_values(T, kind="stable")   # as groupby, which drops NaN keys
    keys, group = np.unique(frame[T].to_numpy(dtype="float64"), return_inverse=True)
    values = frame["value"].to_numpy(dtype="float64")
    count, (q1, med, q3) = _group_quantiles(values, group, len(keys), (0.25, 0.5, 0.75))
    iqr = q3 - q1
    lo, hi = q1 - test.k * iqr, q3 + test.k * iqr
    r_lo, r_hi, r_med, r_iqr = lo[group], hi[group], med[group], iqr[group]
    with np.errstate(invalid="ignore"):
        beyond = np.where(values > r_hi, values - r_hi, np.where(values < r_lo, r_lo - values, 0.0))
        flagged = ((beyond > 0) & (np.abs(values - r_med) >= test.min_deviation) & np.isfinite(values)
                   & (count[group] >= max(test.min_n, 1)))
    with np.errstate(divide="ignore", invalid="ignore"):
        score = np.where(r_iqr > _IQR_EPS, beyond / np.where(r_iqr > _IQR_EPS, r_iqr, 1.0), np.inf)
    pick = np.flatnonzero(flagged)
    return pd.DataFrame({T: keys[group[pick]], "metric": metric,
                         "drone": frame["drone"].to_numpy()[pick].astype("int64"), "value": values[pick],
                         "score": score[pick], "median": r_med[pick], "iqr": r_iqr[pick],
                         "lo": r_lo[pick], "hi": r_hi[pick]})


def detect(timeline: pd.DataFrame, tests: dict[str, OutlierTest]) -> pd.DataFrame:
    """Every flagged (window, metric, drone): t_u, metric, drone, value, score, median, iqr, lo, hi.

    Each window of each metric is tested on its own (:func:`outlier_scores`); the windows are
    computed together, which for a long run is thousands of windows in a few array operations.
    """
    cols = [T, "metric", "drone", "value", "score", "median", "iqr", "lo", "hi"]
    timeline = timeline[timeline["metric"].isin(list(tests))]
    parts = [_detect_metric(frame, str(metric), tests[metric])
             for metric, frame in timeline.groupby("metric", sort=True)]
    parts = [p for p in parts if len(p)]
    if not parts:
        return pd.DataFrame(columns=cols)
    out = pd.concat(parts, ignore_index=True)
    out["metric"] = out["metric"].astype("str")
    return out[cols]


def fault_onset(events: pd.DataFrame) -> FaultOnset | None:
    """The first ``fault`` event named ``*_start`` (unified time), with its target from the data."""
    starts = events[(events["kind"] == "fault") & events["name"].str.endswith("_start")].sort_values(T)
    if starts.empty:
        return None
    row = starts.iloc[0]
    try:
        data = json.loads(row["data"]) if row["data"] else {}
    except ValueError:
        data = {}
    target = data.get("target") if isinstance(data, dict) else None
    target = int(target) if isinstance(target, int | float) and not isinstance(target, bool) else None
    return FaultOnset(float(row[T]), str(row["name"]), target, data if isinstance(data, dict) else {})


def _first(flags: pd.DataFrame) -> pd.Series | None:
    if flags.empty:
        return None
    first_t = flags[T].min()
    win = flags[flags[T] == first_t].assign(dev=lambda f: (f["value"] - f["median"]).abs())
    return win.sort_values(["score", "dev", "drone"], ascending=[False, False, True]).iloc[0]


def diagnose(flags: pd.DataFrame, onset: FaultOnset) -> pd.DataFrame:
    """t_f, tau_d, Sigma_a, flagged drone and target hit, per metric and for ``any`` metric."""
    after = flags[flags[T] > onset.t_u]
    rows = []
    for metric in [*sorted(after["metric"].unique()), "any"]:
        mine = after if metric == "any" else after[after["metric"] == metric]
        first = _first(mine)
        if first is None:
            continue
        on_target = mine[mine["drone"] == onset.target] if onset.target is not None else mine.iloc[0:0]
        rows.append({
            "metric": metric, "detected_metric": first["metric"],
            "t_f_s": float(first[T] - onset.t_u), "tau_d": float(first["value"]),
            "sigma_a": float(first["score"]), "drone": int(first["drone"]),
            "target": onset.target,
            "is_target": onset.target is not None and int(first["drone"]) == onset.target,
            "target_t_f_s": float(on_target[T].min() - onset.t_u) if len(on_target) else np.nan,
            "fault": onset.name, "onset_u": onset.t_u,
        })
    return pd.DataFrame(rows)


def diagnosis_scalars(diagnosis: pd.DataFrame) -> dict[str, float]:
    """Flat ``<metric>_t_f_s`` / ``_tau_d`` / ``_sigma_a`` / ``_is_target`` (``any`` -> ``anomaly``)."""
    out: dict[str, float] = {}
    for row in diagnosis.itertuples(index=False):
        prefix = "anomaly" if row.metric == "any" else row.metric
        out |= {f"{prefix}_t_f_s": row.t_f_s, f"{prefix}_tau_d": row.tau_d,
                f"{prefix}_sigma_a": row.sigma_a, f"{prefix}_is_target": float(row.is_target)}
    return out
