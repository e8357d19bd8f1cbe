"""Hydra callback: analyze a sweep when the multirun ends.

``conf/config.yaml`` wires it in::

    hydra:
      callbacks:
        analyze:
          _target_: swarmbox.analysis.callback.AnalyzeSweepCallback
          group_by: null        # the compared factor; null: algo if it varies, else every swept key
          tasks: null           # aggregates across tasks (e.g. [seed]: a dataset per seed); null: the strata

Hydra builds its callbacks in the process that then runs the jobs, so this module imports the
analysis library (pandas, matplotlib) only in ``on_multirun_end``: runs never load it, and the runtime
(``swarmbox.run``) never imports ``swarmbox.analysis``.
The callback never raises: an analysis error is logged and the multirun's own result stands (its exit
code is the jobs', docs/errors.md); a sweep with no ok run still gets its tables (run counts) and a
warning, and groups that are not comparable are named in the log.
"""

from __future__ import annotations

import logging
import os
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from hydra.experimental.callback import Callback
from omegaconf import DictConfig

log = logging.getLogger(__name__)


class AnalyzeSweepCallback(Callback):
    """Runs the sweep analysis on ``config.hydra.sweep.dir`` in ``on_multirun_end``."""

    def __init__(self, group_by: Sequence[str] | None = None, n_boot: int = 2000, seed: int = 0,
                 figures: bool = True, workers: int | None = None,
                 tasks: Sequence[str] | None = None) -> None:
        self.group_by = tuple(group_by) if group_by else None
        self.tasks = tuple(tasks) if tasks else None
        self.n_boot, self.seed = n_boot, seed
        self.figures, self.workers = figures, workers

    def _workers(self) -> int:
        """Every core unless told otherwise. Not ``default_workers``' idle-core guess: the 1-minute load
        average still counts the sweep's own runs, which have just finished (after a 2-core sweep it
        reads about 2, and the analysis would run on one core)."""
        if self.workers:
            return self.workers
        return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1

    def on_multirun_end(self, config: DictConfig, **kwargs: Any) -> None:
        if os.environ.get("SWARMBOX_INTERRUPTED"):   # set by swarmbox.run on SIGINT / SIGTERM
            log.warning("sweep interrupted (%s): analysis skipped", os.environ["SWARMBOX_INTERRUPTED"])
            return
        try:
            from swarmbox.analysis.outputs import write_sweep
            from swarmbox.analysis.parallel import Reporter
            from swarmbox.analysis.sweep import SweepInputError, SweepOptions, analyze_sweep

            options = SweepOptions(group_by=self.group_by, n_boot=self.n_boot, seed=self.seed,
                                   tasks=self.tasks)
            sweep_dir = Path(str(config.hydra.sweep.dir))
            try:
                result = analyze_sweep(sweep_dir, options, workers=self._workers(),
                                       progress=Reporter("sweep analysis"))
            except SweepInputError as exc:
                log.error("sweep analysis refused: %s", exc)
                return
            write_sweep(result, sweep_dir, with_figures=self.figures)
            for row in result.problems.itertuples(index=False):
                log.warning("%s: %s: %s", row.severity, row.run, row.problem)
            if len(result.runs) and not result.ok_runs:
                log.warning("no run ended ok: the sweep tables hold run counts and no metric")
            log.info("sweep analysis of %d runs written under %s", len(result.runs), sweep_dir)
        except Exception:  # noqa: BLE001 - an analysis failure must not fail the multirun
            log.exception("sweep analysis failed")


class DiagnoseSweepCallback(Callback):
    """Hydra callback: the diagnosis report of a multirun, in ``<sweep>/diagnosis/``
    (``swarmbox detect <sweep>``).

    ``group_by`` is accepted and ignored, so that it can take the place of the generic ``analyze``
    callback. It never raises: a failure is logged.
    """

    def __init__(self, jobs: int = 2, group_by: Sequence[str] = ()) -> None:
        self.jobs = jobs

    def on_multirun_end(self, config: DictConfig, **kwargs: Any) -> None:
        try:
            from swarmbox.analysis.detection import main

            main([str(config.hydra.sweep.dir), "--jobs", str(self.jobs)])
        except Exception:  # noqa: BLE001 - an analysis failure must not fail the multirun
            log.exception("diagnosis of the sweep failed")
