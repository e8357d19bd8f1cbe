"""A study's results, under ``<sweep dir>/tune/``:

- ``trials.csv`` / ``trials.md``: one row per trial: its state (``ok``; ``penalized``: a run not ok, see
  the penalty rule of :mod:`swarmbox.tune.objective`; ``stopped``: flying when the study was stopped,
  its parameters asked again), its parameters, per objective the score told to Optuna and the mean over
  the ok runs with its bootstrap CI over seeds and n, and the runs attempted / ok / aborted / failed /
  interrupted / missing with the success rate;
- ``best.json``, ``best_algo.yaml``: the best trial (single objective: Optuna's best feasible trial;
  several: of the feasible Pareto front, the best in the first objective), its parameters as overrides
  and as a ready-to-use algo config (drop it into ``<your conf>/algo/`` and run ``algo=<file name>``);
- ``heldout.csv`` / ``heldout.md``: the best parameters flown again on the held-out seeds (disjoint from
  the tuning seeds, :func:`swarmbox.tune.checks.seeds_of`): per objective the mean over the ok runs, its
  bootstrap CI over seeds and n, beside the in-sample numbers of the same trial, with the run counts: the
  in-sample number is the tuner's maximum over noisy trials and is biased in its favour, the held-out
  one is not;
- ``figures/``: Optuna's own plots (optimization history, parameter importances, contour), per objective.

Every table is rebuilt from the study's storage (the trials' user attributes), so a resumed study's
results cover all of its trials.
"""

from __future__ import annotations

import json
import sys
import warnings
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import yaml
from omegaconf import OmegaConf

from swarmbox.analysis.groupstats import bootstrap_ci, denominators, rng
from swarmbox.analysis.tables import write_table
from swarmbox.run import interrupt
from swarmbox.run.record import write_atomic
from swarmbox.tune import objective as obj

LEVEL = 0.95


def _ci(values: list[float], n_boot: int, *key: str) -> tuple[float, float]:
    return bootstrap_ci(np.asarray(values, dtype="float64"), rng(0, "tune", *key), n_boot, LEVEL)


def _state(trial: Any) -> str:
    from optuna.trial import TrialState

    if trial.state == TrialState.COMPLETE:
        return "ok" if all(v <= 0 for v in trial.constraints.values()) else "penalized"
    names = {TrialState.FAIL: "stopped", TrialState.RUNNING: "running"}
    return names.get(trial.state, trial.state.name.lower())


def _runs(counts: dict[str, int]) -> dict[str, Any]:
    """The sweep tables' denominators (runs per outcome, success rate with its Wilson interval)."""
    statuses = pd.DataFrame({"status": [s for s, n in counts.items() for _ in range(int(n))]})
    if statuses.empty:
        return {"runs_attempted": 0}
    rows = {r["metric"]: r for r in denominators({}, statuses, LEVEL)}
    out = {k: int(r["mean"]) for k, r in rows.items() if k.startswith("runs_")}
    out["runs_missing"] = int(counts.get("missing", 0))
    rate = rows["success_rate"]
    return out | {"success_rate": rate["mean"], "success_ci_low": rate["ci_low"],
                  "success_ci_high": rate["ci_high"]}


def metric_cells(values: dict[str, list[float]], metrics: tuple[str, ...], n_boot: int,
                 *key: str) -> dict[str, Any]:
    """Per metric: mean over the ok runs, its bootstrap CI over seeds and n."""
    out: dict[str, Any] = {}
    for m in metrics:
        v = values.get(m, [])
        lo, hi = _ci(v, n_boot, *key, m)
        out |= {f"{m}_mean": float(np.mean(v)) if v else np.nan, f"{m}_ci_low": lo, f"{m}_ci_high": hi,
                f"{m}_n": len(v)}
    return out


