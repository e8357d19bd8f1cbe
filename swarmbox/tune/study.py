"""The tuning loop: an Optuna study (ask and tell) whose trials fly through the configured launcher.

Per round, ``batch_trials`` trials are asked; each flies on every tuning seed (all of the round's runs in
one launch, so the launcher's workers run them in parallel), into ``trial<NNNN>_seed<S>/`` under the
sweep directory. Each run's objective values come from its ``objective.json`` (written by the worker,
:mod:`swarmbox.tune.callback`), the trial is scored and told (:func:`swarmbox.tune.objective.score`:
the penalty rule), with its runs, seeds and per-seed values kept in its user attributes, so every table
can be rebuilt from the study's storage alone.

Storage: ``study.db`` (SQLite) in the sweep directory, held by a claim (:mod:`swarmbox.run.claims`) while
the study runs, so a second invocation into the same directory is refused instead of writing into it.
``run.resume=true`` loads the same study: finished trials stay as they are, a trial that was flying when
the study was stopped is closed as failed and its parameters are asked again (a new trial number), and
the study asks new trials until ``n_trials`` have finished. After the last trial the best parameters are
flown again on held-out seeds (:mod:`swarmbox.tune.results`).
"""

from __future__ import annotations

import sys
import time
import warnings
from pathlib import Path
from typing import Any

from omegaconf import DictConfig, OmegaConf

from swarmbox.run import claims, interrupt
from swarmbox.run.progress import _clock  # the sweeps' own h:mm:ss
from swarmbox.run.record import RunExistsError, hide_in_config
from swarmbox.tune import objective as obj
from swarmbox.tune.checks import STUDY_FILE, Plan, TuneInputError, check

CONSTRAINT = "runs_not_ok"


def make_sampler(name: str, seed: int) -> Any:
    import optuna

    samplers = {"tpe": optuna.samplers.TPESampler, "random": optuna.samplers.RandomSampler,
                "cmaes": optuna.samplers.CmaEsSampler, "nsga2": optuna.samplers.NSGAIISampler}
    return samplers[name](seed=seed)


def identity(plan: Plan) -> dict[str, Any]:
    """What makes a study what it is: a resume must match it."""
    return {"objective": list(plan.objective.metrics), "directions": list(plan.objective.directions),
            "space": plan.space.describe(), "fixed": sorted(plan.space.defining()),
            "seeds": list(plan.seeds)}


def open_study(root: Path, name: str, plan: Plan, sampler: Any) -> Any:
    """Create the study in ``root/study.db``, or load it (a resume) after checking it is the same."""
    import optuna

    existed = (root / STUDY_FILE).exists()
    study = optuna.create_study(storage=f"sqlite:///{root / STUDY_FILE}", study_name=name, sampler=sampler,
                                directions=plan.objective.optuna_directions, load_if_exists=True)
    wanted = identity(plan)
    stored = study.user_attrs.get("identity")
    if existed and stored is not None and stored != wanted:
        diff = sorted(k for k in wanted if stored.get(k) != wanted[k])
        raise TuneInputError(f"{root / STUDY_FILE}: study '{name}' was started with another "
                             f"{', '.join(diff)} ({', '.join(f'{k}={stored.get(k)}' for k in diff)}); "
                             "resume it with the same settings or choose another hydra.sweep.dir")
    if stored is None:
        study.set_user_attr("identity", wanted)
    return study


