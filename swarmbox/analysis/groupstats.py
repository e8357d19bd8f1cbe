"""Per-group statistics of a sweep: denominators, summary with bootstrap CIs, paired comparison, ranks.

Groups are the sweep :class:`~swarmbox.analysis.identity.Design`'s keys (compared factor + strata).
Definitions (n < ``MIN_N_CI`` rule, seeded bootstrap per cell, how aborted runs enter): docs/analysis.md.
"""

from __future__ import annotations

import warnings
import zlib

import numpy as np
import pandas as pd
from scipy import stats

from swarmbox.analysis.catalog import (
    COMPLETION_METRICS,
    MACHINE_METRICS,
    RUN_COUNTS,
    Direction,
    direction_of,
    unit_of,
)
from swarmbox.analysis.identity import Design, labels

MIN_N_CI = 5   # fewer values (or pairs): no bootstrap CI, no test
OUTCOMES = ("ok", "aborted", "failed", "interrupted")
SUMMARY_COLUMNS = ["metric", "n", "n_runs", "mean", "median", "std", "ci_low", "ci_high", "note", "direction",
                   "unit", "kind"]
PAIRED_COLUMNS = ["a", "b", "metric", "n_pairs", "mean_a", "mean_b", "diff_mean", "ci_low", "ci_high",
                  "p_wilcoxon", "note", "direction", "better"]


def rng(seed: int, *key: str) -> np.random.Generator:
    return np.random.default_rng(np.random.SeedSequence([seed, zlib.crc32("|".join(key).encode())]))


def bootstrap_ci(values: np.ndarray, gen: np.random.Generator, n_boot: int,
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
                                  method=method, vectorized=True, random_state=gen)
        lo, hi = res.confidence_interval
        if np.isfinite(lo) and np.isfinite(hi):
            return float(lo), float(hi)
    return np.nan, np.nan


def ci_note(n: int) -> str:
    return f"n={n} < {MIN_N_CI}: no CI" if 0 < n < MIN_N_CI else ("no values" if n == 0 else "")


def label(key: object) -> str:
    return "/".join(str(k) for k in key) if isinstance(key, tuple) else str(key)


def finite(series: pd.Series) -> np.ndarray:
    arr = series.to_numpy(dtype="float64")
    return arr[np.isfinite(arr)]


def _groups(runs: pd.DataFrame, keys: tuple[str, ...]):
    if not keys:
        yield {}, "all", runs
        return
    for key, group in runs.groupby(list(keys), sort=True, dropna=False):
        key = key if isinstance(key, tuple) else (key,)
        yield dict(zip(keys, key, strict=True)), label(key if len(key) > 1 else key[0]), group


def _count_row(keys: dict, metric: str, value: float, attempted: int, ci=(np.nan, np.nan), note="") -> dict:
    return {**keys, "metric": metric, "n": attempted, "n_runs": attempted, "mean": value, "median": value,
            "std": np.nan, "ci_low": ci[0], "ci_high": ci[1], "note": note,
            "direction": RUN_COUNTS[metric], "unit": "", "kind": "runs"}


def denominators(keys: dict, group: pd.DataFrame, level: float) -> list[dict]:
    """runs_attempted, runs_<outcome> and success_rate (Wilson interval) of one group."""
    attempted = len(group)
    counts = {s: int((group["status"] == s).sum()) for s in OUTCOMES}
    rows = [_count_row(keys, "runs_attempted", float(attempted), attempted)]
    rows += [_count_row(keys, f"runs_{s}", float(c), attempted) for s, c in counts.items()]
    ci = stats.binomtest(counts["ok"], attempted).proportion_ci(level, method="wilson")
    rows.append(_count_row(keys, "success_rate", counts["ok"] / attempted, attempted, (ci.low, ci.high),
                           f"{counts['ok']} of {attempted} runs ok; Wilson interval"))
    return rows


def metric_values(group: pd.DataFrame, metric: str, statuses: tuple[str, ...]) -> np.ndarray:
    """The values a metric is summarized over: runs of ``statuses``; never a mission-window metric of a
    run that did not complete (an abort ends the window early and would flatter it)."""
    chosen = group["status"].isin(statuses)
    if metric in COMPLETION_METRICS:
        chosen &= group["status"] == "ok"
    return finite(group.loc[chosen, metric]) if metric in group else np.array([])


