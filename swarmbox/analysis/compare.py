"""Regression gate: compare two summary tables metric by metric.

Input: two CSV files as written by the analyzer, a sweep's ``tables/summary.csv`` (column ``mean``)
or a run's ``tables/metrics.csv`` (column ``value``). Rows are matched on ``metric`` plus every key
column (any column that is not a statistic, e.g. ``algo``).

Rows must overlap: two tables with no (keys, metric) row in common are not a baseline and its sweep,
and are refused (exit 2), as are tables with different key columns.

A sweep summary carries its run counts as rows (``runs_attempted``, ``runs_ok``, ``runs_aborted``,
``runs_failed``, ``runs_interrupted``, ``success_rate``), compared exactly by default: a run lost, or
one more aborted or failed, is a regression. A metric whose mean stands on fewer values than in the
baseline (its ``n`` dropped) is ``fewer``, also a regression.

Per row, with baseline b, current c and tolerance tol = max(atol, rtol * |b|) (atol alone when b is
infinite; |b|, so a negative baseline gets the same band as a positive one): for a *lower is better*
metric, c - b > tol is ``worse`` and b - c > tol ``better``; mirrored
for *higher is better*; a metric without a direction is ``changed`` beyond its tolerance (a
regression: nobody said a change of it is harmless) unless the tolerance file marks it
``informational``, then ``info``. A row present in the baseline but absent or NaN in the current
table is ``missing`` / ``nan``. ``worse``, ``changed``, ``fewer``, ``missing`` and ``nan`` are
regressions (``missing`` can be allowed).

A baseline directory carries its own tolerances: without ``--config``, a ``tolerances.yaml`` next to
the baseline CSV is used.

Tolerances and directions, by precedence: the YAML file's ``metrics.<name>`` entry; the ``--rtol`` /
``--atol`` flags; the built-in defaults below; ``default`` (rtol 0.05, atol 1e-9). Directions come
from the YAML, then the baseline's ``direction`` column, then the built-in catalog. YAML layout::

    default: {rtol: 0.05, atol: 0.0}
    allow_missing: false
    metrics:
      mission_duration_s: {rtol: 0.1, atol: 0.5}
      my_metric_mean: {direction: higher}
      busy_s_mean: {informational: true}   # no direction: report a change, never fail on it
      real_time_factor: {rtol: 0.3}    # an entry without ``ignore`` compares a metric ignored by default
      delivery_wait_s_mean: {mode: exact}        # rtol = atol = 0 (deterministic backends)
      distance_h_m_mean: {mode: float-noise}     # rtol 1e-9, atol 1e-12: summation-order noise only
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import pandas as pd
import yaml

from swarmbox.analysis.catalog import RUN_COUNTS, Direction, direction_of

STAT_COLUMNS = {"metric", "n", "n_runs", "mean", "value", "median", "std", "ci_low", "ci_high", "direction",
                "unit", "note", "kind"}   # note, kind: annotations (CI withheld, machine figure)
REGRESSIONS = {"worse", "changed", "fewer", "missing", "nan"}
NO_COMMON_ROW = "no (group, metric) in common — is this the baseline for this sweep?"
#: ``mode`` of a tolerance entry: (rtol, atol) it stands for.
MODES = {"exact": (0.0, 0.0), "float-noise": (1e-9, 1e-12)}
#: Name of the tolerance file that travels with a baseline.
BASELINE_TOLERANCES = "tolerances.yaml"


class CompareInputError(ValueError):
    """A summary table or tolerance file that cannot be used."""


@dataclass(frozen=True, slots=True)
class Tolerance:
    rtol: float = 0.05
    atol: float = 1e-9
    direction: Direction = None
    ignore: bool = False
    informational: bool = False   # a change of a metric without direction is reported, not failed


#: Built-in tolerances: what noise or run-to-run variation is acceptable for each metric.
BUILTIN_TOLERANCES: dict[str, Tolerance] = {
    "mission_duration_s": Tolerance(0.05, 0.5), "distance_h_m_mean": Tolerance(0.05, 1.0),
    "distance_h_m_std": Tolerance(0.10, 1.0), "distance_h_m_total": Tolerance(0.05, 1.0),
    "distance_3d_m_mean": Tolerance(0.05, 1.0), "distance_3d_m_std": Tolerance(0.10, 1.0),
    "busy_s_std": Tolerance(0.10, 0.5), "utilization_mean": Tolerance(0.0, 0.02),
    "utilization_std": Tolerance(0.0, 0.02), "idle_s_mean": Tolerance(0.10, 0.5),
    "completed_fraction": Tolerance(0.0, 1e-9), "latency_ms_mean": Tolerance(0.10, 1.0),
    "latency_ms_p50": Tolerance(0.10, 1.0), "latency_ms_p95": Tolerance(0.10, 2.0),
    "latency_ms_max": Tolerance(0.25, 5.0), "loss_ratio": Tolerance(0.0, 0.02),
    "tx_bytes_per_s_mean": Tolerance(0.10, 0.0), "discrepancy_h_m_mean": Tolerance(0.10, 0.1),
    "discrepancy_h_m_max": Tolerance(0.10, 0.2), "min_separation_m": Tolerance(0.10, 0.2),
    "time_below_separation_s": Tolerance(0.0, 0.1), "collision_events": Tolerance(0.0, 1e-9),
    "safety_events": Tolerance(0.0, 1e-9), "order_mean": Tolerance(0.0, 0.05),
    "connectivity_mean": Tolerance(0.05, 0.05), "connectivity_min": Tolerance(0.0, 0.05),
    # machine-dependent: compared only when a tolerance file names them
    "real_time_factor": Tolerance(0.5, 0.0, ignore=True), "wall_time_s": Tolerance(ignore=True),
    "anomaly_t_f_s": Tolerance(0.0, 0.5),
    # run counts: exact; fewer runs, fewer ok or more aborted/failed/interrupted is a regression
    **{m: Tolerance(0.0, 0.0, d) for m, d in RUN_COUNTS.items()},
}


@dataclass(frozen=True)
class CompareConfig:
    default: Tolerance = Tolerance()
    metrics: dict[str, Tolerance] | None = None
    rtol: float | None = None        # command-line override for every metric without a YAML entry
    atol: float | None = None
    allow_missing: bool = False
    ignore: tuple[str, ...] = ()

    def tolerance(self, metric: str, baseline_direction: str) -> Tolerance:
        explicit = (self.metrics or {}).get(metric)
        tol = explicit or BUILTIN_TOLERANCES.get(metric, self.default)
        if explicit is None and self.rtol is not None:
            tol = replace(tol, rtol=self.rtol)
        if explicit is None and self.atol is not None:
            tol = replace(tol, atol=self.atol)
        direction = (explicit.direction if explicit else None) or _direction(baseline_direction) \
            or direction_of(metric)
        return replace(tol, direction=direction, ignore=tol.ignore or metric in self.ignore)


def _direction(value: Any) -> Direction:
    return value if value in ("lower", "higher") else None


def _tolerance(entry: Any, where: str, base: Tolerance | None = None) -> Tolerance:
    if not isinstance(entry, dict):
        raise CompareInputError(f"{where}: expected a mapping, got {entry!r}")
    unknown = set(entry) - {"rtol", "atol", "direction", "ignore", "informational", "mode"}
    if unknown:
        raise CompareInputError(f"{where}: unknown key(s) {sorted(unknown)}")
    if "mode" in entry:
        if entry["mode"] not in MODES or {"rtol", "atol"} & set(entry):
            raise CompareInputError(f"{where}: mode must be one of {sorted(MODES)}, without rtol/atol")
        entry = {**entry, **dict(zip(("rtol", "atol"), MODES[entry["mode"]], strict=True))}
    if entry.get("direction") not in (None, "lower", "higher"):
        raise CompareInputError(f"{where}: direction must be 'lower' or 'higher'")
    try:
        base = base or Tolerance()
        return Tolerance(float(entry.get("rtol", base.rtol)), float(entry.get("atol", base.atol)),
                         entry.get("direction"), bool(entry.get("ignore", False)),
                         bool(entry.get("informational", base.informational)))
    except (TypeError, ValueError) as exc:
        raise CompareInputError(f"{where}: rtol and atol must be numbers") from exc


def load_config(path: Path | None, **overrides: Any) -> CompareConfig:
    """Tolerance configuration from an optional YAML file plus command-line overrides."""
    raw: dict[str, Any] = {}
    if path is not None:
        try:
            raw = yaml.safe_load(Path(path).read_text()) or {}
        except (OSError, yaml.YAMLError) as exc:
            raise CompareInputError(f"{path}: cannot read tolerance file ({exc})") from exc
        if not isinstance(raw, dict) or set(raw) - {"default", "metrics", "allow_missing"}:
            raise CompareInputError(f"{path}: top-level keys must be among default, metrics, allow_missing")
    default = _tolerance(raw.get("default", {}), "default")
    metrics = {str(k): _tolerance(v, f"metrics.{k}", BUILTIN_TOLERANCES.get(str(k), default))
               for k, v in (raw.get("metrics") or {}).items()}
    allow = bool(overrides.pop("allow_missing", False) or raw.get("allow_missing", False))
    return CompareConfig(default, metrics, allow_missing=allow, **overrides)


def baseline_tolerances(baseline: Path) -> Path | None:
    """The tolerance file shipped with a baseline (``tolerances.yaml`` beside it), if any."""
    path = Path(baseline).parent / BASELINE_TOLERANCES
    return path if path.is_file() else None


def load_summary(path: Path) -> pd.DataFrame:
    """A summary table with a ``metric`` column and a ``value`` column (from ``mean`` or ``value``)."""
    try:
        frame = pd.read_csv(path)
    except FileNotFoundError as exc:
        raise CompareInputError(f"{path}: no such file") from exc
    except (OSError, ValueError, pd.errors.ParserError) as exc:
        raise CompareInputError(f"{path}: not a readable CSV ({exc})") from exc
    if "metric" not in frame.columns or not ({"mean", "value"} & set(frame.columns)):
        raise CompareInputError(f"{path}: needs a 'metric' column and a 'mean' or 'value' column "
                                f"(found {list(frame.columns)})")
    value = frame["mean"] if "mean" in frame.columns else frame["value"]
    frame = frame.assign(value=pd.to_numeric(value, errors="coerce"))
    keys = key_columns(frame)
    frame[keys] = frame[keys].astype("str")
    if frame.duplicated([*keys, "metric"]).any():
        raise CompareInputError(f"{path}: duplicate rows for the same {[*keys, 'metric']}")
    return frame


def key_columns(frame: pd.DataFrame) -> list[str]:
    return [c for c in frame.columns if c not in STAT_COLUMNS]


def verdict(base: float, cur: float, tol: Tolerance) -> str:
    if tol.ignore:
        return "ignored"
    if math.isnan(base):
        return "ok" if math.isnan(cur) else "new"
    if math.isnan(cur):
        return "nan"
    if base == cur:
        return "ok"
    allowed = max(tol.atol, tol.rtol * abs(base)) if math.isfinite(base) else tol.atol
    delta = cur - base
    if tol.direction is None:
        return "ok" if abs(delta) <= allowed else "info" if tol.informational else "changed"
    gain = delta if tol.direction == "higher" else -delta
    return "better" if gain > allowed else "worse" if gain < -allowed else "ok"


def compare(baseline: pd.DataFrame, current: pd.DataFrame, config: CompareConfig) -> pd.DataFrame:
    """Verdict per (keys, metric): keys, metric, baseline, current, delta, tolerance, direction, verdict.

    Raises :class:`CompareInputError` when the key columns differ or no row is in both tables.
    """
    keys = key_columns(baseline)
    if set(keys) != set(key_columns(current)):
        raise CompareInputError(f"{NO_COMMON_ROW} (the baseline's groups are keyed by {keys}, the current "
                                f"table's by {key_columns(current)})")
    counts = ["n"] if "n" in baseline and "n" in current else []
    base = baseline[[*keys, "metric", "value", *counts] + (["direction"] if "direction" in baseline else [])]
    merged = base.merge(current[[*keys, "metric", "value", *counts]], on=[*keys, "metric"], how="outer",
                        suffixes=("_base", "_cur"), indicator=True)
    if not (merged["_merge"] == "both").any():
        raise CompareInputError(NO_COMMON_ROW)
    rows = []
    for row in merged.to_dict("records"):
        tol = config.tolerance(row["metric"], row.get("direction"))
        b, c = float(row["value_base"]), float(row["value_cur"])
        if row["_merge"] == "left_only":
            result = "ignored" if tol.ignore else "ok" if config.allow_missing else "missing"
        elif row["_merge"] == "right_only":
            result = "new"
        else:
            result = verdict(b, c, tol)
            fewer = counts and row["n_cur"] < row["n_base"]   # the mean stands on fewer values
            if fewer and result not in ("ignored", "worse", "changed", "nan"):
                result = "fewer"
        allowed = max(tol.atol, tol.rtol * abs(b)) if math.isfinite(b) else tol.atol
        rows.append({**{k: row[k] for k in keys}, "metric": row["metric"], "baseline": b, "current": c,
                     "delta": c - b, "tolerance": allowed, "direction": tol.direction or "",
                     **({"n_baseline": row["n_base"], "n_current": row["n_cur"]} if counts else {}),
                     "verdict": result})
    return pd.DataFrame(rows)


def regressed(verdicts: pd.DataFrame) -> list[str]:
    """Names of the metrics with a regression verdict, run counts first."""
    names = verdicts.loc[verdicts["verdict"].isin(REGRESSIONS), "metric"] if len(verdicts) else []
    unique = list(dict.fromkeys(names))
    order = list(RUN_COUNTS)
    return sorted(unique, key=lambda m: order.index(m) if m in RUN_COUNTS else len(order) + unique.index(m))


def has_regression(verdicts: pd.DataFrame) -> bool:
    return bool(verdicts["verdict"].isin(REGRESSIONS).any()) if len(verdicts) else False
