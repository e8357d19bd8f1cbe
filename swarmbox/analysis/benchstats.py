"""Intervals and held-out calibration for the diagnosis benchmark (:mod:`.detection`'s rows).

A detection rate of k detected runs out of n gets its exact (Clopper–Pearson) interval: 3 of 3 has
a 95 % lower bound of 29 %, so "detected in >= 90 % of runs" cannot be claimed from 3 runs. A
false-alarm count k over T drone-hours gets the exact Poisson interval on the rate: 0 alarms in
2.4 drone-hours has a 95 % upper bound of 1.5 per drone-hour, so it does not show "<= 1".

Choosing the most sensitive detector setting per cell and reporting its rates on the same runs
flatters it: :func:`.detection.held_out_smallest` chooses on some seeds and reports on the others.
"""

from __future__ import annotations

import numpy as np
import pandas as pd
from scipy import stats

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
