"""Intervals and held-out calibration for the diagnosis benchmark (:mod:`.detection`'s rows).

A detection rate of k detected runs out of n gets its exact (Clopper–Pearson) interval: 3 of 3 has
a 95 % lower bound of 29 %, so "detected in >= 90 % of runs" cannot be claimed from 3 runs. A
false-alarm count k over T drone-hours gets the exact Poisson interval on the rate: 0 alarms in
2.4 drone-hours has a 95 % upper bound of 1.5 per drone-hour, so it does not show "<= 1".

Choosing the most sensitive detector setting per cell and reporting its rates on the same runs
flatters it. :func:`held_out_smallest` splits the runs by seed: the setting is chosen on the
calibration seeds only, and every rate is reported on the other seeds.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence

import numpy as np
import pandas as pd
from scipy import stats

from swarmbox.analysis import detection

LEVEL = 0.95


def binomial_ci(k: int, n: int, level: float = LEVEL) -> tuple[float, float]:
    """Exact (Clopper–Pearson) interval of a proportion k / n; (nan, nan) when n = 0."""
    if n <= 0:
        return np.nan, np.nan
    a = 1.0 - level
    low = 0.0 if k == 0 else float(stats.beta.ppf(a / 2, k, n - k + 1))
    high = 1.0 if k == n else float(stats.beta.ppf(1 - a / 2, k + 1, n - k))
    return low, high


def poisson_rate_ci(k: int, exposure: float, level: float = LEVEL) -> tuple[float, float]:
    """Exact interval of a Poisson rate: k events over ``exposure`` (e.g. drone-hours)."""
    if not exposure > 0:
        return np.nan, np.nan
    a = 1.0 - level
    low = 0.0 if k == 0 else float(stats.chi2.ppf(a / 2, 2 * k)) / 2
    high = float(stats.chi2.ppf(1 - a / 2, 2 * k + 2)) / 2
    return low / exposure, high / exposure


def with_detection_ci(det: pd.DataFrame, level: float = LEVEL) -> pd.DataFrame:
    """``det`` (from :func:`.detection.detection_rates`) plus ``detection_ci_low/high``."""
    ci = [binomial_ci(int(k), int(n), level) for k, n in zip(det["detected"], det["runs"], strict=True)]
    return det.assign(detection_ci_low=[c[0] for c in ci], detection_ci_high=[c[1] for c in ci])


def with_false_alarm_ci(fa: pd.DataFrame, level: float = LEVEL) -> pd.DataFrame:
    """``fa`` (from :func:`.detection.false_alarm_rates`) plus ``fa_ci_low/high`` per drone-hour."""
    ci = [poisson_rate_ci(int(k), float(t), level)
          for k, t in zip(fa["false_alarms"], fa["healthy_drone_h"], strict=True)]
    return fa.assign(fa_ci_low=[c[0] for c in ci], fa_ci_high=[c[1] for c in ci])


def split_by_seed(rows: pd.DataFrame, calibration_seeds: Iterable[int]) -> tuple[pd.DataFrame, pd.DataFrame]:
    """(calibration rows, held-out rows): a run belongs to one side by its seed."""
    calib = rows["seed"].isin(set(calibration_seeds))
    return rows[calib], rows[~calib]


def held_out_smallest(rows: pd.DataFrame, calibration_seeds: Iterable[int], min_rate: float = 0.9,
                      max_fa: float = 1.0, by: Sequence[str] = ("n_drones", "network"),
                      level: float = LEVEL) -> pd.DataFrame:
    """Per detector, group and fault: the setting chosen on the calibration seeds (most sensitive with
    <= ``max_fa`` false alarms per drone-hour there, as :func:`.detection.smallest_detected`), and
    on the held-out seeds, with that setting: the smallest magnitude detected in >= ``min_rate`` of
    the runs, its detected/runs with the exact interval, and the false-alarm count, drone-hours and
    exact rate interval."""
    calib, test = split_by_seed(rows, calibration_seeds)
    if calib.empty or test.empty:
        raise ValueError("both the calibration and the held-out seeds need runs")
    chosen = detection.smallest_detected(detection.detection_rates(calib, by),
                                         detection.false_alarm_rates(calib, by), min_rate, max_fa, by)
    det = with_detection_ci(detection.detection_rates(test, by), level)
    fa = with_false_alarm_ci(detection.false_alarm_rates(test, by), level)
    setting = [c for c in detection.SETTING if c != "detector"]
    out = []
    for _, c in chosen.iterrows():
        key = {k: c[k] for k in ("detector", *by)}
        match = {**key, **{k: _setting_of(calib, c, k) for k in setting}}
        d = det[_rows_matching(det, {**match, "fault": c["fault"]})].sort_values("magnitude")
        f = fa[_rows_matching(fa, match)]
        good = d[d["detection_rate"] >= min_rate]
        hit = good.iloc[0] if len(good) else None
        out.append({**key, "fault": c["fault"], **{k: match[k] for k in setting},
                    "calibration_magnitude": c["smallest_magnitude"],
                    "smallest_magnitude": hit["magnitude"] if hit is not None else np.nan,
                    "detected": f"{int(hit['detected'])}/{int(hit['runs'])}" if hit is not None else "",
                    "detection_ci_low": hit["detection_ci_low"] if hit is not None else np.nan,
                    "detection_ci_high": hit["detection_ci_high"] if hit is not None else np.nan,
                    "false_alarms": int(f["false_alarms"].sum()),
                    "healthy_drone_h": float(f["healthy_drone_h"].sum()),
                    "fa_ci_high": float(f["fa_ci_high"].iloc[0]) if len(f) == 1 else np.nan})
    return pd.DataFrame(out)


def _setting_of(calib: pd.DataFrame, chosen: pd.Series, column: str):
    """The chosen setting's value of ``column`` (``smallest_detected`` keeps rule and scale only)."""
    if column in chosen.index:
        return chosen[column]
    same = calib[(calib["detector"] == chosen["detector"]) & (calib["rule"] == chosen["rule"])
                 & (calib["threshold_scale"] == chosen["threshold_scale"])]
    values = same[column].unique()
    if len(values) != 1:
        raise ValueError(f"setting column {column} is ambiguous for {chosen['rule']} "
                         f"x{chosen['threshold_scale']}")
    return values[0]


def _rows_matching(frame: pd.DataFrame, values: dict) -> pd.Series:
    mask = pd.Series(True, index=frame.index)
    for k, v in values.items():
        mask &= frame[k] == v
    return mask
