"""Every check a tuning study gets before anything is written (bad input: one line, exit 2).

Run from the tuner's callback at the start of the multirun, before the sweep directory is claimed: the
sweeper's settings, the search space (each key must exist, and a parameter must be one the algorithm
declares; each end of its range must pass the run checks of :mod:`swarmbox.run.checks`), the objective
(a metric the analyzer computes for this algorithm, with a direction), the seeds (tuning and held-out
disjoint) and the study directory (an existing study needs ``run.resume=true``).
"""

from __future__ import annotations

import copy
import importlib.util
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from omegaconf import DictConfig, OmegaConf, open_dict

from swarmbox.tune.objective import Objective, ObjectiveError, as_list, resolve
from swarmbox.tune.space import Dimension, Space, SpaceError, parse

STUDY_FILE = "study.db"
SAMPLERS = ("tpe", "random", "cmaes", "nsga2")
_ABSENT = object()


class TuneInputError(ValueError):
    """Bad input to a tuning study; the message names the key."""


@dataclass(frozen=True)
class Plan:
    """What the checks established: the search space, the objective, the seeds."""

    space: Space
    objective: Objective
    seeds: tuple[int, ...]
    heldout_seeds: tuple[int, ...]


def seeds_of(sweeper: Any) -> tuple[tuple[int, ...], tuple[int, ...]]:
    """Tuning seeds ``first_seed ..`` and held-out seeds ``heldout_first_seed ..`` (disjoint ranges)."""
    tuning = tuple(range(int(sweeper.first_seed), int(sweeper.first_seed) + int(sweeper.seeds)))
    held = tuple(range(int(sweeper.heldout_first_seed), int(sweeper.heldout_first_seed)
                       + int(sweeper.heldout_seeds)))
    return tuning, held


def _settings(s: Any) -> None:
    for key, low in (("n_trials", 1), ("seeds", 1), ("heldout_seeds", 1), ("batch_trials", 1)):
        if int(s[key]) < low:
            raise TuneInputError(f"hydra.sweeper.{key} must be >= {low}, got {s[key]}")
    if s.sampler not in SAMPLERS:
        raise TuneInputError(f"hydra.sweeper.sampler must be one of {', '.join(SAMPLERS)}, got '{s.sampler}'")
    if s.sampler == "cmaes" and importlib.util.find_spec("cmaes") is None:
        raise TuneInputError("hydra.sweeper.sampler=cmaes needs the cmaes package (pip install cmaes)")
    tuning, held = seeds_of(s)
    common = sorted(set(tuning) & set(held))
    if common:
        raise TuneInputError(f"hydra.sweeper.heldout_first_seed: held-out seeds {held[0]}..{held[-1]} "
                             f"overlap the tuning seeds {tuning[0]}..{tuning[-1]} (shared: {common[:5]})")


def _declared(cfg: DictConfig, key: str) -> None:
    """``algo.params.<name>``: a parameter the algorithm declares (its Params, else its YAML's params)."""
    import dataclasses

    from swarmbox.run.params import ParamsError, params_class

    name = key.split(".", 2)[2].split(".")[0]
    try:
        schema = params_class(cfg.algo)
    except ParamsError as exc:
        raise TuneInputError(str(exc)) from None
    declared = [f.name for f in dataclasses.fields(schema)] if schema else list(cfg.algo.get("params") or {})
    if name not in declared:
        raise TuneInputError(f"{key}: algorithm '{cfg.algo.get('name')}' declares no parameter '{name}' "
                             f"(declared: {', '.join(declared)})")


def _key(cfg: DictConfig, dim: Dimension, groups: set[str]) -> None:
    key = dim.key
    if key == "seed":
        raise TuneInputError("seed: the tuner chooses the seeds (hydra.sweeper.seeds, first_seed, "
                             "heldout_seeds); remove seed from the search space")
    if key in groups:
        raise TuneInputError(f"{key}: a config group; the tuner searches parameter values (compare "
                             f"{key} options with a sweep: swarmbox run -m {key}=a,b)")
    if key.startswith("hydra."):
        raise TuneInputError(f"{key}: Hydra's own settings are not a search space")
    if key.startswith("algo.params."):
        _declared(cfg, key)
    elif OmegaConf.select(cfg, key, default=_ABSENT) is _ABSENT:
        raise TuneInputError(f"{key}: no such key in the config (swarmbox run --cfg job shows it)")


def _value(dim: Dimension, value: Any) -> Any:
    """A search value as Hydra parses it on the command line (``0.5`` a float, ``x`` a string)."""
    from hydra.core.override_parser.overrides_parser import OverridesParser

    return OverridesParser.create().parse_overrides([dim.override(value)])[0].value()


def _ends_run(cfg: DictConfig, space: Space) -> None:
    """Each end of every dimension (the rest at the config's values) passes the run checks."""
    from swarmbox.run.checks import INPUT_ERRORS, check

    for dim in space.dimensions:
        for end in dim.ends():
            job = copy.deepcopy(cfg)
            OmegaConf.update(job, dim.key, _value(dim, end), merge=False)
            try:
                check(job)
            except INPUT_ERRORS as exc:
                raise TuneInputError(f"{dim.override(end)}: {exc}") from None


def check(config: DictConfig, ends: bool = True) -> Plan:
    """Validate a tuning multirun's master config; raises :class:`TuneInputError` naming the cause.
    ``ends=False`` leaves out the run checks at the ends of the ranges (the slow part, done once)."""
    s = config.hydra.sweeper
    _settings(s)
    callbacks = config.hydra.get("callbacks") or {}
    if not any(str(c.get("_target_", "")).endswith(".TuneCallback") for c in callbacks.values()):
        raise TuneInputError("hydra.callbacks.tune is missing: it computes each run's objective in its "
                             "worker (hydra/sweeper=tune brings it; do not remove it)")
    try:
        space = parse(OmegaConf.to_container(s.params) if s.params else None,
                      list(config.hydra.overrides.task))
        if not space.dimensions:
            raise SpaceError("nothing to search: give a search space, e.g. "
                             "'algo.params.p_rep=interval(0.1,2)'")
        groups = set(config.hydra.runtime.choices.keys()) if "runtime" in config.hydra else set()
        job = copy.deepcopy(config)
        with open_dict(job):
            del job["hydra"]   # the job's config, as the task function gets it
        with_fixed_seed = [f for f in space.fixed if f.lstrip("+~").split("=")[0] == "seed"]
        if with_fixed_seed:
            raise TuneInputError(f"{with_fixed_seed[0]}: the tuner chooses the seeds (hydra.sweeper.seeds)")
        for dim in space.dimensions:
            _key(job, dim, groups)
        container = OmegaConf.to_container(job, resolve=True)
        objective = resolve(as_list(s.objective), as_list(s.directions), container)
    except (SpaceError, ObjectiveError) as exc:
        raise TuneInputError(str(exc)) from None
    if s.sampler == "cmaes" and len(objective.metrics) > 1:
        raise TuneInputError("hydra.sweeper.sampler=cmaes optimises one objective; use tpe or nsga2")
    if ends:
        _ends_run(job, space)
    study = Path(str(config.hydra.sweep.dir)) / STUDY_FILE
    if study.exists() and not config.run.resume:
        raise TuneInputError(f"{study} holds a study: continue it with run.resume=true, or choose another "
                             "hydra.sweep.dir")
    tuning, held = seeds_of(s)
    return Plan(space, objective, tuning, held)