def trials_table(study: Any, metrics: tuple[str, ...], keys: list[str], n_boot: int) -> pd.DataFrame:
    rows = []
    for t in study.get_trials(deepcopy=False):
        if t.state.name == "WAITING":
            continue
        row: dict[str, Any] = {"trial": t.number, "state": _state(t)}
        row |= {k: t.params.get(k) for k in keys}
        told = t.values or [np.nan] * len(metrics)
        row |= {f"{m}_score": v for m, v in zip(metrics, told, strict=True)}
        row |= metric_cells(t.user_attrs.get("values", {}), metrics, n_boot, str(t.number))
        row |= _runs(t.user_attrs.get("runs", {}))
        row["resumes"] = t.user_attrs.get("resumes")
        rows.append(row)
    return pd.DataFrame(rows)


def pick_best(study: Any, metrics: tuple[str, ...]) -> Any | None:
    """Single objective: the best feasible trial; several: the feasible Pareto trial best in the first."""
    try:
        if len(metrics) == 1:
            return study.best_trial
        front = study.best_trials
    except ValueError:   # no feasible trial
        return None
    if not front:
        return None
    sign = 1 if study.directions[0].name == "MINIMIZE" else -1
    return min(front, key=lambda t: (sign * t.values[0], t.number))


def heldout_table(best: Any, records: list[dict[str, Any]], objective: obj.Objective,
                  n_boot: int) -> pd.DataFrame:
    """In-sample (tuning seeds) and held-out rows of the best trial, same columns."""
    sc = obj.score(records, objective)
    held = {m: v.tolist() for m, v in sc.values.items()}
    seeds = [r.get("seed") for r in records]
    rows = [
        {"seeds": "tuning", "seed_range": _span(best.user_attrs.get("seeds", [])), "trial": best.number,
         **metric_cells(best.user_attrs.get("values", {}), objective.metrics, n_boot, str(best.number)),
         **_runs(best.user_attrs.get("runs", {}))},
        {"seeds": "held-out", "seed_range": _span(seeds), "trial": best.number,
         **metric_cells(held, objective.metrics, n_boot, "heldout", str(best.number)), **_runs(sc.counts)},
    ]
    return pd.DataFrame(rows)


def _span(seeds: list[Any]) -> str:
    seeds = [int(s) for s in seeds if s is not None]
    return f"{min(seeds)}..{max(seeds)}" if seeds else ""


def best_algo_yaml(config: Any, best: Any, keys: list[str], fixed: list[str]) -> str:
    """The algo config with the best parameters, ready to use as ``conf/algo/<name>.yaml``."""
    algo = OmegaConf.to_container(config.algo, resolve=False)
    for k in keys:
        if k.startswith("algo.params."):
            algo.setdefault("params", {})[k.removeprefix("algo.params.")] = best.params[k]
    mission = OmegaConf.select(config, "hydra.runtime.choices.mission")
    body = {"defaults": [{"override /mission@_global_.mission": mission}, "_self_"]} if mission else {}
    body |= algo
    others = [f"{k}={best.params[k]}" for k in keys if not k.startswith("algo.params.")]
    header = [f"# Tuned parameters: trial {best.number} of study "
              f"'{config.hydra.sweeper.study_name}' in {config.hydra.sweep.dir}",
              f"# objective: {', '.join(obj.as_list(config.hydra.sweeper.objective))}",
              f"# tuned with: {' '.join(fixed) or '(no other overrides)'}"]
    if others:
        header.append(f"# not algo parameters, give them on the command line: {' '.join(others)}")
    return "\n".join(header) + "\n" + yaml.safe_dump(body, sort_keys=False)


