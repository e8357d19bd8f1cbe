"""Benchmark tables over a sweep (multirun) directory.

- ``runs``: one row per run with a readable ``run.json``: ``run`` (path relative to the sweep),
  ``status``, ``seed``, its identity (the config choices and every other override from ``run.json``, see
  :mod:`swarmbox.analysis.identity`; never parsed from directory names) and every scalar metric. Failed
  and interrupted runs and runs whose logs are incomplete are listed without metrics (they count in the
  denominators) and reported in ``problems``; unreadable ``run.json`` files and killed runs only there.
  Runs are analyzed in parallel processes. Two runs with the same identity and seed are an error.
- ``summary`` (long): per group (the compared factor, default ``algo``, plus every other key that varies:
  the strata) its run counts (``runs_attempted``, ``runs_ok``, ``runs_aborted``, ``runs_failed``,
  ``runs_interrupted``, ``success_rate`` with a Wilson interval), then per metric, over the runs whose
  status is in ``statuses`` (default ``ok``): n, the group's runs (``n_runs``), mean, median, sample std
  and a bootstrap CI of the mean (scipy BCa; none below ``MIN_N_CI`` = 5 values). Mission-window metrics
  are never taken from a run that did not complete. ``kind``: ``runs``, ``metric`` or ``machine``
  (figures of the computer: reported, never compared).
- ``paired``: per stratum, every two groups of the compared factor, runs paired on seed and the rest of
  their identity: n pairs, mean of b - a with a bootstrap CI, Wilcoxon signed-rank p-value, the better
  side when the CI excludes 0. Groups that never share a stratum get one row saying why.
- ``ranks``: per stratum and metric with a direction, groups ranked by mean, and the mean rank.
Definitions and the reasons behind them: docs/analysis.md.
"""

from __future__ import annotations

import itertools
import logging
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from pathlib import Path

import pandas as pd

from swarmbox.analysis import aggregate, groupstats
from swarmbox.analysis.catalog import MACHINE_METRICS, Direction, declared_units
from swarmbox.analysis.groupstats import (  # noqa: F401 - the sweep API re-exports them
    MIN_N_CI,
    bootstrap_ci,
    ci_note,
    summary_wide,
)
from swarmbox.analysis.groupstats import rng as _rng  # noqa: F401
from swarmbox.analysis.identity import (
    DEFAULT,
    Design,
    SweepInputError,
    check_unique,
    comparable_pairs,
    design,
    labels,
    not_comparable,
    run_identity,
)
from swarmbox.analysis.load import RunLoadError, find_runs, find_unfinished, load_run, read_manifest
from swarmbox.analysis.parallel import map_runs
from swarmbox.analysis.report import SCALAR_COLUMNS, AnalysisOptions, analyze_run

log = logging.getLogger(__name__)

ID_COLUMNS = ("run", "status", "seed")
__all__ = ["MACHINE_METRICS", "MIN_N_CI", "SweepInputError", "SweepOptions", "SweepResult", "analyze_sweep",
           "bootstrap_ci", "ci_note", "summary_wide"]


@dataclass(frozen=True)
class SweepOptions:
    group_by: tuple[str, ...] | None = None   # None: algo if it varies, else every swept key
    statuses: tuple[str, ...] = ("ok",)
    n_boot: int = 2000
    ci: float = 0.95
    seed: int = 0
    pairs: tuple[tuple[str, str], ...] | None = None   # None: every pair of groups
    #: what a task is for the aggregates across tasks (IQM, P(improvement), profiles): identity keys or
    #: "seed" (a dataset per seed, as in RQ4); None: the strata (e.g. the mission), when there are any
    tasks: tuple[str, ...] | None = None
    run: AnalysisOptions = field(default_factory=AnalysisOptions)


@dataclass
class SweepResult:
    runs: pd.DataFrame
    problems: pd.DataFrame
    summary: pd.DataFrame
    paired: pd.DataFrame
    ranks: pd.DataFrame
    directions: dict[str, Direction]
    choice_columns: list[str]   # the identity columns
    group_by: tuple[str, ...]   # the summary's key columns: compared factor, then strata
    design: Design | None = None
    units: dict[str, str] = field(default_factory=dict)
    warnings: list[str] = field(default_factory=list)   # groups that are not comparable, and why
    aggregates: Aggregates | None = None                # across tasks, when a sweep has several

    def metric_columns(self) -> list[str]:
        return metric_columns(self.runs, self.choice_columns)

    @property
    def ok_runs(self) -> int:
        return int((self.runs["status"] == "ok").sum()) if "status" in self.runs else 0


