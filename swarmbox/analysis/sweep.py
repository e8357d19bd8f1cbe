"""Benchmark tables over a sweep (multirun) directory.

- ``runs``: one row per analyzed run: ``run`` (path relative to the sweep), ``status``, ``seed``, the
  config choices from ``run.json`` (``choices``; never parsed from directory names) and every scalar
  metric. Failed runs, directories whose ``run.json`` is unreadable and runs missing a table the
  metrics need are reported in ``problems`` and skipped. Runs are analyzed in parallel processes.
- ``summary`` (long): per group (default: ``algo``) and metric, over the runs whose status is in
  ``statuses`` (default ``ok``): n, mean, median, sample std, and a bootstrap CI of the mean from
  :func:`scipy.stats.bootstrap` (BCa; percentile when BCa is undefined, e.g. for a constant metric;
  ``n_boot`` resamples, level ``ci``). With fewer than ``MIN_N_CI`` (5) values no CI is given and
  ``note`` says so: a bootstrap over 2-4 runs reports an interval it cannot support. Every (group,
  metric) cell draws from its own ``numpy.random.Generator`` seeded with
  ``SeedSequence([seed, crc32("group|metric")])``, so the numbers do not depend on the order or
  number of other cells. NaN values are left out. ``kind`` is ``machine`` for figures of the
  computer rather than the algorithm (wall time, real-time factor): reported, never compared.
- ``paired``: for two groups a and b, runs paired on ``seed`` and every other choice (e.g. the
  mission), only where such pairs exist; per algorithm metric: n pairs, mean of b - a with a
  bootstrap CI, Wilcoxon signed-rank p-value (1.0 when every difference is 0) and which side is
  better given the metric's direction (only when the CI excludes 0). Fewer than ``MIN_N_CI`` pairs:
  no CI, no test, a note.
- ``ranks``: per algorithm metric with a direction, groups ranked by mean (1 = best; means equal to
  5 significant digits tie and share the lower rank), plus the mean rank. Machine figures are never
  ranked.
"""

from __future__ import annotations

import itertools
import logging
import warnings
import zlib
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
import pandas as pd
from scipy import stats

from swarmbox.analysis.catalog import MACHINE_METRICS, Direction, direction_of, unit_of
from swarmbox.analysis.load import RunLoadError, find_runs, find_unfinished, load_run
from swarmbox.analysis.parallel import map_runs
from swarmbox.analysis.report import SCALAR_COLUMNS, AnalysisOptions, analyze_run

log = logging.getLogger(__name__)

ID_COLUMNS = ("run", "status", "seed")
MIN_N_CI = 5   # fewer values (or pairs): no bootstrap CI, no test


@dataclass(frozen=True)
class SweepOptions:
    group_by: tuple[str, ...] = ("algo",)
    statuses: tuple[str, ...] = ("ok",)
    n_boot: int = 2000
    ci: float = 0.95
    seed: int = 0
    pairs: tuple[tuple[str, str], ...] | None = None   # None: every pair of groups
    run: AnalysisOptions = field(default_factory=AnalysisOptions)


@dataclass
class SweepResult:
    runs: pd.DataFrame
    problems: pd.DataFrame
    summary: pd.DataFrame
    paired: pd.DataFrame
    ranks: pd.DataFrame
    directions: dict[str, Direction]
    choice_columns: list[str]
    group_by: tuple[str, ...]

    def metric_columns(self) -> list[str]:
        return metric_columns(self.runs, self.choice_columns)


