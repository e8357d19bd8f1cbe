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

from __future__ import annotations

import importlib
from typing import Any

# Names are loaded on first use (PEP 562), so importing one light submodule (the sweep callback
# that Hydra builds before the runs start) does not load pandas into the runs.
_EXPORTS = {
    "RunData": "load", "RunLoadError": "load", "find_runs": "load", "load_run": "load",
    "AnalysisOptions": "report", "RunAnalysis": "report", "analyze_run": "report",
    "SweepOptions": "sweep", "SweepResult": "sweep", "analyze_sweep": "sweep",
}

__all__ = [
    "AnalysisOptions", "RunAnalysis", "RunData", "RunLoadError", "SweepOptions", "SweepResult",
    "analyze_run", "analyze_sweep", "find_runs", "load_run",
]


def __getattr__(name: str) -> Any:
    if name not in _EXPORTS:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(importlib.import_module(f"{__name__}.{_EXPORTS[name]}"), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_EXPORTS))