def _analyze_one(run_dir: Path, root: Path, opts: AnalysisOptions) -> dict:
    """One run's table row, problems, declared directions and units, and identity keys (in a worker).

    Every run with a readable ``run.json`` gets a row (a run that is not analyzed still counts in its
    group's denominators). Only the scalars are read, so the columns that feed none are not loaded
    (``SCALAR_COLUMNS``) and the tables that feed none are not computed (``scalars_only``).
    """
    rel = str(run_dir.relative_to(root)) if run_dir != root else "."
    out: dict = {"row": None, "problems": [], "directions": {}, "units": {}, "identity": []}
    try:
        run = load_run(run_dir, SCALAR_COLUMNS)
    except RunLoadError as exc:
        out["problems"].append({"run": rel, "severity": "skipped", "problem": str(exc)})
        return out
    identity = run_identity(run.manifest)
    out.update(identity=list(identity), units=declared_units(run.config),
               row={"run": rel, "status": run.status, "seed": run.manifest.get("seed"), **identity})
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
    out["directions"] = dict(analysis.directions)
    out["row"] |= analysis.scalars
    return out


def collect_runs(root: Path, opts: AnalysisOptions, workers: int | None = None,
                 progress: Callable[[int, int], None] | None = None,
                 ) -> tuple[pd.DataFrame, pd.DataFrame, dict, list[str], dict[str, str]]:
    """Analyze every run below ``root`` (in parallel: ``workers`` processes, default one per core).

    Returns (runs table, problems table, declared directions, identity columns, declared units), in
    the runs' order. Identity columns a run did not set hold :data:`~swarmbox.analysis.identity.DEFAULT`.
    """
    rows, problems, directions, identity, units = [], [], {}, [], {}
    for run_dir in find_unfinished(root):
        rel = str(run_dir.relative_to(root)) if run_dir != root else "."
        problems.append({"run": rel, "severity": "skipped",
                         "problem": "no run.json: the run was killed or has not finished"})
    for one in map_runs(_analyze_one, find_runs(root), root, opts, workers=workers, progress=progress):
        problems += one["problems"]
        directions |= one["directions"]
        units |= one["units"]
        identity += [c for c in one["identity"] if c not in identity]
        if one["row"] is not None:
            rows.append(one["row"])
    runs = pd.DataFrame(rows)
    for col in identity:
        runs[col] = runs[col].astype("object").where(runs[col].notna(), DEFAULT).astype("str")
    return runs, pd.DataFrame(problems, columns=["run", "severity", "problem"]), directions, identity, units


def _skip_reason(run) -> str:
    if run.status in ("failed", "interrupted"):
        return f"run {run.status}: {run.manifest.get('reason') or 'no reason given'}"
    if run.incomplete:
        return "incomplete logs: " + "; ".join(run.problems)
    return ""


def metric_columns(runs: pd.DataFrame, choice_columns: list[str]) -> list[str]:
    skip = set(ID_COLUMNS) | set(choice_columns)
    return [c for c in runs.columns if c not in skip and pd.api.types.is_numeric_dtype(runs[c])]


