"""Command lines: ``python -m swarmbox.analyze PATH`` and ``python -m swarmbox.compare BASE CUR``."""

from __future__ import annotations

import argparse
import logging
import sys
from pathlib import Path

import matplotlib

from swarmbox.analysis.compare import (
    CompareInputError,
    baseline_tolerances,
    compare,
    has_regression,
    load_config,
    load_summary,
    regressed,
)
from swarmbox.analysis.load import RunLoadError, find_runs, find_unfinished, load_run
from swarmbox.analysis.outputs import metrics_table, write_run, write_sweep
from swarmbox.analysis.parallel import Reporter
from swarmbox.analysis.report import ANALYZED_COLUMNS, AnalysisOptions, RunAnalysis, analyze_run
from swarmbox.analysis.sweep import SweepInputError, SweepOptions, analyze_sweep, summary_wide
from swarmbox.analysis.tables import to_markdown

#: 4 (a sweep): the tables were written but no run ended ok, so they hold run counts and no metric.
EXIT_OK, EXIT_REGRESSION, EXIT_BAD_INPUT, EXIT_INCOMPLETE, EXIT_NO_OK_RUN = 0, 1, 2, 3, 4


def _analyze_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="python -m swarmbox.analyze",
                                description="Analyze a run directory or a sweep (multirun) directory.")
    p.add_argument("path", type=Path, help="a run directory (with run.json) or a directory of runs")
    p.add_argument("--out", type=Path, help="where tables/ and figures/ go (default: beside the data)")
    p.add_argument("--no-figures", action="store_true", help="write tables only")
    p.add_argument("--allow-incomplete", action="store_true",
                   help="analyze a run with damaged or missing tables anyway (flagged; exit 0)")
    run = p.add_argument_group("run analysis")
    run.add_argument("--window", type=float, default=0.5, help="timeline/anomaly window, s (0.5)")
    run.add_argument("--iqr-k", type=float, default=1.5, help="Tukey fence multiplier (1.5)")
    run.add_argument("--separation", type=float, default=2.0, help="separation threshold, m (2.0)")
    run.add_argument("--fault-onset", type=float, help="fault onset, unified s (default: the fault event)")
    run.add_argument("--fault-target", type=int, help="fault target drone (default: from the fault event)")
    sweep = p.add_argument_group("sweep tables")
    sweep.add_argument("--group-by", nargs="+",
                       help="the compared factor: any choice or override key, e.g. algo or network.loss_prob "
                            "(default: algo if it varies, else every swept key)")
    sweep.add_argument("--tasks", nargs="+",
                       help="what a task is for the aggregates across tasks (IQM, P(improvement), profiles): "
                            "keys or seed (default: the other swept keys, e.g. mission)")
    sweep.add_argument("--pair", nargs=2, action="append", metavar=("A", "B"),
                       help="paired comparison B - A (repeatable; default: every pair of groups)")
    sweep.add_argument("--statuses", nargs="+", default=["ok"], help="run statuses summarized (ok)")
    sweep.add_argument("--n-boot", type=int, default=2000, help="bootstrap resamples (2000)")
    sweep.add_argument("--ci", type=float, default=0.95, help="confidence level (0.95)")
    sweep.add_argument("--seed", type=int, default=0, help="bootstrap seed (0)")
    sweep.add_argument("--metrics", nargs="+", help="metrics drawn in the sweep figures")
    sweep.add_argument("--per-run", action="store_true", help="also write every run's own tables/figures")
    sweep.add_argument("--workers", type=int, help="parallel analysis processes (default: one per idle core)")
    return p


def _run_options(args: argparse.Namespace) -> AnalysisOptions:
    return AnalysisOptions(window_s=args.window, iqr_k=args.iqr_k, separation_m=args.separation,
                           fault_onset_u=args.fault_onset, fault_target=args.fault_target)


def _print_run(analysis: RunAnalysis) -> None:
    manifest = analysis.run.manifest
    print(f"run {analysis.run.path}: status {analysis.run.status} {manifest.get('reason') or ''}".rstrip())
    for problem in analysis.problems:
        print(f"warning: {problem}")
    print(to_markdown(analysis.clocks[["node", "offset_s", "drift_ppm", "method"]]))
    cols = [c for c in ("drone", "distance_h_m", "busy_s", "utilization", "idle_s", "latency_ms_mean",
                        "loss_ratio", "disc_h_m_max") if c in analysis.drones.columns]
    print(to_markdown(analysis.drones[cols]))
    if len(analysis.finding):
        print("finding (from the logs alone):")
        print(to_markdown(analysis.finding))
    if len(analysis.diagnosis):
        print(f"scoring against the fault onset ({analysis.onset.name if analysis.onset else 'given'}):")
        print(to_markdown(analysis.diagnosis[["metric", "t_f_s", "tau_d", "sigma_a", "drone", "is_target"]]))
    print(to_markdown(metrics_table(analysis)[["metric", "value", "unit"]]))


