"""Hydra callback: analyze a sweep when the multirun ends.

Wire it in a config (the lead does this in ``conf/``)::

    hydra:
      callbacks:
        analyze:
          _target_: swarmbox.analysis.callback.AnalyzeSweepCallback
          group_by: [algo]

The callback never raises: an analysis error is logged and the multirun's own result stands.
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from hydra.experimental.callback import Callback
from omegaconf import DictConfig

from swarmbox.analysis.outputs import write_sweep
from swarmbox.analysis.parallel import Reporter
from swarmbox.analysis.sweep import SweepOptions, analyze_sweep

log = logging.getLogger(__name__)


class AnalyzeSweepCallback(Callback):
    """Runs the sweep analysis on ``config.hydra.sweep.dir`` in ``on_multirun_end``."""

    def __init__(self, group_by: Sequence[str] = ("algo",), n_boot: int = 2000, seed: int = 0,
                 figures: bool = True) -> None:
        self.options = SweepOptions(group_by=tuple(group_by), n_boot=n_boot, seed=seed)
        self.figures = figures

    def on_multirun_end(self, config: DictConfig, **kwargs: Any) -> None:
        try:
            sweep_dir = Path(str(config.hydra.sweep.dir))
            result = analyze_sweep(sweep_dir, self.options, progress=Reporter("sweep analysis"))
            write_sweep(result, sweep_dir, with_figures=self.figures)
            for row in result.problems.itertuples(index=False):
                log.warning("%s: %s: %s", row.severity, row.run, row.problem)
            log.info("sweep analysis of %d runs written under %s", len(result.runs), sweep_dir)
        except Exception:  # noqa: BLE001 - an analysis failure must not fail the multirun
            log.exception("sweep analysis failed")