def _note(n: int, attempted: int) -> str:
    parts = [ci_note(n)] if ci_note(n) else []
    if n < attempted:
        parts.append(f"{attempted - n} of {attempted} runs without a value (not ok, or NaN)")
    return "; ".join(parts)


def summarize(runs: pd.DataFrame, metrics: list[str], d: Design, directions: dict[str, Direction],
              units: dict[str, str], statuses: tuple[str, ...], seed: int, n_boot: int,
              level: float) -> pd.DataFrame:
    """Long summary: per group its denominators, then per metric n, mean, median, std, CI."""
    rows = []
    for keys, name, group in _groups(runs, d.keys):
        rows += denominators(keys, group, level)
        for metric in metrics:
            values = metric_values(group, metric, statuses)
            lo, hi = bootstrap_ci(values, rng(seed, name, metric), n_boot, level)
            machine = metric in MACHINE_METRICS
            rows.append({**keys, "metric": metric, "n": int(values.size), "n_runs": len(group),
                         "mean": float(values.mean()) if values.size else np.nan,
                         "median": float(np.median(values)) if values.size else np.nan,
                         "std": float(values.std(ddof=1)) if values.size > 1 else np.nan,
                         "ci_low": lo, "ci_high": hi, "note": _note(values.size, len(group)),
                         "direction": "" if machine else direction_of(metric, directions) or "",
                         "unit": unit_of(metric, units), "kind": "machine" if machine else "metric"})
    return pd.DataFrame(rows, columns=[*d.keys, *SUMMARY_COLUMNS])


def _wilcoxon(diff: np.ndarray) -> float:
    if diff.size == 0:
        return np.nan
    if np.all(diff == 0):
        return 1.0
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return float(stats.wilcoxon(diff).pvalue)


def _better(a: str, b: str, lo: float, hi: float, direction: Direction) -> str:
    if direction is None or np.isnan(lo) or lo <= 0 <= hi:
        return ""
    return b if (lo > 0) == (direction == "higher") else a


def _pair_rows(joined: pd.DataFrame, a: str, b: str, metrics: list[str], directions: dict[str, Direction],
               seed: int, n_boot: int, level: float, tag: str) -> list[dict]:
    rows = []
    for metric in metrics:
        va, vb = (joined[f"{metric}_{side}"].to_numpy(dtype="float64") for side in ("a", "b"))
        both = np.isfinite(va) & np.isfinite(vb)
        if not both.any():
            continue    # no run of a shares its seed (and the rest of its configuration) with a run of b
        va, vb = va[both], vb[both]
        diff = vb - va
        lo, hi = bootstrap_ci(diff, rng(seed, *tag, a, b, metric), n_boot, level)
        direction = direction_of(metric, directions)
        rows.append({"a": a, "b": b, "metric": metric, "n_pairs": int(diff.size), "mean_a": float(va.mean()),
                     "mean_b": float(vb.mean()), "diff_mean": float(diff.mean()), "ci_low": lo, "ci_high": hi,
                     "p_wilcoxon": _wilcoxon(diff) if diff.size >= MIN_N_CI else np.nan,
                     "note": ci_note(diff.size).replace("n=", "pairs=").replace("CI", "CI, no test"),
                     "direction": direction or "", "better": _better(a, b, lo, hi, direction)})
    return rows


def paired(runs: pd.DataFrame, metrics: list[str], d: Design, pairs: list[tuple[str, str, str]],
           not_comparable: list[tuple[str, str, str]], directions: dict[str, Direction], seed: int,
           n_boot: int, level: float) -> pd.DataFrame:
    """Paired comparison b - a of each (stratum, a, b); runs pair on seed and every other identity key.

    ``not_comparable`` (a, b, why) get one row each with the reason in ``note``.
    """
    group, stratum = labels(runs, d.group_by), labels(runs, d.strata)
    keys = ["seed", *[c for c in d.identity if c not in d.group_by]]
    compared = [m for m in metrics if m not in MACHINE_METRICS]
    rows = []
    for where, a, b in pairs:
        inside = runs[stratum == where]
        left, right = (inside[group[stratum == where] == g][keys + compared] for g in (a, b))
        joined = left.merge(right, on=keys, how="inner", suffixes=("_a", "_b"), validate="one_to_one")
        tag = (where,) if d.strata else ()
        found = _pair_rows(joined, a, b, compared, directions, seed, n_boot, level, tag) or [
            {"a": a, "b": b, "metric": "", "n_pairs": 0,
             "note": f"no pair: no run of {a} and run of {b} with the same seed both have values"}]
        rows += [{c: inside[c].iloc[0] for c in d.strata} | r for r in found]
    rows += [{"a": a, "b": b, "metric": "", "n_pairs": 0, "note": why} for a, b, why in not_comparable]
    if not rows:
        only = ", ".join(sorted(group.unique())) or "none"
        rows = [{"metric": "", "n_pairs": 0, "note": f"one group per stratum ({only}): nothing to pair"}]
    return pd.DataFrame(rows, columns=[*d.strata, *PAIRED_COLUMNS])