def _analyze_one(run_dir: Path, root: Path, opts: AnalysisOptions) -> dict:
    """One run's table row, problems, declared directions and choice names (runs in a worker).

    Only the scalars are read, so the columns that feed none are not loaded (``SCALAR_COLUMNS``) and the
    tables that feed none are not computed (``scalars_only``).
    """
    rel = str(run_dir.relative_to(root)) if run_dir != root else "."
    out: dict = {"row": None, "problems": [], "directions": {}, "choices": []}
    try:
        run = load_run(run_dir, SCALAR_COLUMNS)
    except RunLoadError as exc:
        out["problems"].append({"run": rel, "severity": "skipped", "problem": str(exc)})
        return out
    notes = [{"run": rel, "severity": "warning", "problem": p} for p in run.problems]
    skip = _skip_reason(run)
    if skip:
        out["problems"] += [{"run": rel, "severity": "skipped", "problem": skip}, *notes]
        return out
    try:
        analysis = analyze_run(run, replace(opts, scalars_only=True))
    except Exception as exc:  # noqa: BLE001 - one bad run must not stop the sweep
        log.exception("analysis of %s failed", run_dir)
        out["problems"].append({"run": rel, "severity": "skipped", "problem": f"analysis failed: {exc!r}"})
        return out
    out["problems"] += [{"run": rel, "severity": "warning", "problem": p} for p in analysis.problems]
    run_choices = {str(k): str(v) for k, v in (run.manifest.get("choices") or {}).items()}
    out.update(choices=list(run_choices), directions=dict(analysis.directions),
               row={"run": rel, "status": run.status, "seed": run.manifest.get("seed"),
                    **run_choices, **analysis.scalars})
    return out


def collect_runs(root: Path, opts: AnalysisOptions, workers: int | None = None,
                 progress: Callable[[int, int], None] | None = None,
                 ) -> tuple[pd.DataFrame, pd.DataFrame, dict, list[str]]:
    """Analyze every run below ``root`` (in parallel: ``workers`` processes, default one per core).

    Returns (runs table, problems table, declared directions, choice columns), in the runs' order.
    """
    rows, problems, directions, choices = [], [], {}, []
    for run_dir in find_unfinished(root):
        rel = str(run_dir.relative_to(root)) if run_dir != root else "."
        problems.append({"run": rel, "severity": "skipped",
                         "problem": "no run.json: the run was killed or has not finished"})
    for one in map_runs(_analyze_one, find_runs(root), root, opts, workers=workers, progress=progress):
        problems += one["problems"]
        directions |= one["directions"]
        choices += [c for c in one["choices"] if c not in choices]
        if one["row"] is not None:
            rows.append(one["row"])
    runs = pd.DataFrame(rows)
    return runs, pd.DataFrame(problems, columns=["run", "severity", "problem"]), directions, choices


def _skip_reason(run) -> str:
    if run.status in ("failed", "interrupted"):
        return f"run {run.status}: {run.manifest.get('reason') or 'no reason given'}"
    if run.incomplete:
        return "incomplete logs: " + "; ".join(run.problems)
    return ""


def metric_columns(runs: pd.DataFrame, choice_columns: list[str]) -> list[str]:
    skip = set(ID_COLUMNS) | set(choice_columns)
    return [c for c in runs.columns if c not in skip and pd.api.types.is_numeric_dtype(runs[c])]


def _rng(seed: int, *key: str) -> np.random.Generator:
    return np.random.default_rng(np.random.SeedSequence([seed, zlib.crc32("|".join(key).encode())]))


def bootstrap_ci(values: np.ndarray, rng: np.random.Generator, n_boot: int,
                 level: float) -> tuple[float, float]:
    """Bootstrap CI of the mean (scipy, BCa; percentile where BCa is undefined); NaN below MIN_N_CI."""
    values = np.asarray(values, dtype="float64")
    if values.size < MIN_N_CI:
        return np.nan, np.nan
    if np.all(values == values[0]):
        return float(values[0]), float(values[0])      # every resample has this mean
    for method in ("BCa", "percentile"):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")            # BCa's degenerate-distribution warning
            res = stats.bootstrap((values,), np.mean, n_resamples=n_boot, confidence_level=level,
                                  method=method, vectorized=True, random_state=rng)
        lo, hi = res.confidence_interval
        if np.isfinite(lo) and np.isfinite(hi):
            return float(lo), float(hi)
    return np.nan, np.nan


def ci_note(n: int) -> str:
    return f"n={n} < {MIN_N_CI}: no CI" if 0 < n < MIN_N_CI else ("no values" if n == 0 else "")


def _label(key: object) -> str:
    return "/".join(str(k) for k in key) if isinstance(key, tuple) else str(key)


def _finite(series: pd.Series) -> np.ndarray:
    arr = series.to_numpy(dtype="float64")
    return arr[np.isfinite(arr)]


