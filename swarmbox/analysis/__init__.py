"""Swarm-level log analyzer: unify -> metrics -> anomalies -> tables -> figures -> compare.

Reads run directories written by ``swarmbox.run`` (layout in :mod:`swarmbox.record.schema`); the
runtime never imports this package. Metric definitions live in the module docstrings
(:mod:`.unify`, :mod:`.metrics`, :mod:`.network`, :mod:`.timeline`, :mod:`.anomaly`,
:mod:`.mission`, :mod:`.sweep`, :mod:`.compare`) and in ``docs/analysis.md``.

Typical use::

    from swarmbox.analysis import analyze_run, analyze_sweep
    run = analyze_run("results/2026-01-01/12-00-00")
    run.scalars["mission_duration_s"], run.drones, run.clocks, run.diagnosis
    sweep = analyze_sweep("multirun/2026-01-01/12-00-00")
    sweep.summary, sweep.paired, sweep.ranks
"""

from swarmbox.analysis.load import RunData, RunLoadError, find_runs, load_run
from swarmbox.analysis.report import AnalysisOptions, RunAnalysis, analyze_run
from swarmbox.analysis.sweep import SweepOptions, SweepResult, analyze_sweep

__all__ = [
    "AnalysisOptions", "RunAnalysis", "RunData", "RunLoadError", "SweepOptions", "SweepResult",
    "analyze_run", "analyze_sweep", "find_runs", "load_run",
]
