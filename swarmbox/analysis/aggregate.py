"""Aggregates across tasks (missions, datasets): interquartile mean with stratified-bootstrap CIs,
probability of improvement and performance profiles — the methodology of Agarwal et al., "Deep RL at
the edge of the statistical precipice" (NeurIPS 2021, the ``rliable`` library), on SwarmBox metrics.

Scores. Metrics of different tasks have different scales (a 100-package mission takes longer than a
15-package one), so each run's value is scored within its task: ``score = (v - worst) / (best - worst)``
over every run of every algorithm on that task, oriented by the metric's direction, so 1 is the best
run on the task and 0 the worst (all equal: 1). A run that did not end ok, or has no value, scores 0: a
failure never helps an algorithm. Scores are relative to the algorithms in the study.

- IQM: mean of the middle 50 % of an algorithm's scores over all its runs and tasks
  (``scipy.stats.trim_mean(x, 0.25)``), robust to a few outlier tasks, less noisy than the median.
- CI: stratified bootstrap — runs are resampled within each task, keeping every task in every resample;
  with one run per task (a deterministic simulator, or one seed per dataset) the tasks themselves are
  resampled. Percentile interval, ``n_boot`` resamples from a ``numpy.random.Generator`` seeded from
  ``seed`` and the (metric, algorithm) names (never the global RNG).
- Probability of improvement P(X > Y): per task, the Mann-Whitney probability that a run of X scores
  above a run of Y (ties count half), averaged over tasks; CI from the same bootstrap of tasks.
- Performance profile: share of an algorithm's runs whose score exceeds tau, for tau in [0, 1].

Why not the ``rliable`` package: it pulls ``arch``, ``statsmodels`` and ``absl`` into the install for
a few dozen lines of arithmetic, and its bootstrap draws from numpy's global random state, which the
project never uses (every random draw here comes from a seeded Generator).
"""

from __future__ import annotations

import itertools
import zlib

import numpy as np
import pandas as pd
from scipy import stats

from swarmbox.analysis.catalog import Direction

TAUS = np.linspace(0.0, 1.0, 101)
AGGREGATE_COLUMNS = ["metric", "algorithm", "n_tasks", "n_runs", "iqm", "ci_low", "ci_high", "mean_score",
                     "resampled"]
IMPROVEMENT_COLUMNS = ["metric", "x", "y", "p_improvement", "ci_low", "ci_high", "n_tasks"]


def _rng(seed: int, *key: str) -> np.random.Generator:
    return np.random.default_rng(np.random.SeedSequence([seed, zlib.crc32("|".join(key).encode())]))


def scores(runs: pd.DataFrame, metric: str, direction: Direction, algorithm: str, task: str) -> pd.DataFrame:
    """Columns algorithm, task, score: every attempted run scored within its task (non-ok or NaN: 0)."""
    value = runs[metric].where(runs["status"] == "ok").astype("float64")
    signed = value if direction == "higher" else -value
    by_task = signed.groupby(runs[task])
    best, worst = by_task.transform("max"), by_task.transform("min")
    span = (best - worst).to_numpy()
    score = np.where(span > 0, (signed - worst).to_numpy() / np.where(span > 0, span, 1.0), 1.0)
    score = np.where(np.isfinite(signed.to_numpy()), score, 0.0)
    return pd.DataFrame({"algorithm": runs[algorithm].to_numpy(), "task": runs[task].to_numpy(),
                         "score": score})


def iqm(values: np.ndarray) -> float:
    return float(stats.trim_mean(values, 0.25)) if len(values) else np.nan


def _boot_samples(per_task: list[np.ndarray], rng: np.random.Generator,
                  n_boot: int) -> tuple[np.ndarray, str]:
    """(n_boot, n_runs) stratified resamples: runs within each task, or, with one run per task, the tasks."""
    if any(len(t) > 1 for t in per_task):
        cols = [t[rng.integers(0, len(t), (n_boot, len(t)))] for t in per_task]
        return np.hstack(cols), "runs within tasks"
    singles = np.concatenate(per_task)
    return singles[rng.integers(0, len(singles), (n_boot, len(singles)))], "tasks"


