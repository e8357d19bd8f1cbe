"""The tuner's Hydra callback (wired in by ``hydra/sweeper=tune``): checks before the study, objective
values in the worker.

- ``on_multirun_start``: the checks of :mod:`swarmbox.tune.checks`, before any other callback claims
  or creates the sweep directory (this callback comes first in ``hydra.callbacks``): bad input prints one
  line and exits 2 with nothing written.
- ``on_job_end``: in the process that flew the run (a joblib, Ray or Submitit worker), the objective
  metrics of the run, computed by the analyzer from the run's logs, into ``objective.json`` beside its
  ``run.json``; the sweeper reads them from there. A run skipped by ``run.resume=true`` keeps the file
  it has.
"""

from __future__ import annotations

import json
import sys
import traceback
from pathlib import Path
from typing import Any

from hydra.experimental.callback import Callback
from hydra.types import RunMode
from omegaconf import DictConfig

from swarmbox.tune.objective import OBJECTIVE_FILE, as_list, run_values


def run_dir_of(config: DictConfig) -> Path:
    """Where the job's run wrote its record (``run.out_dir``, else Hydra's output directory)."""
    out = config.get("run", {}).get("out_dir")
    return Path(str(out)) if out else Path(str(config.hydra.runtime.output_dir))


def write_objective(run_dir: Path, metrics: list[str]) -> dict[str, Any] | None:
    """``objective.json`` of a finished run (None when the run left no ``run.json``)."""
    from swarmbox.run.record import write_atomic

    path = run_dir / OBJECTIVE_FILE
    if path.exists() or not (run_dir / "run.json").exists():
        return None
    record = run_values(run_dir, metrics)
    write_atomic(path, json.dumps(record, indent=2, allow_nan=True))
    return record


class TuneCallback(Callback):
    """Checks a tuning study before it starts; writes each run's objective values in its worker."""

    def on_multirun_start(self, config: DictConfig, **kwargs: Any) -> None:
        from swarmbox.tune.checks import TuneInputError, check

        try:
            check(config)
        except TuneInputError as exc:
            print(f"error: {exc} (nothing was run or written)", file=sys.stderr, flush=True)
            sys.exit(2)

    def on_job_end(self, config: DictConfig, job_return: Any, **kwargs: Any) -> None:
        if config.hydra.mode != RunMode.MULTIRUN:
            return
        try:
            write_objective(run_dir_of(config), as_list(config.hydra.sweeper.objective))
        except Exception:  # noqa: BLE001 - the sweeper counts a run without objective.json as not ok
            print(f"objective of {run_dir_of(config)} could not be computed:\n{traceback.format_exc()}",
                  file=sys.stderr, flush=True)
