"""Mission-specific metrics computed from user event markers declared in the algorithm config.

``algo.metrics`` is a list of mappings::

    metrics:
      - {name: delivery_wait_s, marker: delivered, node: ground, measure: since_exec_start,
         agg: [mean, max, count]}
      - {name: formation_error_m, marker: formation_error, node: any, field: error_m, agg: [mean, max]}

Keys:
- ``name`` (required): prefix of the produced metrics, one per aggregate: ``<name>_<agg>``;
- ``marker`` (required): the marker name (events of kind ``marker`` with this ``name``);
- ``node``: whose markers count: ``any`` (default), ``ground``, ``drones`` or ``drone_<i>``;
- the value of one marker is either ``measure: since_exec_start`` (its unified time - ground
  EXECUTION start, s) or ``field: X`` (the number under key X of the marker's data); with neither, every
  marker counts 1 (useful with ``sum``/``count``). Markers whose field is missing or not a number are
  skipped;
- ``agg``: list of ``mean``, ``max``, ``min``, ``sum``, ``count``, ``last`` (latest by time) and
  ``std`` (population, ddof 0); default ``[mean]``. Over no markers ``count`` and ``sum`` are 0, the rest NaN;
- ``direction``: ``lower`` or ``higher`` is better, for the tables and ``compare``; default ``lower``
  (``higher`` for ``count``).

Markers are taken from the whole run, not only EXECUTION.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from typing import Any

import numpy as np
import pandas as pd

from swarmbox.analysis.catalog import Direction
from swarmbox.analysis.load import node_id
from swarmbox.analysis.unify import T

AGGS = ("mean", "max", "min", "sum", "count", "last", "std")


@dataclass(frozen=True, slots=True)
class MarkerMetric:
    name: str
    marker: str
    node: str = "any"
    measure: str | None = None
    field: str | None = None
    agg: tuple[str, ...] = ("mean",)
    direction: Direction = None

    def direction_of(self, agg: str) -> Direction:
        if self.direction:
            return self.direction
        return "higher" if agg == "count" else "lower"


class MetricSpecError(ValueError):
    """A malformed entry of ``algo.metrics``."""


def parse_spec(entry: Any) -> MarkerMetric:
    if not isinstance(entry, dict) or not entry.get("name") or not entry.get("marker"):
        raise MetricSpecError(f"metric entry {entry!r} needs at least 'name' and 'marker'")
    agg = entry.get("agg", ["mean"])
    agg = (agg,) if isinstance(agg, str) else tuple(agg)
    bad = [a for a in agg if a not in AGGS]
    if bad:
        raise MetricSpecError(f"metric {entry['name']}: unknown agg {bad}, use {list(AGGS)}")
    measure, fld = entry.get("measure"), entry.get("field")
    if measure not in (None, "since_exec_start"):
        raise MetricSpecError(f"metric {entry['name']}: unknown measure {measure!r}")
    if measure and fld:
        raise MetricSpecError(f"metric {entry['name']}: give 'measure' or 'field', not both")
    direction = entry.get("direction")
    if direction not in (None, "lower", "higher"):
        raise MetricSpecError(f"metric {entry['name']}: direction must be lower or higher")
    node = str(entry.get("node", "any"))
    if node not in ("any", "drones") and node_id(node) is None:
        raise MetricSpecError(f"metric {entry['name']}: node must be any, drones, ground or drone_<i>")
    return MarkerMetric(str(entry["name"]), str(entry["marker"]), node, measure, fld, agg, direction)


def parse_specs(config: dict[str, Any], problems: list[str]) -> list[MarkerMetric]:
    """Marker metrics declared under ``algo.metrics``; malformed entries are reported and skipped."""
    entries = ((config.get("algo") or {}).get("metrics")) or []
    specs = []
    for entry in entries if isinstance(entries, list) else []:
        try:
            specs.append(parse_spec(entry))
        except MetricSpecError as exc:
            problems.append(str(exc))
    return specs


def _node_filter(events: pd.DataFrame, node: str) -> pd.Series:
    if node == "any":
        return pd.Series(True, index=events.index)
    if node == "drones":
        return events["node"] >= 0
    return events["node"] == node_id(node)


def _field(data: str, key: str) -> float:
    try:
        value = json.loads(data).get(key) if data else None
        return float(value) if value is not None and not isinstance(value, bool) else np.nan
    except (ValueError, TypeError, AttributeError):
        return np.nan


def marker_values(events: pd.DataFrame, spec: MarkerMetric, exec_start: float) -> pd.Series:
    """The value of every marker counted by ``spec``, indexed by unified time, sorted."""
    rows = events[(events["kind"] == "marker") & (events["name"] == spec.marker)
                  & _node_filter(events, spec.node)].sort_values(T)
    if spec.measure == "since_exec_start":
        values = rows[T] - exec_start
    elif spec.field:
        values = rows["data"].map(lambda d: _field(d, spec.field)).astype("float64")
    else:
        values = pd.Series(1.0, index=rows.index)
    values.index = rows[T].to_numpy()
    return values.dropna()


def aggregate(values: pd.Series, agg: str) -> float:
    if agg == "count":
        return float(len(values))
    if agg == "sum":
        return float(values.sum())
    if values.empty:
        return np.nan
    if agg == "last":
        return float(values.iloc[-1])
    if agg == "std":
        return float(np.std(values.to_numpy(), ddof=0))
    return float(getattr(values, agg)())


def mission_metrics(events: pd.DataFrame, specs: list[MarkerMetric],
                    exec_start: float) -> tuple[dict[str, float], dict[str, Direction]]:
    """``<name>_<agg>`` values of every declared metric, and their better direction."""
    values: dict[str, float] = {}
    directions: dict[str, Direction] = {}
    for spec in specs:
        series = marker_values(events, spec, exec_start)
        for agg in spec.agg:
            values[f"{spec.name}_{agg}"] = aggregate(series, agg)
            directions[f"{spec.name}_{agg}"] = spec.direction_of(agg)
    return values, directions


def marker_table(events: pd.DataFrame, specs: list[MarkerMetric], exec_start: float) -> pd.DataFrame:
    """Tidy per-marker values: metric, t_u, value (for the per-run CSV)."""
    parts = [pd.DataFrame({"metric": s.name, T: v.index, "value": v.to_numpy()})
             for s in specs if len(v := marker_values(events, s, exec_start))]
    return pd.concat(parts, ignore_index=True) if parts else pd.DataFrame(columns=["metric", T, "value"])

