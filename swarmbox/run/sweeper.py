"""The jobs of a sweep (the basic sweeper's: every combination, in order, in batches) and which of
them to compose before launching, to catch a bad override early.

:func:`sweep_jobs` makes the jobs from Hydra's parsed overrides (``hydra.core.override_parser``): the
cartesian product of every key's values, keys in the order they first appear (``hydra.sweeper.params``
first, the command line after, a later value of a key replacing an earlier one in place), split into
batches of ``max_batch_size`` jobs.

A job is a list of override strings (``algo=hover``, ``seed=3``, ``+experiment=rq4_delivery``,
``~hydra.callbacks.analyze``). Whether a config *composes* depends on the config groups it selects
(their files, their defaults, their schemas) and on each value set on top of them. So composing one
job per distinct combination of group choices, plus one for every ``key=value`` not covered yet,
checks every file and every value of the sweep at least once. Numbers count as one value per key
(``seed=0`` ... ``seed=19`` compose alike: a config types a key, it does not list its numbers), so a
twenty-seed sweep composes one of them; ``seed=1x`` is not a number and is checked on its own.
"""

from __future__ import annotations

import itertools
import re
from collections.abc import Callable, Sequence

from hydra.core.override_parser.types import Override
from hydra.errors import HydraException

_NUMBER = re.compile(r"[+-]?(\d+(\.\d*)?|\.\d+)([eE][+-]?\d+)?")


def override_key(override: str) -> str:
    """``+algo.params.x=1`` -> ``algo.params.x``; ``~hydra.callbacks.analyze`` -> the same without ``~``."""
    key = override.split("=", 1)[0]
    return key.lstrip("+~")


def _value_class(override: str) -> str:
    """``seed=3`` -> ``seed=<int>``, ``x=0.5`` -> ``x=<float>``: numbers of one key compose alike."""
    key, sep, value = override.partition("=")
    if sep and _NUMBER.fullmatch(value):
        return f"{key}=<{'int' if value.lstrip('+-').isdigit() else 'float'}>"
    return override


def jobs_to_check(batch: Sequence[Sequence[str]], is_group: Callable[[str], bool]) -> list[Sequence[str]]:
    """A covering subset of ``batch``, in its order: the first job of every distinct combination of
    group overrides, and any job with a non-group override (numbers: of a number type for its key)
    not seen in an earlier chosen job."""
    chosen: list[Sequence[str]] = []
    signatures: set[tuple[str, ...]] = set()
    values: set[str] = set()
    group_memo: dict[str, bool] = {}
    for job in batch:
        grouped = []
        for o in job:
            key = override_key(o)
            if key not in group_memo:
                group_memo[key] = is_group(key)
            if group_memo[key]:
                grouped.append(o)
        signature = tuple(sorted(grouped))
        rest = [_value_class(o) for o in job if not group_memo[override_key(o)]]
        if signature not in signatures or any(o not in values for o in rest):
            chosen.append(job)
            signatures.add(signature)
            values.update(rest)
    return chosen


def sweep_jobs(overrides: Sequence[Override], max_batch_size: int | None) -> list[list[list[str]]]:
    """The batches of jobs of a sweep, each job a list of ``key=value`` strings (one per key)."""
    values: dict[str, list[str]] = {}
    for override in overrides:
        key = override.get_key_element()
        if not override.is_sweep_override():
            values[key] = [f"{key}={override.get_value_element_as_str()}"]
        elif override.is_discrete_sweep():
            values[key] = [f"{key}={v}" for v in override.sweep_string_iterator()]
        else:   # interval(a,b): for optimising sweepers, not a list of jobs
            raise HydraException(f"the swarmbox sweeper cannot sweep {override.input_line!r}: "
                                 "an interval has no list of values (use choices or range())")
    jobs = [list(job) for job in itertools.product(*values.values())]
    if max_batch_size is not None and max_batch_size <= 0:
        raise HydraException(f"hydra.sweeper.max_batch_size={max_batch_size}: a batch needs a job at least")
    if max_batch_size is None:
        return [jobs]
    return [jobs[i:i + max_batch_size] for i in range(0, len(jobs), max_batch_size)]