def summarize(runs: pd.DataFrame, metrics: list[str], opts: SweepOptions,
              directions: dict[str, Direction]) -> pd.DataFrame:
    """Long summary table: group columns, metric, n, mean, median, std, ci_low, ci_high, direction, unit."""
    chosen = runs[runs["status"].isin(opts.statuses)] if len(runs) else runs
    rows = []
    if chosen.empty:
        return pd.DataFrame(columns=[*opts.group_by, "metric", "n", "mean", "ci_low", "ci_high"])
    for key, group in chosen.groupby(list(opts.group_by), sort=True, dropna=False):
        keys = dict(zip(opts.group_by, key if isinstance(key, tuple) else (key,), strict=True))
        for metric in metrics:
            values = _finite(group[metric])
            lo, hi = bootstrap_ci(values, _rng(opts.seed, _label(key), metric), opts.n_boot, opts.ci)
            machine = metric in MACHINE_METRICS
            rows.append({**keys, "metric": metric, "n": int(values.size),
                         "mean": float(values.mean()) if values.size else np.nan,
                         "median": float(np.median(values)) if values.size else np.nan,
                         "std": float(values.std(ddof=1)) if values.size > 1 else np.nan,
                         "ci_low": lo, "ci_high": hi, "note": ci_note(values.size),
                         "direction": "" if machine else direction_of(metric, directions) or "",
                         "unit": unit_of(metric), "kind": "machine" if machine else "metric"})
    return pd.DataFrame(rows)


def _labels(runs: pd.DataFrame, group_by: tuple[str, ...]) -> pd.Series:
    """Each run's group label ("a/b" for several group-by columns)."""
    return runs[list(group_by)].astype("str").agg("/".join, axis=1)


def _pairs_frame(runs: pd.DataFrame, labels: pd.Series, keys: list[str], metrics: list[str], a: str,
                 b: str) -> pd.DataFrame:
    """Runs of ``a`` and ``b`` paired on ``keys``: a row per pair, columns ``<metric>_a``, ``<metric>_b``."""
    left = runs[labels == a][keys + metrics]
    right = runs[labels == b][keys + metrics]
    return left.merge(right, on=keys, how="inner", suffixes=("_a", "_b"))


def _wilcoxon(diff: np.ndarray) -> float:
    if diff.size == 0:
        return np.nan
    if np.all(diff == 0):
        return 1.0
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return float(stats.wilcoxon(diff).pvalue)


PAIRED_COLUMNS = ["a", "b", "metric", "n_pairs", "mean_a", "mean_b", "diff_mean", "ci_low", "ci_high",
                  "p_wilcoxon", "note", "direction", "better"]


def paired(runs: pd.DataFrame, metrics: list[str], opts: SweepOptions, choice_columns: list[str],
           directions: dict[str, Direction]) -> pd.DataFrame:
    """Paired-by-seed comparison of every requested pair of groups (b - a)."""
    chosen = runs[runs["status"].isin(opts.statuses)] if len(runs) else runs
    if chosen.empty:
        return pd.DataFrame(columns=PAIRED_COLUMNS)
    labels = _labels(chosen, opts.group_by)
    groups = sorted(labels.unique())
    pairs = opts.pairs if opts.pairs is not None else tuple(itertools.combinations(groups, 2))
    keys = ["seed"] + [c for c in choice_columns if c not in opts.group_by]
    compared = [m for m in metrics if m not in MACHINE_METRICS]
    rows = []
    for a, b in pairs:
        joined = _pairs_frame(chosen, labels, keys, compared, a, b)
        for metric in compared:
            va, vb = (joined[f"{metric}_{side}"].to_numpy(dtype="float64") for side in ("a", "b"))
            both = np.isfinite(va) & np.isfinite(vb)
            if not both.any():
                continue    # no run of a shares its seed (and other choices) with a run of b
            va, vb = va[both], vb[both]
            diff = vb - va
            lo, hi = bootstrap_ci(diff, _rng(opts.seed, a, b, metric), opts.n_boot, opts.ci)
            direction = direction_of(metric, directions)
            rows.append({"a": a, "b": b, "metric": metric, "n_pairs": int(diff.size),
                         "mean_a": float(va.mean()), "mean_b": float(vb.mean()),
                         "diff_mean": float(diff.mean()),
                         "ci_low": lo, "ci_high": hi,
                         "p_wilcoxon": _wilcoxon(diff) if diff.size >= MIN_N_CI else np.nan,
                         "note": ci_note(diff.size).replace("n=", "pairs=").replace("CI", "CI, no test"),
                         "direction": direction or "", "better": _better(a, b, lo, hi, direction)})
    return pd.DataFrame(rows, columns=PAIRED_COLUMNS)


