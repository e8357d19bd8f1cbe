"""Onset-agnostic fault diagnosis: from the logs alone, is a drone misbehaving, which one, on which
metric, and since when. Nothing here reads the injected faults; :mod:`.scoring` compares the answer
with the ground truth afterwards.

Series (:func:`drone_series`). Every monitored metric is put on the run's sample grid: one step is
the time a drone's state row stands for, tick length x ``run.state_every_ticks`` as logged
(:mod:`.sampling`), so a run logged every 4th tick is scanned on a 4-tick grid instead of a grid
where three cells in four are empty. A sample at unified time t belongs to the *nearest* grid point,
round(t / step): the clock offsets :func:`unify` estimates are off by microseconds even when no
offset is injected, so a floor with a tiny epsilon would drop samples into the previous cell at
random. A series with fewer samples than its grid has points is reported (``Series.problems``): its
persistence cannot be met as configured. Per drone and grid point:

- ``disc_n_m``, ``disc_e_m``, ``disc_d_m``: GNSS - estimate, mean of the drone's state samples;
- ``latency_ms``: mean latency of the delivered messages it sent or that were sent to it, by the
  tick of their *receive* time (a latency is known only once the message has arrived);
- ``loss_ratio``: lost / counted among its messages sent in the trailing ``loss_window_s``
  (a sliding window evaluated every tick, stamped at its last send tick).

Detection (:func:`scan`), per metric and tick, across *all* drones (cross-sectional, as in the
paper's section 5.3: the "statistical norm" is the rest of the swarm at that tick):

- ``rule="tukey"`` (default): fences q1 - k IQR and q3 + k IQR with k = 1.5, both tails, and
  |v - median| >= min deviation (1.5 m, 1 ms, 5 %) times ``threshold_scale``;
- ``rule="paper"``: the reference's detector, fences at 2.5 IQR, upper tail only, v > the same
  thresholds (absolute);
- score = distance beyond the crossed fence in IQRs (+inf when IQR = 0);
- a (drone, metric) is *in alarm* once flagged for ``persist_s`` (0.1 s): on
  ceil(persist_s / step) consecutive grid points, at least one; an alarm episode starts at the point
  the persistence is reached (the first moment it is known) and lasts while the flags continue. Its
  value and score are those of that point.

The scan covers the ground's EXECUTION stage (take-off and landing are manoeuvres every drone makes
at different times, not a norm to compare against). The diagnosis of a run (:func:`finding`) is its
first alarm: drone, metric, when (``t_u``), value (tau_d) and score (Sigma_a).

Per-drone baseline (:func:`estimator_alarms`): every estimator position reset a drone logs is an alarm
for that drone (PX4 EKF2's ``reset_count_pos_ne``, what a single-drone log shows).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from swarmbox.analysis import metrics, network, sampling, windows
from swarmbox.analysis.flagruns import FlagRuns
from swarmbox.analysis.load import GROUND, RunData
from swarmbox.analysis.unify import T

DISC = ("disc_n_m", "disc_e_m", "disc_d_m")
#: estimator events that are baseline alarms (the sim logs position_reset; PX4's ULog all three)
BASELINE_EVENTS = ("position_reset", "dead_reckoning", "gnss_fusion_lost")
METRICS = (*DISC, "latency_ms", "loss_ratio")
MIN_DEVIATION = {"disc_n_m": 1.5, "disc_e_m": 1.5, "disc_d_m": 1.5, "latency_ms": 1.0, "loss_ratio": 0.05}
RULES = {"tukey": 1.5, "paper": 2.5}
ALARM_COLUMNS = [T, "metric", "drone", "value", "score", "median", "iqr", "end_u"]
_IQR_EPS = 1e-12
#: Grid step when a run says nothing of its tick (no run.json ``tick_s``, no config, no state rows).
FALLBACK_STEP_S = 0.025
#: Below this fraction of grid points with a sample (median drone), a series is reported as sparse.
MIN_COVERAGE = 0.9


@dataclass(frozen=True)
class DiagnosisOptions:
    step_s: float | None = None        # grid step, s; None: the run's state period (sampling.py)
    loss_window_s: float = 2.5
    rule: str = "tukey"
    threshold_scale: float = 1.0
    persist_s: float = 0.1             # how long a flag must hold before it is an alarm
    min_n: int = 3
    min_deviation: Mapping[str, float] = field(default_factory=dict)   # overrides per metric
    stage: str = "EXECUTION"

    def __post_init__(self) -> None:
        if self.rule not in RULES:
            raise ValueError(f"rule {self.rule!r} is not one of {sorted(RULES)}")
        if self.persist_s < 0 or self.loss_window_s <= 0 or (self.step_s is not None and self.step_s <= 0):
            raise ValueError("persist_s >= 0, loss_window_s > 0 and step_s > 0 (or None) are required")

    def threshold(self, metric: str) -> float:
        return float({**MIN_DEVIATION, **self.min_deviation}[metric]) * self.threshold_scale

    def persist_points(self, step_s: float) -> int:
        """Consecutive flagged grid points of ``step_s`` that make ``persist_s``: at least one."""
        return max(1, int(np.ceil(self.persist_s / step_s - 1e-9)))


@dataclass
class Series:
    """Metric matrices on the sample grid: ``values[metric]`` has shape (len(ticks), len(drones))."""

    ticks: np.ndarray            # grid indices (t_u = index * step_s)
    drones: list[int]
    values: dict[str, np.ndarray]
    step_s: float
    problems: list[str] = field(default_factory=list)   # e.g. a series sparser than its grid

    def times(self) -> np.ndarray:
        return self.ticks * self.step_s

    def tidy(self) -> pd.DataFrame:
        """Long form: t_u, drone, metric, value (NaN cells dropped)."""
        parts = []
        for metric, mat in self.values.items():
            t, d = np.nonzero(np.isfinite(mat))
            parts.append(pd.DataFrame({T: self.ticks[t] * self.step_s, "drone": np.asarray(self.drones)[d],
                                       "metric": metric, "value": mat[t, d]}))
        if not parts:
            return pd.DataFrame(columns=[T, "drone", "metric", "value"])
        return pd.concat(parts, ignore_index=True)


def nearest_tick(t_u: np.ndarray | pd.Series, step_s: float) -> np.ndarray:
    """Index of the nearest grid point of step ``step_s``."""
    return np.rint(np.asarray(t_u, dtype="float64") / step_s).astype("int64")


def grid_step(run: RunData, opts: DiagnosisOptions) -> float:
    """The grid step: ``opts.step_s``, else the run's state period, else :data:`FALLBACK_STEP_S`."""
    step = opts.step_s if opts.step_s is not None else sampling.state_period_s(run)
    return float(step) if np.isfinite(step) and step > 0 else FALLBACK_STEP_S


