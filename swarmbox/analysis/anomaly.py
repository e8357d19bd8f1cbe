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


def detect(timeline: pd.DataFrame, tests: dict[str, OutlierTest]) -> pd.DataFrame:
    """Every flagged (window, metric, drone): t_u, metric, drone, value, score, median, iqr, lo, hi."""
    rows = []
    timeline = timeline[timeline["metric"].isin(list(tests))]
    for (metric, t_u), group in timeline.groupby(["metric", T], sort=True):
        scores, fences = outlier_scores(group["value"].to_numpy(), tests[metric])
        for drone, value, score in zip(group["drone"], group["value"], scores, strict=True):
            if not np.isnan(score):
                stats = {k: float(fences[k]) for k in ("median", "iqr", "lo", "hi")}
                rows.append({T: t_u, "metric": metric, "drone": int(drone), "value": float(value),
                             "score": float(score), **stats})
    cols = [T, "metric", "drone", "value", "score", "median", "iqr", "lo", "hi"]
    return pd.DataFrame(rows, columns=cols)


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