def analyze_main(argv: list[str] | None = None) -> int:
    args = _analyze_parser().parse_args(argv)
    matplotlib.use("Agg")
    logging.basicConfig(level=logging.WARNING, format="%(levelname)s %(name)s: %(message)s")
    path: Path = args.path
    if not path.is_dir():
        print(f"error: {path} is not a directory", file=sys.stderr)
        return EXIT_BAD_INPUT
    out = args.out or path
    if (path / "run.json").is_file():
        try:
            run = load_run(path, ANALYZED_COLUMNS, streamed=("messages",))   # matched window by window
        except RunLoadError as exc:
            print(f"error: {exc}", file=sys.stderr)
            return EXIT_BAD_INPUT
        if run.incomplete:
            why = "; ".join(run.problems)
            if not args.allow_incomplete:
                print(f"error: incomplete run {path}: {why} (--allow-incomplete analyzes it anyway)",
                      file=sys.stderr)
                return EXIT_INCOMPLETE
            print(f"WARNING: incomplete run {path}: {why}; metrics cover only what could be read",
                  file=sys.stderr)
        analysis = analyze_run(run, _run_options(args))
        write_run(analysis, out, with_figures=not args.no_figures)
        _print_run(analysis)
        print(f"tables and figures written under {out}")
        return EXIT_OK
    if not find_runs(path):
        unfinished = "".join(f"\n  skipped: {d}: no run.json" for d in find_unfinished(path))
        print(f"error: no run directory (with run.json) at or below {path}{unfinished}", file=sys.stderr)
        return EXIT_BAD_INPUT
    return _analyze_sweep(path, out, args)


def _analyze_sweep(path: Path, out: Path, args: argparse.Namespace) -> int:
    opts = SweepOptions(group_by=tuple(args.group_by) if args.group_by else None,
                        statuses=tuple(args.statuses),
                        n_boot=args.n_boot, ci=args.ci, seed=args.seed,
                        pairs=tuple(map(tuple, args.pair)) if args.pair else None,
                        tasks=tuple(args.tasks) if args.tasks else None, run=_run_options(args))
    try:
        result = analyze_sweep(path, opts, workers=args.workers, progress=Reporter("analysis"))
    except SweepInputError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return EXIT_BAD_INPUT
    write_sweep(result, out, with_figures=not args.no_figures, metrics=args.metrics)
    for row in result.problems.itertuples(index=False):
        print(f"{row.severity}: {row.run}: {row.problem}")
    if args.per_run:
        for rel in result.runs.loc[result.runs["status"] == "ok", "run"]:
            write_run(analyze_run(path / rel, opts.run), path / rel, with_figures=not args.no_figures)
    if result.summary.empty:
        print("error: no run could be read", file=sys.stderr)
        return EXIT_BAD_INPUT
    skipped = int((result.problems["severity"] == "skipped").sum())
    counts = result.runs["status"].value_counts().to_dict()
    print(f"{len(result.runs)} runs ({', '.join(f'{v} {k}' for k, v in sorted(counts.items()))}), "
          f"{skipped} skipped")
    print(to_markdown(summary_wide(result.summary, result.group_by)))
    print(f"tables and figures written under {out}")
    if not result.ok_runs:
        print("error: no run ended ok: the tables hold run counts and no metric", file=sys.stderr)
        return EXIT_NO_OK_RUN
    return EXIT_OK


def _compare_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="python -m swarmbox.compare",
                                description="Compare two summary CSVs; exit 1 on regression, 2 on bad input.")
    p.add_argument("baseline", type=Path, help="baseline summary.csv (or a run's metrics.csv)")
    p.add_argument("current", type=Path, help="current summary.csv (or a run's metrics.csv)")
    p.add_argument("--config", type=Path, help="YAML with default/metrics tolerances and directions "
                   "(default: tolerances.yaml beside BASELINE, if there is one)")
    p.add_argument("--rtol", type=float, help="relative tolerance for every metric not in the YAML")
    p.add_argument("--atol", type=float, help="absolute tolerance for every metric not in the YAML")
    p.add_argument("--ignore", nargs="+", default=[], help="metrics to leave out")
    p.add_argument("--allow-missing", action="store_true",
                   help="a metric missing from CURRENT is not a regression")
    p.add_argument("--all", action="store_true", help="print every row, not only the changed ones")
    return p


def compare_main(argv: list[str] | None = None) -> int:
    parser = _compare_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:
        return EXIT_OK if exc.code == 0 else EXIT_BAD_INPUT
    try:
        tolerances = args.config or baseline_tolerances(args.baseline)
        if tolerances is not None and args.config is None:
            print(f"tolerances: {tolerances}")
        config = load_config(tolerances, rtol=args.rtol, atol=args.atol, ignore=tuple(args.ignore),
                             allow_missing=args.allow_missing)
        verdicts = compare(load_summary(args.baseline), load_summary(args.current), config)
    except CompareInputError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return EXIT_BAD_INPUT
    shown = verdicts if args.all else verdicts[~verdicts["verdict"].isin(["ok", "ignored"])]
    print(to_markdown(shown) if len(shown) else "every metric within tolerance")
    counts = verdicts["verdict"].value_counts().to_dict()
    print(", ".join(f"{k}: {v}" for k, v in sorted(counts.items())))
    if has_regression(verdicts):
        print(f"REGRESSION: {', '.join(regressed(verdicts))}")
        return EXIT_REGRESSION
    print("OK")
    return EXIT_OK