def scan_span(run: RunData, stage: str = "EXECUTION") -> tuple[float, float]:
    """Unified start and end of the ground's ``stage`` (end: its next stage, or the last record)."""
    st = run.tables["stages"]
    ground = st[st["node"] == GROUND].sort_values(T)
    rows = ground[ground["name"] == stage]
    if rows.empty:
        raise ValueError(f"{run.path}: the ground never entered {stage}; nothing to scan")
    start = float(rows[T].iloc[0])
    later = ground[ground[T] > start]
    end = float(later[T].iloc[0]) if len(later) else float(run.tables["state"][T].max())
    return start, end


def _matrix(frame: pd.DataFrame, col: str, ticks: np.ndarray, drones: list[int],
            how: str = "mean") -> np.ndarray:
    out = np.full((len(ticks), len(drones)), np.nan)
    if frame.empty:
        return out
    grouped = frame.groupby(["tick", "drone"])[col].agg(how)
    t_idx = np.searchsorted(ticks, grouped.index.get_level_values(0).to_numpy())
    d_pos = {d: i for i, d in enumerate(drones)}
    d_idx = np.array([d_pos[d] for d in grouped.index.get_level_values(1)], dtype="int64")
    at = grouped.index.get_level_values(0)
    keep = (t_idx < len(ticks)) & (ticks[np.minimum(t_idx, len(ticks) - 1)] == at)
    out[t_idx[keep], d_idx[keep]] = grouped.to_numpy()[keep]
    return out


