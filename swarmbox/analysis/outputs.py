"""Write the tables and figures of a run or a sweep (used by the CLI and the Hydra callback).

Run: ``<run>/tables/`` holds metrics (long: metric, value, direction, unit), drones, links, agents,
clocks, finding (the onset-agnostic diagnosis: first alarm) and alarms (every alarm episode), scoring
(only with a fault onset: t_f, tau_d, Sigma_a against it), anomalies (every flag), timeline (per drone
and window), swarm (per tick),
connectivity (per window), markers, problems; ``<run>/figures/`` holds trajectories,
one timeline per monitored metric, and the communication graph (up to ``figures.MANY_DRONES``
drones; larger swarms get density/summary figures instead of one line per drone).
Sweep: ``<sweep>/tables/`` holds runs, summary (long, the input of ``compare``), summary_wide,
paired, ranks, problems; ``<sweep>/figures/`` holds the normalized heatmap and the box plots.
"""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np
import pandas as pd

from swarmbox.analysis import aggregate_plots, figures
from swarmbox.analysis.catalog import declared_units, direction_of, unit_of
from swarmbox.analysis.report import RunAnalysis
from swarmbox.analysis.sweep import SweepResult, summary_wide
from swarmbox.analysis.tables import write_table
from swarmbox.analysis.timeline import MONITORED

log = logging.getLogger(__name__)

#: Metrics drawn by default in the sweep figures (paper Table 6 and the usual safety/network set).
FIGURE_METRICS = ("mission_duration_s", "distance_h_m_mean", "distance_h_m_std", "busy_s_std",
                  "utilization_mean", "idle_s_mean", "latency_ms_mean", "loss_ratio", "min_separation_m",
                  "collision_events")


def metrics_table(analysis: RunAnalysis) -> pd.DataFrame:
    units = declared_units(analysis.run.config)
    rows = [{"metric": k, "value": v, "direction": direction_of(k, analysis.directions) or "",
             "unit": unit_of(k, units)} for k, v in analysis.scalars.items()]
    return pd.DataFrame(rows, columns=["metric", "value", "direction", "unit"])


def problems_table(problems: list[str]) -> pd.DataFrame:
    return pd.DataFrame({"problem": problems})


def write_run(analysis: RunAnalysis, out: Path, with_figures: bool = True) -> list[Path]:
    """Write every table (and figure) of one analyzed run under ``out``."""
    tables = out / "tables"
    written: list[Path] = []
    for name, frame, md in (
        ("metrics", metrics_table(analysis), True), ("drones", analysis.drones, True),
        ("links", analysis.links, True), ("agents", analysis.agents, True),
        ("clocks", analysis.clocks, True), ("swarm", analysis.swarm, False),
        ("connectivity", analysis.connectivity, False),
        ("finding", analysis.finding, True), ("alarms", analysis.alarms, False),
        *((("scoring", analysis.diagnosis, True),) if len(analysis.diagnosis) else ()),
        ("anomalies", analysis.flags, False),
        ("timeline", analysis.timeline, False), ("markers", analysis.markers, False),
        ("problems", problems_table(analysis.problems), False),
    ):
        written += write_table(frame, tables, name, markdown=md)
    if with_figures:
        written += _run_figures(analysis, out / "figures")
    return written


def _run_figures(analysis: RunAnalysis, out: Path) -> list[Path]:
    written: list[Path] = []
    state = analysis.run.tables["state"]
    if len(state):
        written += figures.save(figures.trajectories(state), out, "trajectories")
    onset = analysis.onset
    for metric in MONITORED:
        if not (analysis.timeline["metric"] == metric).any():
            continue
        detection = _detection(analysis, metric)
        fig = figures.timeline(analysis.timeline, metric=metric, onset=onset.t_u if onset else None,
                               detection=detection, target=onset.target if onset else None)
        written += figures.save(fig, out, f"timeline_{metric}")
    if len(analysis.links) and len(analysis.run.drones) <= figures.MANY_DRONES:
        # one labelled edge per link: unreadable past a few dozen drones (tables/links.csv has it all)
        written += figures.save(figures.comm_graph(analysis.links), out, "comm_graph")
    return written