def analyze_sweep(root: str | Path, opts: SweepOptions | None = None, workers: int | None = None,
                  progress: Callable[[int, int], None] | None = None) -> SweepResult:
    """Analyze every run below ``root`` (``workers`` processes; ``progress(done, total)``) and tabulate.

    Raises :class:`SweepInputError` for a group-by key no run has and for two runs with the same
    identity and seed (nothing is tabulated from such a sweep).
    """
    opts = opts or SweepOptions()
    _refuse_duplicates(Path(root))
    runs, problems, directions, identity, units = collect_runs(Path(root), opts.run, workers, progress)
    empty = pd.DataFrame()
    if runs.empty:
        return SweepResult(runs, problems, empty, empty, empty, directions, identity, opts.group_by or (),
                           units=units)
    d = design(runs, identity, opts.group_by)
    check_unique(runs, d.identity)
    metrics = metric_columns(runs, identity)
    pairs, warnings = comparable_pairs(runs, d)
    pairs, refused = _requested(pairs, opts.pairs, runs, d)
    for text in warnings:
        problems.loc[len(problems)] = {"run": ".", "severity": "warning", "problem": text}
    summary = groupstats.summarize(runs, metrics, d, directions, units, opts.statuses, opts.seed, opts.n_boot,
                                   opts.ci)
    compared = groupstats.paired(runs, metrics, d, pairs, refused, directions, opts.seed, opts.n_boot,
                                 opts.ci)
    ranked = groupstats.ranks(summary, d, warnings)
    return SweepResult(runs, problems, summary, compared, ranked, directions, identity, d.keys, d, units,
                       warnings, across_tasks(runs, summary, d, opts))


def _refuse_duplicates(root: Path) -> None:
    """Two runs with the same identity and seed, found from the manifests before any run is analyzed."""
    rows = []
    for run_dir in find_runs(root):
        try:
            manifest = read_manifest(run_dir)
        except RunLoadError:
            continue          # reported as skipped by the analysis
        rel = str(run_dir.relative_to(root)) if run_dir != root else "."
        rows.append({"run": rel, "seed": manifest.get("seed"), **run_identity(manifest)})
    frame = pd.DataFrame(rows)
    if len(frame) > 1:
        identity = tuple(c for c in frame.columns if c not in ("run", "seed"))
        check_unique(frame.fillna({c: DEFAULT for c in identity}), identity)


@dataclass
class Aggregates:
    """Per-algorithm aggregates across tasks (:mod:`swarmbox.analysis.aggregate`)."""

    tasks: tuple[str, ...]
    iqm: pd.DataFrame
    improvement: pd.DataFrame
    profiles: pd.DataFrame


def across_tasks(runs: pd.DataFrame, summary: pd.DataFrame, d: Design,
                 opts: SweepOptions) -> Aggregates | None:
    """IQM, P(improvement) and performance profiles of the compared groups over the tasks, when there
    are at least two groups and two tasks; None otherwise."""
    tasks = opts.tasks if opts.tasks is not None else d.strata
    unknown = [t for t in tasks if t not in runs.columns]
    if unknown:
        raise SweepInputError(f"task key(s) {unknown} are not among the runs' seed, choices and overrides")
    if not tasks:
        return None
    frame = runs.assign(_algorithm=labels(runs, d.group_by), _task=labels(runs, tasks))
    if frame["_algorithm"].nunique() < 2 or frame["_task"].nunique() < 2:
        return None
    directed = summary[summary["kind"].eq("metric") & summary["direction"].isin(["lower", "higher"])]
    metrics = dict(zip(directed["metric"], directed["direction"], strict=False))
    iqm, improvement, profiles = aggregate.aggregate(frame, metrics, "_algorithm", "_task", opts.seed,
                                                     opts.n_boot, opts.ci)
    return Aggregates(tuple(tasks), iqm, improvement, profiles)


Triple = tuple[str, str, str]


def _requested(pairs: list[Triple], wanted: tuple[tuple[str, str], ...] | None, runs: pd.DataFrame,
               d: Design) -> tuple[list[Triple], list[Triple]]:
    """The comparable (stratum, a, b) to tabulate (all, or those asked for, in the asked order), and
    (a, b, why) for every two groups that are not comparable (or were asked for and are not)."""
    group = labels(runs, d.group_by)
    shared = {(a, b) for _, a, b in pairs} | {(b, a) for _, a, b in pairs}
    asked = wanted if wanted is not None else tuple(
        (a, b) for a, b in itertools.combinations(sorted(group.unique()), 2))
    chosen = [(s, a, b) for a, b in asked for s, x, y in pairs if {x, y} == {a, b}]
    known = set(group)
    refused = [(a, b, not_comparable(runs, d, a, b, group) if {a, b} <= known
                else f"no group {', '.join(sorted({a, b} - known))} (groups: {', '.join(sorted(known))})")
               for a, b in asked if (a, b) not in shared]
    return chosen, refused