def drone_series(run: RunData, opts: DiagnosisOptions | None = None,
                 span: tuple[float, float] | None = None, flow: pd.DataFrame | None = None) -> Series:
    """Every monitored metric per drone and grid point of the scan span (``run`` must be unified).

    ``flow``: the run's :func:`~swarmbox.analysis.network.message_flow` (with its tick and latency
    bound) when the caller has it: a 1,000-drone run's messages are then not matched a second time."""
    opts = opts or DiagnosisOptions()
    step = grid_step(run, opts)
    start, end = span or scan_span(run, opts.stage)
    ticks = np.arange(nearest_tick([start], step)[0], nearest_tick([end], step)[0] + 1)
    drones = list(run.drones)
    if flow is None:
        flow = network.message_flow(run.tables["messages"], sampling.tick_s(run), sampling.max_latency_s(run))
    values = {m: np.full((len(ticks), len(drones)), np.nan) for m in METRICS}
    first = _first_counted(flow, drones, step, ticks)
    chunks = network.agent_chunks(flow, drones)
    column = {d: i for i, d in enumerate(drones)}
    for chunk in chunks:   # a few drones at a time: each (grid point, drone) is whole in its chunk
        mine = drones if chunk is None else chunk
        part = _series_part(run.tables["state"], flow, mine, ticks, opts, step, first, len(chunks) > 1)
        if part is None:   # grouped otherwise than the whole would be (network.sorted_keys): at once
            mine, part = drones, _series_part(run.tables["state"], flow, drones, ticks, opts, step, first)
        at = [column[d] for d in mine]
        for metric, mat in part.items():
            values[metric][:, at] = mat
        if mine is drones:
            break
    return Series(ticks, drones, values, step, _sparse(values[DISC[0]], step, opts))


def _first_counted(flow: pd.DataFrame, drones: list[int], step: float, ticks: np.ndarray) -> int:
    """The first grid point a message to or from one of ``drones`` was counted at (after the scan when
    none was): where the trailing loss windows begin to be full."""
    counted = flow["counted"].to_numpy(dtype=bool) & (np.isin(flow["src"].to_numpy(), drones)
                                                      | np.isin(flow["dst"].to_numpy(), drones))
    sent = nearest_tick(flow["t_send"].to_numpy()[counted], step)
    return int(sent.min()) if len(sent) else int(ticks[-1]) + 1


def _series_part(state: pd.DataFrame, flow: pd.DataFrame, drones: list[int], ticks: np.ndarray,
                 opts: DiagnosisOptions, step: float, first: int,
                 chunked: bool = False) -> dict[str, np.ndarray] | None:
    """The series of ``drones`` (columns in their order); None, when ``chunked``, if a metric's rows
    come in key order (pandas would average them otherwise than among every drone's)."""
    mine = state if not chunked else state[state["node"].isin(drones).to_numpy()]
    disc = metrics.discrepancy(mine)
    disc = disc[disc["node"].isin(drones)].assign(tick=nearest_tick(disc[T], step)).rename(
        columns={"node": "drone"})
    if chunked and network.sorted_keys(disc["tick"].to_numpy(), disc["drone"].to_numpy()):
        return None
    values = {m: _matrix(disc, m, ticks, drones) for m in DISC}
    del disc, mine
    # only the rows each metric reads, never the whole flow doubled: ~0.5 GB a copy at 1,000 drones
    got = network.touching(flow, ["t_recv", "latency_ms"], drones, flow["delivered"].to_numpy(dtype=bool))
    got["tick"] = nearest_tick(got["t_recv"], step)
    if chunked and network.sorted_keys(got["tick"].to_numpy(), got["agent"].to_numpy()):
        return None
    values["latency_ms"] = _matrix(got.rename(columns={"agent": "drone"}), "latency_ms", ticks, drones)
    del got
    counted = network.touching(flow, ["t_send", "counted", "lost"], drones,
                               flow["counted"].to_numpy(dtype=bool))
    values["loss_ratio"] = _loss(counted.rename(columns={"agent": "drone"}), ticks, drones, opts, step, first)
    return values


