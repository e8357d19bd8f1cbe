"""Scoring an onset-agnostic diagnosis against the injected ground truth, afterwards.

The analyzer (:mod:`.diagnosis`) never sees the fault events; this module reads them and grades its
alarms. Definitions (paper section 5.3, with the deliberate differences in brackets):

- **t_f**: from the fault's onset to the target's first alarm while the fault is on. [The paper
  counts to the first deviation of the metric; here an alarm needs its flags to hold for
  ``persist_s`` and is stamped at the grid point the persistence is reached, so t_f includes that
  confirmation time but no window-length rounding.]
- **tau_d**: the target's metric value at that alarm. **Sigma_a**: its score, the distance beyond
  the fence in IQRs of the swarm at that tick. [The paper's sentence reads as "the IQR"; its code,
  and this one, divide the excess by the IQR.]
- **detected**: the target raised an alarm while the fault was on (onset to end);
  **localized**: the *first* alarm while the fault was on named the target (which drone); alarms
  on the target of another fault of the same run (composed faults) are that fault's and skipped;
  **metric**: the metric of that first alarm (which metric).
- **false alarms**: alarm incidents (a drone's overlapping episodes on any metric merged into one)
  that start in healthy time: outside every fault window and the ``grace_s`` after it, where the
  swarm recovers (a GNSS fix jumping back, a backlog draining). Their rate is per drone-hour of
  healthy time in the scan span.
- **measured**: for network faults, the target's mean latency (loss ratio) over the fault window
  minus the median of the other drones' — the magnitude as recovered.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from swarmbox.analysis import network
from swarmbox.analysis.unify import T

GRACE_S = 10.0
GROUND = -1     # a fault's target id for the ground node


@dataclass(frozen=True)
class Truth:
    name: str               # fault model, e.g. "gps_drift"
    target: int | None
    onset_u: float
    end_u: float | None     # None: until the end of the run
    params: dict = field(default_factory=dict)


def ground_truth(events: pd.DataFrame) -> list[Truth]:
    """The injected faults, from the ground's ``fault`` events (``<model>_start`` / ``<model>_end``)."""
    ev = events[events["kind"] == "fault"].sort_values(T)
    out = []
    for _, row in ev[ev["name"].str.endswith("_start")].iterrows():
        name = str(row["name"]).removesuffix("_start")
        try:
            data = json.loads(row["data"]) if row["data"] else {}
        except ValueError:
            data = {}
        data = data if isinstance(data, dict) else {}
        target = data.get("target")
        target = int(target) if isinstance(target, int | float) and not isinstance(target, bool) else None
        ends = ev[(ev["name"] == f"{name}_end") & (ev[T] >= row[T])]
        if target is not None:
            ends = ends[[_target_of(d) == target for d in ends["data"]]]
        end = float(ends[T].iloc[0]) if len(ends) else None
        out.append(Truth(name, target, float(row[T]), end, data))
    return out


def scored_truths(truths: list[Truth], drones: list[int]) -> list[Truth]:
    """The truths a run is scored on: one per (fault, onset) that targets some drones, one per
    target drone; a fault that hits every drone (or the ground, target -1) at once becomes a single
    swarm-wide truth with ``target`` None, detected by an alarm on any drone."""
    groups: dict[tuple[str, float], list[Truth]] = {}
    for t in truths:
        groups.setdefault((t.name, t.onset_u), []).append(t)
    out = []
    for (name, onset), group in groups.items():
        targets = {t.target for t in group}
        if None in targets or GROUND in targets or (drones and targets >= set(drones)):
            ends = [t.end_u for t in group]
            end = None if None in ends else max(ends)
            params = {k: v for k, v in group[0].params.items() if k != "target"}
            out.append(Truth(name, None, onset, end, params))
        else:
            out.extend(group)
    return sorted(out, key=lambda t: (t.onset_u, t.name, -1 if t.target is None else t.target))


def _target_of(data: str) -> int | None:
    try:
        value = json.loads(data).get("target") if data else None
    except (ValueError, AttributeError):
        return None
    return int(value) if isinstance(value, int | float) and not isinstance(value, bool) else None


def incidents(alarms: pd.DataFrame) -> pd.DataFrame:
    """A drone's alarm episodes merged while they overlap (any metric): t_u, end_u, drone, metric
    (of the first episode), value, score."""
    rows = []
    for drone, g in alarms.sort_values([T, "end_u"]).groupby("drone", sort=True):
        current = None
        for rec in g.to_dict("records"):
            if current is not None and rec[T] <= current["end_u"]:
                current["end_u"] = max(current["end_u"], rec["end_u"])
                continue
            if current is not None:
                rows.append(current)
            current = {T: rec[T], "end_u": rec["end_u"], "drone": int(drone), "metric": rec["metric"],
                       "value": rec["value"], "score": rec["score"]}
        rows.append(current)
    return pd.DataFrame(rows, columns=[T, "end_u", "drone", "metric", "value", "score"]).sort_values(
        [T, "drone"]).reset_index(drop=True)


