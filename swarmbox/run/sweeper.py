"""Which jobs of a sweep to compose before launching, to catch a bad override early.

A job is a list of override strings (``algo=hover``, ``seed=3``, ``+experiment=rq4_delivery``,
``~hydra.callbacks.analyze``). Whether a config *composes* depends on the config groups it selects
(their files, their defaults, their schemas) and on each value set on top of them. So composing one
job per distinct combination of group choices, plus one for every ``key=value`` not covered yet,
checks every file and every value of the sweep at least once. Numbers count as one value per key
(``seed=0`` ... ``seed=19`` compose alike: a config types a key, it does not list its numbers), so a
twenty-seed sweep composes one of them; ``seed=1x`` is not a number and is checked on its own.
"""

from __future__ import annotations

import re
from collections.abc import Callable, Sequence

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