def _sparse(disc: np.ndarray, step: float, opts: DiagnosisOptions) -> list[str]:
    """A warning when the median drone has a state sample at fewer than :data:`MIN_COVERAGE` of the
    grid points: flags then have gaps, and ``persist_s`` is met late or never."""
    if not disc.size:
        return []
    have = int(np.median(np.isfinite(disc).sum(axis=0)))
    if have >= MIN_COVERAGE * len(disc):
        return []
    return [f"diagnosis: the state series has {have} samples per drone for {len(disc)} grid points of "
            f"{step * 1e3:g} ms: a {opts.persist_s:g} s persistence may never be met "
            "(grid finer than the log?)"]


def _loss(flow: pd.DataFrame, ticks: np.ndarray, drones: list[int], opts: DiagnosisOptions,
          step: float, first: int) -> np.ndarray:
    """Trailing-window loss ratio per grid point: cumulative sums of lost and counted by send point. A
    window is only full once the run has sent messages for its whole length: before that (the
    first seconds of a run) the ratio of a few dozen messages is noise, and is left out (``first``: the
    grid point of the first counted message of any drone)."""
    width = max(1, int(round(opts.loss_window_s / step)))
    lo = ticks[0] - width
    grid = np.arange(lo, ticks[-1] + 1)
    counted = flow[flow["counted"]].assign(tick=lambda f: nearest_tick(f["t_send"], step))
    counted = counted[(counted["tick"] >= lo) & (counted["tick"] <= ticks[-1])]
    n = np.nan_to_num(_matrix(counted.assign(one=1.0), "one", grid, drones, "sum"))
    lost = counted.assign(lost_f=counted["lost"].astype("float64"))
    lost = np.nan_to_num(_matrix(lost, "lost_f", grid, drones, "sum"))
    cn, cl = np.cumsum(n, axis=0), np.cumsum(lost, axis=0)
    sel = np.arange(width, len(grid))
    wn, wl = cn[sel] - cn[sel - width], cl[sel] - cl[sel - width]
    full = (ticks >= first + width - 1)[:, None]
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where((wn > 0) & full, wl / np.where(wn > 0, wn, 1.0), np.nan)


def _row_quantiles(rows: np.ndarray, qs: tuple[float, ...]) -> list[np.ndarray]:
    """Linear-interpolation quantiles of every row's finite values (``numpy.nanquantile``'s
    definition, computed with one sort instead of one call per row)."""
    ordered = np.sort(np.where(np.isfinite(rows), rows, np.inf), axis=1)
    n = np.isfinite(rows).sum(axis=1)
    idx = np.arange(len(rows))
    out = []
    for q in qs:
        pos = q * (n - 1)
        lo = np.floor(pos).astype("int64")
        hi = np.minimum(lo + 1, n - 1)
        frac = pos - lo
        out.append(ordered[idx, lo] + (ordered[idx, hi] - ordered[idx, lo]) * frac)
    return out