def finish(runner: Any, study: Any) -> None:
    """After the last trial: held-out re-evaluation of the best trial, then every result file."""
    plan, s = runner.plan, runner.s
    out = runner.root / "tune"
    keys = [d.key for d in plan.space.dimensions]
    table = trials_table(study, plan.objective.metrics, keys, int(s.n_boot))
    write_table(table, out, "trials")
    best = pick_best(study, plan.objective.metrics)
    if best is None:
        print("tune: no feasible trial (every trial had a run not ok): see tune/trials.md",
              flush=True)
        write_figures(study, plan.objective, keys, out / "figures")
        return
    label = f"heldout{best.number:04d}"
    records = runner.fly_seeds([(label, plan.space.overrides(best.params))], plan.heldout_seeds)[label]
    if interrupt.requested():
        return
    held = heldout_table(best, records, plan.objective, int(s.n_boot))
    write_table(held, out, "heldout")
    overrides = plan.space.overrides(best.params)[len(plan.space.fixed):]
    write_atomic(out / "best.json", json.dumps(
        {"trial": best.number, "params": best.params, "overrides": overrides,
         "objective": dict(zip(plan.objective.metrics, plan.objective.directions, strict=True)),
         "tuning": held.iloc[0].to_dict(), "heldout": held.iloc[1].to_dict()}, indent=2, default=str))
    write_atomic(out / "best_algo.yaml", best_algo_yaml(runner.config, best, keys, plan.space.defining()))
    write_figures(study, plan.objective, keys, out / "figures")
    _print_best(best, held, plan.objective, out)


def _print_best(best: Any, held: pd.DataFrame, objective: obj.Objective, out: Path) -> None:
    params = ", ".join(f"{k}={v:.4g}" if isinstance(v, float) else f"{k}={v}" for k, v in best.params.items())
    print(f"tune: best trial {best.number}: {params}", flush=True)
    for m, direction in zip(objective.metrics, objective.directions, strict=True):
        for _, row in held.iterrows():
            print(f"  {m} ({direction} is better), {row['seeds']} seeds {row['seed_range']}: "
                  f"{row[f'{m}_mean']:.4g} [{row[f'{m}_ci_low']:.4g}, {row[f'{m}_ci_high']:.4g}] "
                  f"(n={row[f'{m}_n']}, {row['runs_ok']}/{row['runs_attempted']} ok)", flush=True)
    print(f"  results: {out}", flush=True)


def feasible_copy(study: Any) -> Any:
    """An in-memory study of the feasible finished trials (importance and contour plots read values)."""
    import optuna

    copy = optuna.create_study(directions=study.directions)
    copy.add_trials([t for t in study.get_trials(deepcopy=False) if _state(t) == "ok"])
    return copy


def _plot(name: str, study: Any, feasible: Any, keys: list[str], i: int, objective: obj.Objective) -> Any:
    from optuna.importance import PedAnovaImportanceEvaluator
    from optuna.visualization import matplotlib as ovm

    metric = objective.metrics[i]
    target = (lambda t: t.values[i]) if len(objective.metrics) > 1 else None

    if name == "history":   # every trial, the penalized ones shown as infeasible
        return ovm.plot_optimization_history(study, target=target, target_name=metric)
    if name == "importance":
        # PED-ANOVA rates what leads to low target values: a higher-is-better metric is negated
        sign = -1.0 if objective.directions[i] == "higher" else 1.0
        return ovm.plot_param_importances(feasible, evaluator=PedAnovaImportanceEvaluator(),
                                          target=lambda t: sign * t.values[i], target_name=metric)
    return ovm.plot_contour(feasible, params=keys[:2], target=target, target_name=metric)


def write_figures(study: Any, objective: obj.Objective, keys: list[str], out: Path) -> list[Path]:
    """Optuna's matplotlib plots, per objective; a plot its data cannot make is skipped, saying why."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out.mkdir(parents=True, exist_ok=True)
    feasible = feasible_copy(study)
    written = []
    for i, m in enumerate(objective.metrics):
        names = ("history", "importance", "contour") if len(keys) > 1 else ("history", "importance")
        for name in names:
            path = out / f"{name}_{m}.png"
            try:
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore")   # Optuna marks its matplotlib plots experimental
                    ax = _plot(name, study, feasible, keys, i, objective)
                fig = (ax.flat[0] if hasattr(ax, "flat") else ax).figure
                fig.savefig(path, dpi=110, bbox_inches="tight")
                plt.close(fig)
                written.append(path)
            except (ValueError, RuntimeError, ZeroDivisionError) as exc:
                # printed, not logged: Hydra's logging setup disables the loggers made before it
                print(f"tune: figure {path.name} skipped: {exc}", file=sys.stderr, flush=True)
    return written
