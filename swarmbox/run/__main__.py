"""``python -m swarmbox.run``: one run, or a sweep with ``-m`` (Hydra multirun).

Examples::

    python -m swarmbox.run                                    # the default formation mission
    python -m swarmbox.run algo=hover mission=hover seed=3
    python -m swarmbox.run -m algo=hover,formation 'seed=range(3)'
    python -m swarmbox.run -m hydra/launcher=joblib 'seed=range(20)'   # parallel, one job per core
    python -m swarmbox.run -m 'seed=range(20)' hydra.sweep.dir=study run.resume=true  # resume a sweep
"""

from __future__ import annotations

import sys
from pathlib import Path

import hydra
from hydra.core.hydra_config import HydraConfig
from hydra.types import RunMode
from omegaconf import DictConfig

from swarmbox.run.config import register
from swarmbox.run.resume import ResumeMismatchError, finished_run
from swarmbox.run.runner import RunExistsError, execute, run_choices, summary_line

CONF_DIR = str(Path(__file__).resolve().parents[1] / "conf")

register()


@hydra.main(config_path=CONF_DIR, config_name="config", version_base="1.3")
def main(cfg: DictConfig) -> str:
    hc = HydraConfig.get()
    run_dir = Path(cfg.run.out_dir) if cfg.run.out_dir else Path(hc.runtime.output_dir)
    choices = run_choices(cfg, hc.runtime.choices)
    if hc.mode == RunMode.MULTIRUN:
        cfg.run.progress = False   # the sweep's own progress speaks for its runs
    try:
        manifest = finished_run(run_dir, list(hc.overrides.task)) if cfg.run.resume else None
        if manifest is not None:
            print(f"SKIP    {run_dir}: already finished ({manifest['status']}; run.resume=true)", flush=True)
            return manifest["status"]
        manifest = execute(cfg, run_dir, choices, list(hc.overrides.task))
    except (RunExistsError, ResumeMismatchError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        sys.exit(2)
    print(summary_line(manifest, run_dir), flush=True)
    if manifest["status"] == "failed":
        if manifest["traceback"]:
            print(manifest["traceback"], file=sys.stderr)
        if hc.mode != RunMode.MULTIRUN:
            sys.exit(1)
    return manifest["status"]


if __name__ == "__main__":
    main()
