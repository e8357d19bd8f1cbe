"""``python -m swarmbox.run``: one run, or a sweep with ``-m`` (Hydra multirun).

Examples::

    python -m swarmbox.run                                    # the default formation mission
    python -m swarmbox.run algo=hover mission=hover seed=3
    python -m swarmbox.run -m algo=hover,formation 'seed=range(3)'
    python -m swarmbox.run -m hydra/launcher=joblib 'seed=range(20)'   # parallel, one job per core
    python -m swarmbox.run --verbose ...                      # tracebacks on the terminal too
    python -m swarmbox.run -m 'seed=range(20)' hydra.sweep.dir=study run.resume=true  # resume a sweep

One error path: a bad input prints one line naming the key or file and creates nothing; a run
that fails prints one line with its reason and run directory (the traceback is in its run.json).
Exit codes: 0 ok or aborted (a truthful record of the mission), 1 a run failed, 2 bad input
(config, mission file, or a directory that holds a finished run), 128+N stopped by signal N
(130: Ctrl-C).
"""

from __future__ import annotations

import io
import os
import sys
from pathlib import Path

import hydra
from hydra.core.hydra_config import HydraConfig
from hydra.types import RunMode
from omegaconf import DictConfig

from swarmbox.run import claims, interrupt, mode, record, sweep_state
from swarmbox.run.checks import INPUT_ERRORS
from swarmbox.run.config import register
from swarmbox.run.resume import ResumeMismatchError, finished_run
from swarmbox.run.runner import RunExistsError, execute, run_choices, summary_line

CONF_DIR = str(Path(__file__).resolve().parents[1] / "conf")
EXIT_FAILED, EXIT_INPUT = 1, 2

register()


def verbose() -> bool:
    return bool(os.environ.get("SWARMBOX_VERBOSE") or os.environ.get("HYDRA_FULL_ERROR"))


def _drop_if_empty(path: Path) -> None:
    """Remove an output directory Hydra made for a job that wrote nothing (never a non-empty one,
    never one that existed before the command)."""
    claims.drop_if_made(path)


@hydra.main(config_path=CONF_DIR, config_name="config", version_base="1.3")
def main(cfg: DictConfig) -> str:
    sweep_state.entered()
    hc = HydraConfig.get()
    multirun = hc.mode == RunMode.MULTIRUN
    hydra_dir = Path(hc.runtime.output_dir)
    run_dir = Path(cfg.run.out_dir) if cfg.run.out_dir else hydra_dir
    overrides = list(hc.overrides.task)
    if interrupt.requested():
        _drop_if_empty(hydra_dir)
        sweep_state.not_started(overrides)
        return "not started"
    choices = run_choices(cfg, hc.runtime.choices)
    if hc.mode == RunMode.MULTIRUN:
        cfg.run.progress = False   # the sweep's own progress speaks for its runs
    try:
        manifest = finished_run(run_dir, overrides) if cfg.run.resume else None
        if manifest is not None:
            print(f"SKIP    {run_dir}: already finished ({manifest['status']}; run.resume=true)", flush=True)
            return manifest["status"]
        manifest = execute(cfg, run_dir, choices, overrides)
    except (RunExistsError, ResumeMismatchError, *INPUT_ERRORS) as exc:
        _drop_if_empty(hydra_dir)
        refused = isinstance(exc, RunExistsError | ResumeMismatchError)
        tail = "" if refused else " (nothing was run or written)"
        print(f"error: {record.scrub_error(str(exc), overrides)}{tail}", file=sys.stderr, flush=True)
        if not multirun:
            sys.exit(EXIT_INPUT)
        sweep_state.invalid(overrides, str(exc))
        return "invalid"
    finally:
        if run_dir != hydra_dir:
            _drop_if_empty(hydra_dir)
    status = manifest["status"]
    stream = sys.stdout if status in ("ok", "aborted") else sys.stderr
    print(summary_line(manifest, run_dir), flush=True, file=stream)
    if manifest["traceback"]:
        if verbose():
            print(manifest["traceback"], file=sys.stderr)
        else:
            print(f"  traceback: {run_dir / 'run.json'} (or rerun with --verbose)", file=sys.stderr)
    if status == "interrupted":
        interrupt.release()
    if not multirun:
        if status == "interrupted":
            sys.exit(interrupt.exit_code())
        if status == "failed":
            sys.exit(EXIT_FAILED)
    return status


def one_line(text: str) -> str:
    """Hydra's multi-line composition error as one line (its key and cause kept)."""
    text = text.split("Config search path:")[0]
    lines = [ln.strip() for ln in text.splitlines() if ln.strip()]
    keep = [ln for ln in lines if not ln.startswith(("Set the environment variable", "object_type="))]
    return "; ".join(keep).replace(":;", ":")


def cli() -> None:
    """Entry point: ``--verbose`` (not a Hydra option) turns on tracebacks on the terminal.

    Until the config has composed, stderr is held: if Hydra refuses the config (unknown key, wrong
    type, missing group option) its message is printed as one line and the exit code is 2.
    """
    if "--verbose" in sys.argv:
        sys.argv.remove("--verbose")
        os.environ["SWARMBOX_VERBOSE"] = "1"
    interrupt.install()
    mode.install()
    real, held = sys.stderr, io.StringIO()

    def release() -> None:
        if sys.stderr is held:
            sys.stderr = real
            real.write(held.getvalue())

    if not verbose():
        sys.stderr = held
        sweep_state.on_enter(release)
    try:
        main()
    except SystemExit as exc:
        if exc.code == 1 and not sweep_state.any_entered():
            sys.stderr = real
            text = record.scrub_error(one_line(held.getvalue()), sys.argv[1:]) or \
                "the config could not be composed"
            print(f"error: {text} (nothing was run or written)", file=real, flush=True)
            sys.exit(EXIT_INPUT)
        raise
    finally:
        release()


if __name__ == "__main__":
    cli()