def outlier_matrix(mat: np.ndarray, threshold: float, rule: str = "tukey", min_n: int = 3
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per cell: score (NaN when not flagged), and per row the median and IQR across drones."""
    k = RULES[rule]
    finite = np.isfinite(mat)
    enough = finite.sum(axis=1) >= max(min_n, 1)
    score = np.full(mat.shape, np.nan)
    med = np.full(len(mat), np.nan)
    iqr = np.full(len(mat), np.nan)
    if not enough.any():
        return score, med, iqr
    rows = mat[enough]
    q1, m, q3 = _row_quantiles(rows, (0.25, 0.5, 0.75))
    spread = q3 - q1
    hi, lo = (q3 + k * spread)[:, None], (q1 - k * spread)[:, None]
    if rule == "paper":
        beyond = np.where(rows > hi, rows - hi, 0.0)
        gate = rows > threshold
    else:
        beyond = np.where(rows > hi, rows - hi, np.where(rows < lo, lo - rows, 0.0))
        gate = np.abs(rows - m[:, None]) >= threshold
    flagged = (beyond > 0) & gate & np.isfinite(rows)
    with np.errstate(invalid="ignore", divide="ignore"):
        safe = np.where(spread > _IQR_EPS, spread, 1.0)[:, None]
        s = np.where(spread[:, None] > _IQR_EPS, beyond / safe, np.inf)
    score[enough] = np.where(flagged, s, np.nan)
    med[enough], iqr[enough] = m, spread
    return score, med, iqr


def _episodes(flags: np.ndarray, persist: int) -> list[tuple[int, int]]:
    """(alarm index, last index) of every run of >= ``persist`` consecutive True values."""
    padded = np.concatenate([[False], flags, [False]]).astype("int8")
    edges = np.diff(padded)
    starts, stops = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)
    return [(int(a) + persist - 1, int(b) - 1)
            for a, b in zip(starts, stops, strict=True) if b - a >= persist]


def scan(series: Series, opts: DiagnosisOptions | None = None, chunk: int | None = None) -> pd.DataFrame:
    """Every alarm episode: t_u (alarm), metric, drone, value, score, median, iqr, end_u (last flag).

    The grid is scanned ``chunk`` points at a time (default: one analysis window,
    :mod:`~swarmbox.analysis.windows`): the fences are per grid point, so only the chunk's sorted copy
    is held, and a flag run that crosses a chunk's edge carries on into the next
    (:class:`~.flagruns.FlagRuns`)."""
    opts = opts or DiagnosisOptions()
    chunk = chunk if chunk is not None else windows.points(series.step_s)
    if chunk < 1:
        raise ValueError(f"chunk must be >= 1 grid point, not {chunk}")
    rows: list[dict] = []
    for metric in METRICS:
        mat = series.values.get(metric)
        if mat is None:
            continue
        runs = FlagRuns(len(series.drones), opts.persist_points(series.step_s))
        for lo in range(0, len(mat), chunk):
            part = mat[lo:lo + chunk]
            score, med, iqr = outlier_matrix(part, opts.threshold(metric), opts.rule, opts.min_n)
            runs.feed(lo, ~np.isnan(score), (part, score, med, iqr))
        for j, first, last, seen in runs.close(len(mat)):
            value, sc, median, spread = seen
            rows.append({T: series.ticks[first] * series.step_s, "metric": metric,
                         "drone": int(series.drones[j]), "value": value, "score": sc, "median": median,
                         "iqr": spread, "end_u": series.ticks[last] * series.step_s})
    return _ordered(pd.DataFrame(rows, columns=ALARM_COLUMNS))


def _ordered(alarms: pd.DataFrame) -> pd.DataFrame:
    """Earliest first; at the same tick the highest score, then the largest deviation, then the lowest id."""
    dev = (alarms["value"] - alarms["median"]).abs()
    order = alarms.assign(_dev=dev).sort_values([T, "score", "_dev", "drone", "metric"],
                                                ascending=[True, False, False, True, True], kind="mergesort")
    return order.drop(columns="_dev").reset_index(drop=True)


def finding(alarms: pd.DataFrame) -> dict:
    """The run's diagnosis: its first alarm (``detected`` False when there is none)."""
    if alarms.empty:
        return {"detected": False}
    first = alarms.iloc[0]
    return {"detected": True, "drone": int(first["drone"]), "metric": str(first["metric"]),
            "t_u": float(first[T]), "value": float(first["value"]), "score": float(first["score"])}


def estimator_alarms(run: RunData, span: tuple[float, float]) -> pd.DataFrame:
    """The per-drone baseline: every estimator position reset inside the span, as an alarm (on PX4 also
    EKF2's own loss markers from its ULog: dead reckoning begins, GNSS fusion stops)."""
    ev = run.tables["events"]
    resets = ev[(ev["kind"] == "estimator") & ev["name"].isin(BASELINE_EVENTS) & ev["node"].isin(run.drones)
                & (ev[T] >= span[0]) & (ev[T] <= span[1])].sort_values([T, "node"])
    return pd.DataFrame({T: resets[T].to_numpy(dtype="float64"),
                         "drone": resets["node"].astype("int64").to_numpy(),
                         "tick": resets["tick"].astype("int64").to_numpy()})
