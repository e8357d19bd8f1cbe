"""Who a run is: its configuration (every override but the seed), and how a sweep's runs group and pair.

A run's *identity* is read from its ``run.json``: the config-group choices (``choices``: algo, mission,
network, ...) and every other override it was started with (``overrides``: ``network.loss_prob=0.2``,
``algo.params.hover_s=1``), never from directory names. Overrides that change how a run is shown or
stored but not what it computes (``run.progress``, ``run.resume``, the dashboard, the log writer) are
not part of it, nor is ``seed``: runs that differ only in the seed are repetitions of one configuration.

A sweep's :class:`Design` splits the identity columns that vary across its runs into the *compared
factor* (``group_by``) and the *strata* (everything else that varies, e.g. ``mission`` or a swept
``network.loss_prob``). Groups are compared, paired and ranked only inside one stratum; two levels of the
compared factor that never share a stratum (``-m algo=hover,formation``: each algorithm flies its own
mission) are reported as not comparable and never ranked against each other.
"""

from __future__ import annotations

import itertools
from collections.abc import Iterable
from dataclasses import dataclass
from typing import Any

import pandas as pd

#: Overrides that do not change what a run computes (display, storage, resumption).
NOT_IDENTITY = frozenset({"seed", "run.resume", "run.progress", "run.monitor", "run.monitor_hz", "run.rerun",
                          "run.out_dir", "run.log_writer"})
#: Value of an identity column a run did not override (it ran on the default).
DEFAULT = "(default)"
#: Identity keys that name what is flown: never chosen as the compared factor automatically.
MISSION_KEYS = ("mission",)


class SweepInputError(ValueError):
    """A sweep whose runs cannot be tabulated as asked (unknown group-by key, duplicate runs)."""


def override_items(overrides: Iterable[str]) -> dict[str, str]:
    """``key -> value`` of Hydra overrides (``+``/``++`` prefixes dropped, ``~key`` = deleted)."""
    out: dict[str, str] = {}
    for text in overrides:
        text = str(text).lstrip("+")
        deleted = text.startswith("~")
        key, _, value = text.lstrip("~").partition("=")
        key = key.strip()
        if not key or key in NOT_IDENTITY or key.startswith(("hydra.", "hydra/")):
            continue
        out[key] = "(deleted)" if deleted else value.strip()
    return out


def run_identity(manifest: dict[str, Any]) -> dict[str, str]:
    """The identity of a run from its manifest: overrides, with the recorded group choices winning."""
    choices = {str(k): str(v) for k, v in (manifest.get("choices") or {}).items()}
    return {**override_items(manifest.get("overrides") or []), **choices}


@dataclass(frozen=True)
class Design:
    """How a sweep's runs are tabulated."""

    identity: tuple[str, ...]   # every identity column of the sweep
    group_by: tuple[str, ...]   # the compared factor
    strata: tuple[str, ...]     # the other identity columns that vary: compared only within one value

    @property
    def keys(self) -> tuple[str, ...]:
        """Columns of a summary group: the compared factor, then the strata."""
        return (*self.group_by, *self.strata)


def varying(runs: pd.DataFrame, columns: Iterable[str]) -> list[str]:
    return [c for c in columns if c in runs.columns and runs[c].nunique(dropna=False) > 1]


def design(runs: pd.DataFrame, identity: list[str], requested: tuple[str, ...] | None) -> Design:
    """The sweep's design. ``requested`` None: ``algo`` if it varies, else every varying non-mission key,
    else ``algo``. Raises :class:`SweepInputError` for a group-by key no run has."""
    moving = varying(runs, identity)
    if requested:
        unknown = [g for g in requested if g not in identity]
        if unknown:
            raise SweepInputError(f"group-by key(s) {unknown} are not among the runs' choices and overrides "
                                  f"({', '.join(sorted(identity)) or 'none'})")
        group_by = tuple(requested)
    elif "algo" in moving or not moving:
        group_by = ("algo",) if "algo" in identity else ()
    else:
        group_by = tuple(c for c in moving if c not in MISSION_KEYS) or tuple(moving)
    return Design(tuple(identity), group_by, tuple(c for c in moving if c not in group_by))


def check_unique(runs: pd.DataFrame, identity: tuple[str, ...]) -> None:
    """Raise :class:`SweepInputError` when two runs share their configuration and seed."""
    seeded = runs[runs["seed"].notna()] if "seed" in runs else runs.iloc[0:0]
    cols = [*identity, "seed"]
    dup = seeded[seeded.duplicated(cols, keep=False)]
    if len(dup):
        first = dup.sort_values("run").groupby(cols, dropna=False)["run"].apply(list).iloc[0]
        raise SweepInputError(f"runs {', '.join(map(str, first))} have the same configuration and seed: "
                              "a run's identity (overrides + seed) must be unique in a sweep")


def labels(runs: pd.DataFrame, columns: Iterable[str]) -> pd.Series:
    """Each row's label over ``columns`` ("a/b"); "all" when there are no columns."""
    cols = list(columns)
    if not cols:
        return pd.Series("all", index=runs.index, dtype="object")
    return runs[cols].astype("str").agg("/".join, axis=1)


def comparable_pairs(runs: pd.DataFrame, d: Design) -> tuple[list[tuple[str, str, str]], list[str]]:
    """(stratum, a, b) for every two groups that share a stratum, and one warning per two groups that
    never do (they differ in more than the compared factor)."""
    group, stratum = labels(runs, d.group_by), labels(runs, d.strata)
    where = {g: set(stratum[group == g]) for g in sorted(group.unique())}
    pairs, warnings = [], []
    for a, b in itertools.combinations(where, 2):
        shared = sorted(where[a] & where[b])
        pairs += [(s, a, b) for s in shared]
        if not shared:
            warnings.append(not_comparable(runs, d, a, b, group))
    return pairs, warnings


def not_comparable(runs: pd.DataFrame, d: Design, a: str, b: str, group: pd.Series) -> str:
    """One line: groups ``a`` and ``b`` also differ in which strata values."""
    parts = []
    for col in d.strata:
        va, vb = (sorted(set(runs.loc[group == g, col].astype("str"))) for g in (a, b))
        if va != vb:
            parts.append(f"{col} ({a}: {','.join(va)}; {b}: {','.join(vb)})")
    what = "/".join(d.group_by) or "group"
    return (f"not comparable: {what} {a} and {b} also differ in {'; '.join(parts)}; "
            "they are neither paired nor ranked against each other")