class StudyRunner:
    """Flies the trials of one study through a launcher and tells Optuna their scores."""

    def __init__(self, config: DictConfig, launcher: Any, plan: Plan) -> None:
        self.config, self.launcher, self.plan = config, launcher, plan
        self.s = config.hydra.sweeper
        self.root = Path(str(config.hydra.sweep.dir))
        self.job_idx = 0
        self.started = time.perf_counter()
        self.flown = 0

    def fly(self, named: list[tuple[str, list[str]]]) -> dict[str, list[dict[str, Any]]]:
        """Launch every (label, overrides) on every tuning seed; each label's run records, seed order."""
        return self.fly_seeds(named, self.plan.seeds)

    def fly_seeds(self, named: list[tuple[str, list[str]]],
                  seeds: tuple[int, ...]) -> dict[str, list[dict[str, Any]]]:
        dirs = {label: [f"{label}_seed{s}" for s in seeds] for label, _ in named}
        jobs = [[*overrides, f"seed={s}", f"hydra.sweep.subdir={label}_seed{s}"]
                for label, overrides in named for s in seeds]
        returns = self.launcher.launch(jobs, initial_job_idx=self.job_idx)
        self.job_idx += len(jobs)
        for r in returns:
            _ = r.return_value   # a job that raised (not a failed run: a bug) stops the study here
        out = {}
        for label, names in dirs.items():
            out[label] = [obj.read(self.root / n) | {"run": n} for n in names]
        return out

    def requeue_orphans(self, study: Any) -> None:
        """Trials left flying by a stopped study: closed as failed, their parameters asked again."""
        from optuna.trial import TrialState

        for t in study.get_trials(deepcopy=False, states=(TrialState.RUNNING,)):
            study.tell(t.number, state=TrialState.FAIL)
            study.enqueue_trial(t.params, user_attrs={"resumes": t.number})
            print(f"trial {t.number}: stopped before it finished; its parameters are flown again",
                  file=sys.stderr, flush=True)

    def tell(self, study: Any, trial: Any, records: list[dict[str, Any]]) -> obj.Score:
        sc = obj.score(records, self.plan.objective)
        trial.set_user_attr("seeds", list(self.plan.seeds))
        trial.set_user_attr("runs", sc.counts)
        trial.set_user_attr("values", {m: v.tolist() for m, v in sc.values.items()})
        trial.set_user_attr("run_dirs", [r["run"] for r in records])
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")   # set_constraint is experimental in some Optuna releases
            trial.set_constraint(CONSTRAINT, float(sc.not_ok))
        study.tell(trial, sc.told if len(sc.told) > 1 else sc.told[0])
        return sc

    def optimise(self, study: Any) -> bool:
        """Ask, fly and tell until ``n_trials`` trials have finished; False if the study was stopped."""
        from optuna.trial import TrialState

        self.requeue_orphans(study)
        dists = self.plan.space.distributions()
        finished = (TrialState.COMPLETE,)
        while (done := len(study.get_trials(deepcopy=False, states=finished))) < self.s.n_trials:
            trials = [study.ask(dists) for _ in range(min(self.s.batch_trials, self.s.n_trials - done))]
            named = [(f"trial{t.number:04d}", self.plan.space.overrides(t.params)) for t in trials]
            records = self.fly(named)
            if interrupt.requested():
                return False   # the trials stay RUNNING in the storage: a resume flies them again
            for t, (label, _) in zip(trials, named, strict=True):
                self.progress(study, t.number, self.tell(study, t, records[label]), done + 1)
                done += 1
        return True

    def progress(self, study: Any, number: int, sc: obj.Score, done: int) -> None:
        self.flown += 1
        total = int(self.s.n_trials)
        elapsed = time.perf_counter() - self.started
        eta = elapsed / self.flown * (total - done)
        values = ", ".join(f"{m} {v:.4g}" for m, v in zip(self.plan.objective.metrics, sc.told, strict=True))
        state = "" if sc.feasible else f", penalized: {sc.not_ok} run(s) not ok"
        print(f"trial {number} ({done}/{total}): {values} ({sc.counts['ok']}/{sum(sc.counts.values())} ok"
              f"{state}); elapsed {_clock(elapsed)}, ETA {_clock(eta)}", file=sys.stderr, flush=True)


def _refuse(reason: str) -> None:
    print(f"error: {reason}", file=sys.stderr, flush=True)
    sys.exit(2)


def _refuse_study(root: Path, reason: str) -> None:
    """Bad input found once the sweep has claimed its directory: the claim undone, the directory
    removed if this command made it and it holds nothing else, one line, exit 2."""
    (root / ".sweep.claim").unlink(missing_ok=True)
    claims.drop_if_made(root)
    _refuse(f"{reason} (nothing was run or written)")


def run_study(config: DictConfig, launcher: Any) -> Any:
    """The whole study: checks, claim, trials, then the held-out re-evaluation and the results."""
    import optuna

    from swarmbox.tune import results

    optuna.logging.set_verbosity(optuna.logging.WARNING)
    root = Path(str(config.hydra.sweep.dir))
    try:
        plan = check(config, ends=False)   # the tuner's callback checked them all before the study
    except TuneInputError as exc:   # only without that callback
        _refuse_study(root, str(exc))
    try:
        claim = claims.Claim(root, ".tune.claim", "tuning study").acquire()
    except (RunExistsError, OSError) as exc:
        _refuse(f"{exc}")
    s = config.hydra.sweeper
    try:
        study = open_study(root, str(s.study_name), plan, make_sampler(str(s.sampler), int(s.sampler_seed)))
    except TuneInputError as exc:
        claim.release()
        _refuse_study(root, str(exc))
    try:
        public = OmegaConf.create(OmegaConf.to_container(config))
        hide_in_config(public)
        OmegaConf.save(public, root / "multirun.yaml")
        runner = StudyRunner(config, launcher, plan)
        if runner.optimise(study):
            results.finish(runner, study)
        return study
    finally:
        claim.release()
