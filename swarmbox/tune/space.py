"""A tuning study's search space, read from Hydra's own sweep syntax.

Each override of the command line (and of ``hydra.sweeper.params``) is parsed by Hydra's public override
parser (``hydra.core.override_parser``); a sweep override becomes one dimension of Optuna's search space:

- ``key=interval(a,b)`` -> a float in [a, b]; ``tag(log, interval(a,b))`` on a log scale;
  ``tag(int, interval(a,b))`` an integer in [a, b] (both tags together: an integer on a log scale);
- ``key=range(a,b[,step])`` -> the numbers of the range (b excluded), as an ordered int or float dimension;
- ``key=choice(x,y,...)`` or ``key=x,y,...`` -> a categorical dimension over the values as written.

Every other override is fixed: every job of the study gets it as given.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

from hydra.core.override_parser.overrides_parser import OverridesParser
from hydra.core.override_parser.types import ChoiceSweep, IntervalSweep, Override, RangeSweep


class SpaceError(ValueError):
    """A search-space override the tuner cannot search; the message names it."""


@dataclass(frozen=True, slots=True)
class Dimension:
    """One searched key: its Optuna distribution's arguments (made lazily, optuna imports slowly)."""

    key: str
    kind: str                       # float | int | categorical
    low: float | None = None
    high: float | None = None
    step: float | None = None
    log: bool = False
    choices: tuple[str, ...] = ()   # categorical: the values as written on the command line

    def distribution(self) -> Any:
        from optuna.distributions import CategoricalDistribution, FloatDistribution, IntDistribution

        if self.kind == "categorical":
            return CategoricalDistribution(self.choices)
        if self.kind == "int":
            return IntDistribution(int(self.low), int(self.high), log=self.log, step=int(self.step or 1))
        return FloatDistribution(float(self.low), float(self.high), log=self.log, step=self.step)

    def ends(self) -> tuple[Any, ...]:
        """The values at both ends (every value of a categorical): a bad one fails before the study."""
        return self.choices if self.kind == "categorical" else (self.low, self.high)

    def override(self, value: Any) -> str:
        """``key=value`` for a job (floats in full precision)."""
        if self.kind == "int":
            return f"{self.key}={int(value)}"
        if self.kind == "float":
            return f"{self.key}={float(value)!r}"
        return f"{self.key}={value}"


@dataclass(frozen=True, slots=True)
class Space:
    dimensions: tuple[Dimension, ...]
    fixed: tuple[str, ...]          # overrides every job gets as written

    def defining(self) -> list[str]:
        """The fixed overrides that make the runs what they are (``run.resume``, ``run.progress`` do not)."""
        return [f for f in self.fixed if not f.lstrip("+~").startswith(("run.resume=", "run.progress="))]

    def distributions(self) -> dict[str, Any]:
        return {d.key: d.distribution() for d in self.dimensions}

    def overrides(self, params: dict[str, Any]) -> list[str]:
        return [*self.fixed, *(d.override(params[d.key]) for d in self.dimensions)]

    def describe(self) -> dict[str, str]:
        """Each dimension in one line (stored with the study: a resume must search the same space)."""
        return {d.key: (f"choice{d.choices}" if d.kind == "categorical" else
                        f"{d.kind}[{d.low}, {d.high}]" + (f" step {d.step}" if d.step else "")
                        + (" log" if d.log else "")) for d in self.dimensions}


def _number(x: Any) -> bool:
    return isinstance(x, int | float) and not isinstance(x, bool) and math.isfinite(x)


def _interval(key: str, sweep: IntervalSweep, line: str) -> Dimension:
    tags = set(sweep.tags)
    unknown = tags - {"log", "int"}
    if unknown:
        raise SpaceError(f"{line}: unknown tag(s) {sorted(unknown)} (the tuner reads log and int)")
    low, high = sweep.start, sweep.end
    if not (_number(low) and _number(high)) or low >= high:
        raise SpaceError(f"{line}: an interval needs two finite numbers, low < high")
    if "log" in tags and low <= 0:
        raise SpaceError(f"{line}: a log interval needs low > 0")
    if "int" in tags:
        return Dimension(key, "int", math.ceil(low), math.floor(high), 1, "log" in tags)
    return Dimension(key, "float", float(low), float(high), None, "log" in tags)


def _range(key: str, sweep: RangeSweep, override: Override) -> Dimension:
    values = list(override.sweep_iterator())
    if not values:
        raise SpaceError(f"{override.input_line}: the range is empty")
    if len(values) == 1:
        raise SpaceError(f"{override.input_line}: a range of one value is not a search (give key=value)")
    step = sweep.step
    if all(isinstance(v, int) for v in (sweep.start, step)):
        return Dimension(key, "int", int(values[0]), int(values[-1]), int(step))
    return Dimension(key, "float", float(values[0]), float(values[-1]), float(step))


def _dimension(override: Override) -> Dimension:
    key, sweep, line = override.get_key_element(), override.value(), override.input_line
    if override.is_interval_sweep():
        return _interval(key, sweep, line)
    if override.is_range_sweep():
        return _range(key, sweep, override)
    if isinstance(sweep, ChoiceSweep):
        choices = tuple(dict.fromkeys(override.sweep_string_iterator()))
        if len(choices) < 2:
            raise SpaceError(f"{line}: a choice needs two values at least")
        return Dimension(key, "categorical", choices=choices)
    raise SpaceError(f"{line}: not a search space the tuner reads (interval, range or choice)")


def parse(params: dict[str, str] | None, arguments: Sequence[str]) -> Space:
    """The search space of ``hydra.sweeper.params`` then the command line (a later key replaces an
    earlier one). Raises :class:`SpaceError` naming the override."""
    lines = [f"{k}={v}" for k, v in (params or {}).items()] + list(arguments)
    try:
        overrides = OverridesParser.create().parse_overrides(lines)
    except Exception as exc:  # noqa: BLE001 - Hydra's grammar errors, as one line
        raise SpaceError(str(exc).strip().splitlines()[0]) from None
    dims: dict[str, Dimension] = {}
    fixed: dict[str, str] = {}
    for o in overrides:
        key = o.get_key_element()
        dims.pop(key, None)
        fixed.pop(key, None)
        if o.is_sweep_override():
            dims[key] = _dimension(o)
        else:
            fixed[key] = o.input_line
    return Space(tuple(dims.values()), tuple(fixed.values()))