def _faulty(truths: list[Truth], span_end: float, grace_s: float) -> list[tuple[float, float]]:
    return [(t.onset_u, (t.end_u if t.end_u is not None else span_end) + grace_s) for t in truths]


def healthy_time(span: tuple[float, float], truths: list[Truth], grace_s: float = GRACE_S) -> float:
    """Seconds of the scan span outside every fault window (+ grace)."""
    start, end = span
    cut = 0.0
    merged: list[list[float]] = []
    for a, b in sorted(_faulty(truths, end, grace_s)):
        a, b = max(a, start), min(b, end)
        if b <= a:
            continue
        if merged and a <= merged[-1][1]:
            merged[-1][1] = max(merged[-1][1], b)
        else:
            merged.append([a, b])
    cut = sum(b - a for a, b in merged)
    return max(end - start - cut, 0.0)


def false_alarms(times: np.ndarray, span: tuple[float, float], truths: list[Truth],
                 grace_s: float = GRACE_S) -> int:
    """How many alarm (incident) start times fall in healthy time."""
    times = np.asarray(times, dtype="float64")
    inside = (times >= span[0]) & (times <= span[1])
    for a, b in _faulty(truths, span[1], grace_s):
        inside &= ~((times >= a) & (times <= b))
    return int(inside.sum())


def score_alarms(alarms: pd.DataFrame, truth: Truth | None, span: tuple[float, float], n_drones: int,
                 grace_s: float = GRACE_S) -> dict:
    """One run's grade against one truth: detection, localization, t_f / tau_d / Sigma_a, and false
    alarms. A swarm-wide truth (target None) is detected and localized by an alarm on any drone."""
    [row] = score_truths(alarms, [truth] if truth is not None else [], span, n_drones, grace_s)
    return row


def score_truths(alarms: pd.DataFrame, truths: list[Truth], span: tuple[float, float], n_drones: int,
                 grace_s: float = GRACE_S) -> list[dict]:
    """One grade per truth (one row when there is none). False alarms and healthy time are counted
    once per run, outside every truth's window, and sit on the first row (0 on the others), so that
    summing rows never counts a run's healthy flight twice."""
    inc = incidents(alarms) if len(alarms) else pd.DataFrame(columns=[T, "drone"])
    common = {"false_alarms": false_alarms(inc[T].to_numpy(), span, truths, grace_s),
              "healthy_drone_h": healthy_time(span, truths, grace_s) * n_drones / 3600.0}
    if not truths:
        return [common]
    rest = {"false_alarms": 0, "healthy_drone_h": 0.0}
    targets = {t.target for t in truths if t.target is not None}
    return [(common if i == 0 else rest) | _grade(alarms, t, span, targets - {t.target})
            for i, t in enumerate(truths)]


def _grade(alarms: pd.DataFrame, truth: Truth, span: tuple[float, float], others: set[int]) -> dict:
    """``others``: the drones another injected fault of the run targets. An alarm on one of them is
    that fault's answer, so it neither localizes nor mislocalizes this one (composed faults)."""
    end = truth.end_u if truth.end_u is not None else span[1]
    during = alarms[(alarms[T] >= truth.onset_u) & (alarms[T] <= end)]
    mine = during if truth.target is None else during[during["drone"] == truth.target]
    if truth.target is not None and others:
        during = during[~during["drone"].isin(others)]
    first_drone = int(during.iloc[0]["drone"]) if len(during) else None
    localized = first_drone is not None and (truth.target is None or first_drone == truth.target)
    row = {"detected": bool(len(mine)), "localized": localized, "first_drone": first_drone,
           "first_metric": str(during.iloc[0]["metric"]) if len(during) else None}
    if len(mine):
        first = mine.iloc[0]
        row |= {"t_f_s": float(first[T] - truth.onset_u), "tau_d": float(first["value"]),
                "sigma_a": float(first["score"]), "metric": str(first["metric"])}
    return row


def measured_excess(flow: pd.DataFrame, drones: list[int], truth: Truth) -> float:
    """Target's latency (ms) or loss ratio over the fault window minus the median of the other drones'."""
    cols = {"latency": "latency_ms_mean", "packet_loss": "loss_ratio", "burst_loss": "loss_ratio"}
    col = cols.get(truth.name)
    if col is None or truth.target is None or truth.end_u is None:
        return np.nan
    window = network.between(flow, truth.onset_u, truth.end_u)
    values = network.agent_stats(window, truth.end_u - truth.onset_u).set_index("agent")[col].reindex(drones)
    if pd.isna(values.get(truth.target)):
        return np.nan
    others = values.drop(truth.target).dropna()
    return float(values[truth.target] - (others.median() if len(others) else 0.0))
