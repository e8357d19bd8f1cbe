"""What a study optimises: one or more per-run metrics of the analyzer, each with its better direction,
and how a trial's runs make its score.

A metric is any scalar the run analysis computes (:func:`swarmbox.analysis.report.analyze_run`): the
built-in catalog (:mod:`swarmbox.analysis.catalog`, machine figures excepted) and the mission metrics the
algorithm declares in ``algo.metrics`` (``<name>_<agg>``). The direction is the one given in
``hydra.sweeper.directions``, else the declared one, else the catalog's; a metric with none is refused.

Each run of a trial is analyzed in the worker that flew it (:mod:`swarmbox.tune.callback`), with the
analyzer's own code and options, into ``objective.json`` beside its ``run.json``.

Penalty (docs/tuning.md): a trial's score is the mean over its seeds of each objective, taken over runs
that ended ``ok`` with a finite value. A run that did not (aborted, failed, interrupted, never recorded, or
ok with no value of the metric) makes the trial *infeasible*: Optuna's constraint ``runs_not_ok`` is the
number of such runs (> 0). Optuna's samplers and ``best_trial`` rank every infeasible trial below every
feasible one (fewer bad runs first), so a trial with an aborted run can never be the answer, and the
sampler learns that the region is bad without being told an invented number. An infeasible trial with no
value at all is told the worst value there is (-inf when higher is better, +inf when lower is).
"""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

OBJECTIVE_FILE = "objective.json"
OUTCOMES = ("ok", "aborted", "failed", "interrupted", "missing")


class ObjectiveError(ValueError):
    """An objective the tuner cannot optimise; the message names it."""


@dataclass(frozen=True, slots=True)
class Objective:
    metrics: tuple[str, ...]
    directions: tuple[str, ...]     # "higher" | "lower", one per metric

    @property
    def optuna_directions(self) -> list[str]:
        return ["maximize" if d == "higher" else "minimize" for d in self.directions]

    def worst(self) -> list[float]:
        return [-math.inf if d == "higher" else math.inf for d in self.directions]


def as_list(value: Any) -> list[str]:
    """``x`` or ``[x, y]`` (a config string or list) as a list of strings."""
    if value is None:
        return []
    if isinstance(value, str):
        return [v.strip() for v in value.split(",") if v.strip()] if "," in value else [value]
    return [str(v) for v in value]


def known_metrics(config: dict[str, Any]) -> dict[str, str | None]:
    """Every metric a run of ``config`` gets, with its better direction (None: not declared)."""
    from swarmbox.analysis.catalog import BUILTIN, MACHINE_METRICS
    from swarmbox.analysis.mission import parse_specs

    known: dict[str, str | None] = {k: v.direction for k, v in BUILTIN.items() if k not in MACHINE_METRICS}
    for spec in parse_specs(config, []):
        for agg in spec.agg:
            known[f"{spec.name}_{agg}"] = spec.direction_of(agg)
    return known


def resolve(metrics: Sequence[str], directions: Sequence[str], config: dict[str, Any]) -> Objective:
    """The objective of ``metrics`` for a run of ``config``; raises :class:`ObjectiveError`."""
    if not metrics:
        raise ObjectiveError("hydra.sweeper.objective: name the metric(s) to optimise, e.g. "
                             "hydra.sweeper.objective=min_separation_m")
    if len(set(metrics)) != len(metrics):
        raise ObjectiveError(f"hydra.sweeper.objective: a metric is named twice ({list(metrics)})")
    if directions and len(directions) != len(metrics):
        raise ObjectiveError(f"hydra.sweeper.directions: {len(directions)} direction(s) for "
                             f"{len(metrics)} objective(s)")
    known = known_metrics(config)
    algo = (config.get("algo") or {}).get("name", "?")
    out = []
    for i, name in enumerate(metrics):
        if name not in known:
            raise ObjectiveError(
                f"hydra.sweeper.objective: unknown metric '{name}' for algo {algo} (the analyzer's "
                f"built-in metrics and this algorithm's algo.metrics: {', '.join(sorted(known))})")
        direction = directions[i] if directions else known[name]
        if direction not in ("higher", "lower"):
            why = f"got {direction!r}" if directions else "the metric has no better direction"
            raise ObjectiveError(f"hydra.sweeper.directions: higher or lower for '{name}' ({why})")
        out.append(direction)
    return Objective(tuple(metrics), tuple(out))


def run_values(run_dir: Path, metrics: Sequence[str]) -> dict[str, Any]:
    """One run's record for the tuner: status, seed and each objective metric, computed by the
    analyzer from the run's logs (the scalars the sweep analysis computes, with its options)."""
    from swarmbox.analysis.sweep import SweepOptions
    from swarmbox.analysis.sweep import _analyze_one as analyze_one  # the sweep tables' own per-run row

    one = analyze_one(run_dir, run_dir.parent, SweepOptions().run)
    row = one["row"] or {}
    values = {m: _float(row.get(m)) for m in metrics}
    problems = [p["problem"] for p in one["problems"]]
    return {"status": row.get("status", "missing"), "seed": row.get("seed"), "values": values,
            "problems": problems}


def _float(value: Any) -> float:
    try:
        out = float(value)
    except (TypeError, ValueError):
        return math.nan
    return out


def read(run_dir: Path) -> dict[str, Any]:
    """The run's ``objective.json`` (``status: missing`` when the run left no record)."""
    path = run_dir / OBJECTIVE_FILE
    try:
        return json.loads(path.read_text())
    except (OSError, ValueError):
        status = "missing"
        try:
            status = json.loads((run_dir / "run.json").read_text()).get("status", "missing")
        except (OSError, ValueError):
            pass
        return {"status": status, "values": {}, "problems": [f"no {OBJECTIVE_FILE}"]}


@dataclass(frozen=True)
class Score:
    """A trial's (or a re-evaluation's) outcome over its seeds."""

    counts: dict[str, int]          # runs per outcome (OUTCOMES)
    values: dict[str, np.ndarray]   # per metric, the finite values of the ok runs
    not_ok: int                     # runs that make the trial infeasible
    told: list[float]               # what Optuna is told, one per metric

    @property
    def feasible(self) -> bool:
        return self.not_ok == 0


def score(records: Sequence[dict[str, Any]], objective: Objective) -> Score:
    """Counts, values and the told score of a trial's runs (the penalty rule of the module docstring)."""
    counts = dict.fromkeys(OUTCOMES, 0)
    for r in records:
        status = r.get("status")
        counts[status if status in counts else "missing"] += 1
    ok = [r for r in records if r.get("status") == "ok"]
    values, told, not_ok = {}, [], len(records) - len(ok)
    no_value = 0
    for m, worst in zip(objective.metrics, objective.worst(), strict=True):
        arr = np.array([_float(r.get("values", {}).get(m)) for r in ok], dtype="float64")
        no_value = max(no_value, int((~np.isfinite(arr)).sum()))
        values[m] = arr[np.isfinite(arr)]
        told.append(float(values[m].mean()) if values[m].size else worst)
    return Score(counts, values, not_ok + no_value, told)