def _better(a: str, b: str, lo: float, hi: float, direction: Direction) -> str:
    if direction is None or np.isnan(lo) or lo <= 0 <= hi:
        return ""
    b_higher = lo > 0
    return b if b_higher == (direction == "higher") else a


def _significant(values: pd.Series, digits: int = 5) -> pd.Series:
    return values.map(lambda v: float(f"{v:.{digits}g}") if np.isfinite(v) else v)


def ranks(summary: pd.DataFrame, group_by: tuple[str, ...]) -> pd.DataFrame:
    """Groups ranked per metric by mean (1 = best); metrics without a direction are left out.

    Means equal to 5 significant digits tie (they share the lower rank).
    """
    ranked = summary[summary["direction"].isin(["lower", "higher"])
                     & ~summary["metric"].isin(MACHINE_METRICS)].copy()
    if ranked.empty:
        return pd.DataFrame(columns=[*group_by, "mean_rank"])
    ranked["group"] = ranked[list(group_by)].astype("str").agg("/".join, axis=1)
    key = _significant(ranked["mean"].astype("float64"))
    ranked["key"] = np.where(ranked["direction"] == "lower", key, -key)
    ranked["rank"] = ranked.groupby("metric")["key"].rank(method="min")
    wide = ranked.pivot(index="group", columns="metric", values="rank")
    wide = wide[list(dict.fromkeys(ranked["metric"]))]
    wide["mean_rank"] = wide.mean(axis=1)
    return wide.sort_values("mean_rank", kind="stable").reset_index()


def analyze_sweep(root: str | Path, opts: SweepOptions | None = None, workers: int | None = None,
                  progress: Callable[[int, int], None] | None = None) -> SweepResult:
    """Analyze every run below ``root`` (``workers`` processes; ``progress(done, total)``) and tabulate."""
    opts = opts or SweepOptions()
    runs, problems, directions, choice_columns = collect_runs(Path(root), opts.run, workers, progress)
    missing = [g for g in opts.group_by if g not in runs.columns]
    if runs.empty or missing:
        if missing and not runs.empty:
            problems.loc[len(problems)] = {"run": ".", "severity": "error",
                                           "problem": f"group-by column(s) {missing} not among the choices"}
        empty = pd.DataFrame()
        return SweepResult(runs, problems, empty, empty, empty, directions, choice_columns, opts.group_by)
    metrics = metric_columns(runs, choice_columns)
    summary = summarize(runs, metrics, opts, directions)
    pairs = paired(runs, metrics, opts, choice_columns, directions)
    return SweepResult(runs, problems, summary, pairs, ranks(summary, opts.group_by), directions,
                       choice_columns, opts.group_by)


def _cell(row: pd.Series) -> str:
    if np.isfinite(row["ci_low"]):
        return f"{row['mean']:.4g} [{row['ci_low']:.4g}, {row['ci_high']:.4g}]"
    return f"{row['mean']:.4g} (n={row['n']}, no CI)"


def summary_wide(summary: pd.DataFrame, group_by: tuple[str, ...]) -> pd.DataFrame:
    """Metrics as rows, groups as columns, cells ``mean [ci_low, ci_high]`` (for printing).

    Machine figures (wall time, real-time factor) come last; a cell without a CI says why.
    """
    if summary.empty:
        return summary
    cell = summary.apply(_cell, axis=1)
    frame = summary.assign(group=summary[list(group_by)].astype("str").agg("/".join, axis=1), cell=cell)
    wide = frame.pivot(index="metric", columns="group", values="cell")
    kinds = dict(zip(summary["metric"], summary.get("kind", pd.Series("metric", index=summary.index)),
                     strict=False))
    order = sorted(dict.fromkeys(summary["metric"]), key=lambda m: kinds.get(m) == "machine")
    return wide.loc[order].reset_index()