def iqm_ci(per_task: list[np.ndarray], rng: np.random.Generator, n_boot: int,
           level: float) -> tuple[float, float, str]:
    """Stratified-bootstrap percentile CI of the IQM, and what was resampled."""
    samples, how = _boot_samples(per_task, rng, n_boot)
    boot = stats.trim_mean(samples, 0.25, axis=1)
    alpha = (1.0 - level) / 2
    lo, hi = np.quantile(boot, [alpha, 1.0 - alpha])
    return float(lo), float(hi), how


def _p_per_task(x: list[np.ndarray], y: list[np.ndarray]) -> np.ndarray:
    """Per task, P(a run of x scores above a run of y), ties counting half."""
    return np.array([float(np.mean((a[:, None] > b[None, :]) + 0.5 * (a[:, None] == b[None, :])))
                     for a, b in zip(x, y, strict=True)])


def aggregate(runs: pd.DataFrame, metrics: dict[str, Direction], algorithm: str, task: str, seed: int = 0,
              n_boot: int = 2000, level: float = 0.95) -> tuple[pd.DataFrame, pd.DataFrame, pd.DataFrame]:
    """(IQM table, probability-of-improvement table, performance profiles) over the tasks every
    algorithm was run on. ``metrics``: metric -> direction ("lower"/"higher")."""
    common = _common_tasks(runs, algorithm, task)
    runs = runs[runs[task].isin(common)]
    agg, improve, profiles = [], [], []
    for metric, direction in metrics.items():
        if metric not in runs:
            continue
        scored = scores(runs, metric, direction, algorithm, task)
        per = {a: [g.loc[g["task"] == t, "score"].to_numpy() for t in common]
               for a, g in scored.groupby("algorithm")}
        for a, tasks in per.items():
            lo, hi, how = iqm_ci(tasks, _rng(seed, metric, str(a)), n_boot, level)
            pooled = np.concatenate(tasks)
            agg.append({"metric": metric, "algorithm": a, "n_tasks": len(tasks), "n_runs": len(pooled),
                        "iqm": iqm(pooled), "ci_low": lo, "ci_high": hi, "mean_score": float(pooled.mean()),
                        "resampled": how})
            profiles += [{"metric": metric, "algorithm": a, "tau": tau,
                          "share_above": float((pooled > tau).mean())} for tau in TAUS]
        improve += _improvements(per, metric, seed, n_boot, level)
    return (pd.DataFrame(agg, columns=AGGREGATE_COLUMNS), pd.DataFrame(improve, columns=IMPROVEMENT_COLUMNS),
            pd.DataFrame(profiles, columns=["metric", "algorithm", "tau", "share_above"]))


def _improvements(per: dict, metric: str, seed: int, n_boot: int, level: float) -> list[dict]:
    """P(X > Y) for every ordered pair, with a percentile CI over resampled tasks."""
    rows = []
    alpha = (1.0 - level) / 2
    for x, y in itertools.permutations(sorted(per), 2):
        p = _p_per_task(per[x], per[y])
        if not p.size:
            continue
        boot = p[_rng(seed, metric, str(x), str(y)).integers(0, p.size, (n_boot, p.size))].mean(axis=1)
        lo, hi = np.quantile(boot, [alpha, 1.0 - alpha])
        rows.append({"metric": metric, "x": x, "y": y, "p_improvement": float(p.mean()),
                     "ci_low": float(lo), "ci_high": float(hi), "n_tasks": int(p.size)})
    return rows


def _common_tasks(runs: pd.DataFrame, algorithm: str, task: str) -> list:
    """Tasks every algorithm has at least one run on (sorted)."""
    sets = [set(g[task]) for _, g in runs.groupby(algorithm)]
    return sorted(set.intersection(*sets), key=str) if sets else []
