"""Which jobs of a sweep to compose before launching, to catch a bad override early.

A job is a list of override strings (``algo=hover``, ``seed=3``, ``+experiment=rq4_delivery``,
``~hydra.callbacks.analyze``). Whether a config *composes* depends on the config groups it selects
(their files, their defaults, their schemas) and on each value set on top of them. So composing one
job per distinct combination of group choices, plus one for every ``key=value`` not covered yet,
checks every file and every value of the sweep at least once.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence


def override_key(override: str) -> str:
    """``+algo.params.x=1`` -> ``algo.params.x``; ``~hydra.callbacks.analyze`` -> the same without ``~``."""
    key = override.split("=", 1)[0]
    return key.lstrip("+~")


def jobs_to_check(batch: Sequence[Sequence[str]], is_group: Callable[[str], bool]) -> list[Sequence[str]]:
    """A covering subset of ``batch``, in its order: the first job of every distinct combination of
    group overrides, and any job with a non-group override not seen in an earlier chosen job."""
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
        rest = [o for o in job if not group_memo[override_key(o)]]
        if signature not in signatures or any(o not in values for o in rest):
            chosen.append(job)
            signatures.add(signature)
            values.update(rest)
    return chosen