def _significant(values: pd.Series, digits: int = 5) -> pd.Series:
    return values.map(lambda v: float(f"{v:.{digits}g}") if np.isfinite(v) else v)


def ranks(summary: pd.DataFrame, d: Design, why_none: list[str]) -> pd.DataFrame:
    """Groups ranked per stratum and metric by mean (1 = best; means equal to 5 significant digits tie
    and share the lower rank), plus the mean rank. Strata with one group are not ranked; machine figures
    and metrics without a direction never are. An empty ranking is a one-row table saying why."""
    ranked = summary[summary["direction"].isin(["lower", "higher"]) & (summary["kind"] == "metric")].copy()
    ranked = ranked[ranked["mean"].notna()]
    ranked["group"] = labels(ranked, d.group_by) if len(ranked) else []
    ranked["stratum"] = labels(ranked, d.strata) if len(ranked) else []
    ranked = ranked[ranked.groupby(["stratum", "metric"])["group"].transform("nunique") > 1]
    if ranked.empty:
        reason = "; ".join(why_none) or "fewer than two groups with values in any stratum: nothing to rank"
        return pd.DataFrame({"note": [reason]})
    key = _significant(ranked["mean"].astype("float64"))
    ranked["key"] = np.where(ranked["direction"] == "lower", key, -key)
    ranked["rank"] = ranked.groupby(["stratum", "metric"])["key"].rank(method="min")
    index = [*d.strata, "group"]
    wide = ranked.pivot_table(index=index, columns="metric", values="rank", aggfunc="first")
    wide = wide[[m for m in dict.fromkeys(ranked["metric"]) if m in wide.columns]]
    wide["mean_rank"] = wide.mean(axis=1)
    wide = wide.reset_index().sort_values([*d.strata, "mean_rank"], kind="stable")
    wide.columns.name = None
    return wide.reset_index(drop=True)


def _cell(row: pd.Series) -> str:
    if row.get("kind") == "runs":
        value = f"{row['mean']:.4g}"
        return f"{value} [{row['ci_low']:.2g}, {row['ci_high']:.2g}]" if np.isfinite(row["ci_low"]) else value
    n, of = int(row["n"]), int(row.get("n_runs", row["n"]))
    count = f"n={n}" if n == of else f"n={n} of {of} runs"
    if n == 0:
        return f"no values ({of} runs)"
    if np.isfinite(row["ci_low"]):
        return f"{row['mean']:.4g} [{row['ci_low']:.4g}, {row['ci_high']:.4g}] ({count})"
    return f"{row['mean']:.4g} ({count}, no CI)"


def summary_wide(summary: pd.DataFrame, group_by: tuple[str, ...]) -> pd.DataFrame:
    """Metrics as rows, groups as columns, cells ``mean [ci_low, ci_high] (n=…)`` (for printing).

    ``group_by`` are the summary's key columns. Run counts come first, machine figures last.
    """
    if summary.empty:
        return summary
    cell = summary.apply(_cell, axis=1)
    frame = summary.assign(group=labels(summary, group_by), cell=cell)
    wide = frame.pivot(index="metric", columns="group", values="cell")
    kinds = dict(zip(summary["metric"], summary.get("kind", pd.Series("metric", index=summary.index)),
                     strict=False))
    rank = {"runs": 0, "metric": 1, "machine": 2}
    order = sorted(dict.fromkeys(summary["metric"]), key=lambda m: rank.get(kinds.get(m, "metric"), 1))
    out = wide.loc[order].reset_index()
    out.columns.name = None
    return out