def _detection(analysis: RunAnalysis, metric: str) -> float | None:
    diag = analysis.diagnosis
    if diag.empty or analysis.onset is None:
        return None
    row = diag[diag["metric"] == metric]
    return float(analysis.onset.t_u + row["t_f_s"].iloc[0]) if len(row) else None


def figure_metrics(result: SweepResult, requested: list[str] | None = None) -> list[str]:
    """Requested metrics, else the default set plus declared mission metrics, that have data."""
    available = [m for m in result.metric_columns() if result.runs[m].notna().any()]
    if requested:
        return [m for m in requested if m in available]
    declared = [m for m in result.directions if m in available]
    chosen = [m for m in FIGURE_METRICS if m in available] + declared
    return list(dict.fromkeys(chosen))


def write_sweep(result: SweepResult, out: Path, with_figures: bool = True,
                metrics: list[str] | None = None) -> list[Path]:
    """Write the benchmark tables (and figures) of a sweep under ``out``.

    Every table is written whatever the sweep holds: a sweep with no ok run still has its run counts,
    and an empty comparison or ranking is a row saying why.
    """
    tables = out / "tables"
    written = write_table(result.runs, tables, "runs", markdown=False)
    written += write_table(result.problems, tables, "problems", markdown=False)
    if result.summary.empty:
        return written
    written += write_table(result.summary, tables, "summary")
    written += write_table(summary_wide(result.summary, result.group_by), tables, "summary_wide")
    written += write_table(result.paired, tables, "paired")
    written += write_table(result.ranks, tables, "ranks")
    if result.aggregates is not None:
        written += _aggregate_outputs(result, out, with_figures, metrics)
    if with_figures:
        chosen = figure_metrics(result, metrics)
        try:
            written += _sweep_figures(result, out / "figures", chosen)
        except (ValueError, KeyError) as exc:
            log.warning("sweep figures skipped: %s", exc)
    return written


def _aggregate_outputs(result: SweepResult, out: Path, with_figures: bool,
                       metrics: list[str] | None) -> list[Path]:
    agg = result.aggregates
    written = write_table(agg.iqm, out / "tables", "aggregate_iqm")
    written += write_table(agg.improvement, out / "tables", "aggregate_improvement")
    written += write_table(agg.profiles, out / "tables", "aggregate_profiles", markdown=False)
    if with_figures and len(agg.iqm):
        chosen = [m for m in figure_metrics(result, metrics) if (agg.iqm["metric"] == m).any()]
        compared = "/".join(result.design.group_by) if result.design else "group"
        fig = aggregate_plots.aggregates(agg.iqm, agg.profiles, metrics=chosen or None,
                                         tasks="/".join(agg.tasks), units=result.units, compared=compared)
        written += figures.save(fig, out / "figures", "aggregate")
    return written


def _sweep_figures(result: SweepResult, out: Path, chosen: list[str]) -> list[Path]:
    written: list[Path] = []
    if not chosen:
        return written
    d = result.design
    compared, strata = (d.group_by, d.strata) if d else (result.group_by, ())
    ok = result.runs[result.runs["status"] == "ok"]
    written += figures.save(figures.heatmap(result.summary, group_by=compared, strata=strata, metrics=chosen,
                                            units=result.units), out, "heatmap")
    keys = list(result.group_by)
    by = keys[0] if len(keys) == 1 else "group"
    runs = ok if len(keys) == 1 else ok.assign(
        group=ok[keys].astype("str").agg("/".join, axis=1) if keys else "all")
    finite = [m for m in chosen if np.isfinite(runs[m].to_numpy(dtype="float64")).any()]
    if finite:
        written += figures.save(figures.boxplots(runs, metrics=finite, by=by, units=result.units), out,
                                "boxplots")
    return written
