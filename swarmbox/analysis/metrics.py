"""Built-in per-run metrics from unified tables (paper Table 6, safety, swarm order, discrepancy).

All times are unified (ground clock, column ``t_u``). Unless stated, a metric covers the EXECUTION
stage: from the ground's entry into EXECUTION to the ground's next stage entry (LANDING or ABORT); if
the ground never left EXECUTION, to the last record of the run (``ExecWindow.complete`` is False).

Per drone:
- path length (horizontal ``distance_h_m`` and 3-D ``distance_3d_m``) = sum of the distances between
  consecutive state samples inside the window; ground-truth position when the drone's ``true_*``
  columns are all finite there, else the estimate (``position_source``);
- completion time = the time of the drone's ``progress/exec_complete`` event that started its final
  complete streak (the first one, unless an ``exec_incomplete`` followed it); busy time =
  completion - EXECUTION start, clipped to [0, duration]; a drone that never completed is busy for the
  whole duration; utilization = busy / duration; idle = duration - busy;
- discrepancy = GNSS - estimated position per tick (N, E, D; horizontal = hypot(N, E)); a state row
  logged every n-th tick stands for the n ticks from it, its estimate carried on by its velocity.

Across drones: mean and population standard deviation (ddof 0) of the per-drone values.
Safety and swarm metrics align drones on the run's global ``tick``:
- separation at a tick = smallest 3-D distance over drone pairs (truth if every drone has it, else the
  estimate; nearest neighbours from a k-d tree, never an N x N matrix); ``min_separation_m`` its
  minimum over the window; ``time_below_separation_s`` = the time of the logged ticks with separation
  < threshold, each standing for the ticks up to the next logged one (at most the state log's period,
  ``run.state_every_ticks`` x tick length: a gap in the log is not time below), so logging every
  n-th tick does not change it by more than one state period per crossing of the threshold;
- order at a tick = |sum_i v_i| / sum_i |v_i| over the drones' estimated 3-D velocities (NaN when
  the swarm is at rest); ``order_mean`` its mean over the window;
- collision and safety events are counted over the whole run: a collision matters whenever it happens.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np
import pandas as pd
from scipy.spatial import cKDTree

from swarmbox.analysis.load import GROUND
from swarmbox.analysis.unify import T

EXECUTION = 3
#: Up to this many drones, separation compares every pair directly instead of building k-d trees.
SMALL_SWARM = 16


@dataclass(frozen=True, slots=True)
class ExecWindow:
    start: float
    end: float
    complete: bool   # the ground left EXECUTION (else ``end`` is the last record of the run)

    @property
    def duration(self) -> float:
        return self.end - self.start


def exec_window(stages: pd.DataFrame, t_last: float) -> ExecWindow | None:
    """The ground's EXECUTION interval, or None when the ground never entered EXECUTION."""
    ground = (stages["node"] == GROUND).to_numpy(dtype=bool)
    t, stage = stages[T].to_numpy(dtype="float64")[ground], stages["stage"].to_numpy()[ground]
    order = _time_order(t)   # the ground's stage entries by time, as ``sort_values(T)`` orders them
    t, stage = t[order], stage[order]
    starts = t[stage == EXECUTION]
    if not len(starts):
        return None
    start = float(starts[0])
    after = t[(t > start) & (stage != EXECUTION)]
    if not len(after):
        return ExecWindow(start, max(start, t_last), False)
    return ExecWindow(start, float(after[0]), True)


def within(frame: pd.DataFrame, window: ExecWindow) -> pd.DataFrame:
    return frame[(frame[T] >= window.start) & (frame[T] <= window.end)]


_TRUE = ["true_n", "true_e", "true_d"]
_EST = ["pos_n", "pos_e", "pos_d"]
_VEL = ["vel_n", "vel_e", "vel_d"]


def _time_order(t: np.ndarray) -> np.ndarray | slice:
    """The order ``sort_values(T)`` gives: numpy's quicksort of the known times, unknown (NaN) last;
    times already strictly increasing (as logged) keep theirs, as a slice: indexing with it copies nothing."""
    if (t[1:] > t[:-1]).all():
        return slice(None)
    known = ~np.isnan(t)
    return np.concatenate([np.flatnonzero(known)[np.argsort(t[known], kind="quicksort")],
                           np.flatnonzero(~known)])


def _path(t: np.ndarray, true: np.ndarray, est: np.ndarray) -> tuple[float, float, str]:
    pos, source = (true, "truth") if len(true) and np.isfinite(true).all() else (est, "estimate")
    if len(pos) < 2:
        return 0.0, 0.0, source
    step = np.diff(pos[_time_order(t)], axis=0)
    if not np.isfinite(step).all():
        step = step[np.isfinite(step).all(axis=1)]
    return float(np.hypot(step[:, 0], step[:, 1]).sum()), float(np.linalg.norm(step, axis=1).sum()), source


def completion_time(events: pd.DataFrame, drone: int) -> float:
    """Start of the drone's final complete streak (NaN if it never completed or flipped back last)."""
    return _completion(events[events["node"] == drone])


def _progress_events(events: pd.DataFrame) -> pd.DataFrame:
    return events[_is_progress(events)]


def _is_progress(events: pd.DataFrame) -> np.ndarray:
    """Which events are progress events (as arrays: the events frame is small, pandas' text
    comparisons and filters cost more than the work)."""
    kind, name = events["kind"].to_numpy(), events["name"].to_numpy()
    return (kind == "progress") & np.isin(name, ["exec_complete", "exec_incomplete"])


def _completion(mine: pd.DataFrame) -> float:
    mine = _progress_events(mine)
    return _completed_at(mine[T].to_numpy(dtype="float64"), mine["name"].to_numpy())


def _completed_at(t: np.ndarray, names: np.ndarray) -> float:
    """:func:`completion_time` from one drone's progress events (times and names, any order)."""
    order = _time_order(t)
    t, names = t[order], names[order]
    if not len(t) or names[-1] != "exec_complete":
        return np.nan
    incomplete = t[names == "exec_incomplete"]
    done = t[names == "exec_complete"]
    if len(incomplete):
        done = done[done > incomplete[-1]]
    return float(done[0])


def _rows_of(node: np.ndarray, drones: list[int]) -> list[np.ndarray]:
    """Each drone's row positions, in their original order: one stable sort, not a scan per drone."""
    order = np.argsort(node, kind="stable")
    ordered = node[order]
    ids = np.asarray(drones, dtype=np.int64)
    lo, hi = np.searchsorted(ordered, ids, side="left"), np.searchsorted(ordered, ids, side="right")
    return [order[a:b] for a, b in zip(lo.tolist(), hi.tolist(), strict=True)]


def drone_workload(state: pd.DataFrame, events: pd.DataFrame, drones: list[int],
                   window: ExecWindow) -> pd.DataFrame:
    """Per drone: path lengths, completion, busy, utilization, idle (columns documented above).

    Only the columns read are taken, as arrays, and split by drone once: linear in the rows (one
    sort), a few pandas calls per run rather than per drone.
    """
    t = state[T].to_numpy(dtype="float64")
    inside = (t >= window.start) & (t <= window.end)
    t = t[inside]
    true, est = (np.column_stack([state[c].to_numpy(dtype="float64")[inside] for c in cols])
                 for cols in (_TRUE, _EST))
    progress = _is_progress(events)
    p_t, p_name = events[T].to_numpy(dtype="float64")[progress], events["name"].to_numpy()[progress]
    rows = []
    for drone, mine, done in zip(drones, _rows_of(state["node"].to_numpy()[inside], drones),
                                 _rows_of(events["node"].to_numpy()[progress], drones), strict=True):
        dist_h, dist_3d, source = _path(t[mine], true[mine], est[mine])
        t_done = _completed_at(p_t[done], p_name[done])
        busy = window.duration
        if not np.isnan(t_done):
            busy = float(np.clip(t_done - window.start, 0, window.duration))
        rows.append({
            "drone": drone, "distance_h_m": dist_h, "distance_3d_m": dist_3d, "position_source": source,
            "t_complete_u": t_done, "completed": not np.isnan(t_done), "busy_s": busy,
            "utilization": busy / window.duration if window.duration > 0 else np.nan,
            "idle_s": window.duration - busy,
        })
    return pd.DataFrame(rows)


def spread(values: pd.Series, name: str) -> dict[str, float]:
    """Mean and population std of per-drone values."""
    arr = values.to_numpy(dtype="float64")
    if arr.size == 0:
        return {f"{name}_mean": np.nan, f"{name}_std": np.nan}
    return {f"{name}_mean": float(np.nanmean(arr)), f"{name}_std": float(np.nanstd(arr, ddof=0))}


def workload_summary(per_drone: pd.DataFrame, window: ExecWindow) -> dict[str, float]:
    out: dict[str, float] = {"mission_duration_s": window.duration}
    for col in ("distance_h_m", "distance_3d_m", "busy_s", "utilization"):
        out |= spread(per_drone[col], col)
    out["distance_h_m_total"] = float(per_drone["distance_h_m"].sum())
    out["idle_s_mean"] = float(per_drone["idle_s"].mean()) if len(per_drone) else np.nan
    out["completed_fraction"] = float(per_drone["completed"].mean()) if len(per_drone) else np.nan
    return out


def discrepancy(state: pd.DataFrame, every_ticks: int = 1, tick_s: float = 0.0) -> pd.DataFrame:
    """GNSS - estimate per tick: columns node, tick, t_u, disc_n_m, disc_e_m, disc_d_m, disc_h_m.

    A state row logged every ``every_ticks`` ticks of ``tick_s`` stands for the ticks up to the next
    one: for each, the GNSS fix it holds minus its estimate carried on by its estimated velocity (what
    the estimator does between fixes). Reading only the logged ticks instead aliases with the GNSS
    rate (a 10 Hz fix logged at 20 Hz is seen just after each fix, when the gap is smallest) and biases
    the mean and maximum low; with every tick logged this is the logged rows themselves.
    """
    if every_ticks <= 1 or not len(state) or not tick_s > 0:
        return _discrepancy(state, state.index)
    upto = _ticks_to_next(state, every_ticks)
    parts = []
    for j in range(every_ticks):
        rows = state[upto > j] if j else state
        ahead = {f"pos_{a}": rows[f"pos_{a}"] + rows[f"vel_{a}"] * (j * tick_s) for a in "ned"}
        moved = rows.assign(**ahead, tick=rows["tick"] + j, **{T: rows[T] + j * tick_s})
        parts.append(_discrepancy(moved, rows.index))
    return pd.concat(parts, ignore_index=True).sort_values(["node", "tick"], kind="stable", ignore_index=True)


def _ticks_to_next(state: pd.DataFrame, every_ticks: int) -> np.ndarray:
    """Per row: ticks to the drone's next row, at most ``every_ticks`` (the last row: ``every_ticks``)."""
    node, tick = state["node"].to_numpy(), state["tick"].to_numpy(dtype="float64")
    order = np.lexsort((tick, node))
    gap = np.full(len(state), float(every_ticks))
    same = node[order][1:] == node[order][:-1]
    gap[order[:-1][same]] = np.diff(tick[order])[same]
    return np.minimum(gap, every_ticks)


def _discrepancy(state: pd.DataFrame, index: pd.Index) -> pd.DataFrame:
    out = {c: state[c].to_numpy() for c in ("node", "tick", T)}
    for axis in "ned":
        out[f"disc_{axis}_m"] = state[f"gnss_{axis}"].to_numpy() - state[f"pos_{axis}"].to_numpy()
    out["disc_h_m"] = np.hypot(out["disc_n_m"], out["disc_e_m"])
    return pd.DataFrame(out, index=index)


def _drone_slots(node: np.ndarray, drones: list[int]) -> np.ndarray:
    """Each row's position in ``drones`` (the last one for a repeated id), -1 for any other node."""
    ids = np.asarray(drones, dtype=np.int64)
    if not len(ids):
        return np.full(len(node), -1)
    order = np.argsort(ids, kind="stable")
    pos = np.searchsorted(ids[order], node, side="right") - 1
    hit = (pos >= 0) & (ids[order][np.maximum(pos, 0)] == node)
    return np.where(hit, order[np.maximum(pos, 0)], -1)


def _by_tick(state: pd.DataFrame, cols: list[str], drones: list[int],
             ticks: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Array (ticks, drones, len(cols)) with NaN where a drone has no sample at a tick; ``ticks``:
    the sorted ticks to lay out (default: those of ``state``)."""
    if ticks is None:
        ticks = np.sort(state["tick"].unique())
    return ticks, _lay_out(state, [cols], drones, ticks)[0]


def _lay_out(state: pd.DataFrame, groups: list[list[str]], drones: list[int],
             ticks: np.ndarray) -> list[np.ndarray]:
    """:func:`_by_tick` of each group of columns, the rows placed once for all of them."""
    d_idx = _drone_slots(state["node"].to_numpy(), drones)
    keep = d_idx >= 0
    rows = slice(None) if keep.all() else keep
    cell = np.searchsorted(ticks, state["tick"].to_numpy()[rows])
    cell *= len(drones)
    cell += d_idx[rows]   # (tick, drone) as one index into the rows of a (ticks x drones, cols) view
    out = []
    for cols in groups:
        grid = np.full((len(ticks), len(drones), len(cols)), np.nan)
        values = np.column_stack([state[c].to_numpy(dtype="float64")[rows] for c in cols])
        grid.reshape(-1, len(cols))[cell] = values
        out.append(grid)
    return out


def _last_samples(state: pd.DataFrame) -> pd.DataFrame:
    """``state.drop_duplicates(["node", "tick"], keep="last")``; the frame itself, not a copy, when its
    rows are strictly ordered by (node, tick), as the loader gives them: then none repeats."""
    node, tick = state["node"].to_numpy(), state["tick"].to_numpy()
    with np.errstate(invalid="ignore"):
        ordered = (node[1:] > node[:-1]) | ((node[1:] == node[:-1]) & (tick[1:] > tick[:-1]))
    return state if ordered.all() else state.drop_duplicates(["node", "tick"], keep="last")


def nearest_gap(pos: np.ndarray) -> float:
    """Smallest distance between two of the rows of ``pos`` (rows with a NaN left out; NaN below 2).

    A k-d tree answers each point's nearest neighbour in O(N log N), so a tick of 1,000 drones costs
    a few milliseconds and no N x N matrix is ever built.
    """
    pos = pos[np.isfinite(pos).all(axis=1)]
    if len(pos) < 2:
        return np.nan
    dist, _ = cKDTree(pos).query(pos, k=2)
    return float(dist[:, 1].min())


def _position_columns(state: pd.DataFrame) -> list[str]:
    """The truth when every drone has it, else the estimate."""
    truth = len(state) and all(np.isfinite(state[c].to_numpy(dtype="float64")).all() for c in _TRUE)
    return _TRUE if truth else _EST


def separation_by_tick(state: pd.DataFrame, drones: list[int]) -> pd.Series:
    """Smallest pairwise 3-D distance between drones at every tick (NaN with fewer than 2 drones)."""
    state = _last_samples(state)
    cols = _position_columns(state)
    ticks = np.sort(state["tick"].unique())
    if len(drones) < 2 or len(ticks) == 0:
        return pd.Series(np.nan, index=ticks, dtype="float64")
    if len(drones) <= SMALL_SWARM:   # a tick where no drone of ``drones`` logged: NaN
        return pd.Series(_dense_gaps(_by_tick(state, cols, drones, ticks)[1]), index=ticks, dtype="float64")
    # the tick and the positions only, not every column of the state, sorted by tick
    mine = state["node"].isin(drones).to_numpy()
    state = state.loc[mine, ["tick", *cols]].sort_values("tick", kind="stable")
    pos = state[cols].to_numpy(dtype="float64")
    bounds = np.searchsorted(state["tick"].to_numpy(), ticks, side="left").tolist() + [len(state)]
    best = [nearest_gap(pos[lo:hi]) for lo, hi in zip(bounds[:-1], bounds[1:], strict=True)]
    return pd.Series(best, index=ticks, dtype="float64")


def _dense_gaps(pos: np.ndarray) -> np.ndarray:
    """Per tick of ``pos`` (ticks, drones, 3), the smallest distance over every pair, for a small swarm:
    all pairs of a block of ticks in one array operation (a k-d tree per tick costs far more than N^2
    distances at N <= 16)."""
    i, j = np.triu_indices(pos.shape[1], k=1)
    out = np.empty(len(pos))
    step = max(1, 2**16 // max(len(i), 1))   # blocks of ~1.5 MB temporaries: they stay in the cache
    for lo in range(0, len(pos), step):
        block = pos[lo:lo + step]
        d = np.sqrt(((block[:, i] - block[:, j]) ** 2).sum(axis=2))
        with np.errstate(all="ignore"), warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)   # all-NaN ticks give NaN, as intended
            out[lo:lo + step] = np.nanmin(np.where(np.isfinite(d), d, np.nan), axis=1)
    return out


def order_by_tick(state: pd.DataFrame, drones: list[int], block: int = 256) -> pd.Series:
    """Velocity alignment |sum v| / sum |v| at every tick (NaN when every drone is at rest); ``block``
    ticks at a time: a (ticks x drones x 3) grid of the whole flight is ~80 MB per minute at 1,000 drones."""
    state = _last_samples(state)
    ticks = np.sort(state["tick"].unique())
    columns = {c: state[c].to_numpy() for c in ("node", "tick", *_VEL)}
    by_tick = np.argsort(columns["tick"], kind="stable")
    bounds = np.searchsorted(columns["tick"][by_tick], ticks[::block], side="left").tolist() + [len(by_tick)]
    out = []
    for i, (lo, hi) in enumerate(zip(bounds[:-1], bounds[1:], strict=True)):
        rows = np.sort(by_tick[lo:hi])   # the block's rows in their logged order
        part = pd.DataFrame({c: v[rows] for c, v in columns.items()})
        out.append(_alignment(_by_tick(part, _VEL, drones, ticks[i * block:(i + 1) * block])[1]))
    return pd.Series(np.concatenate(out) if out else np.zeros(0), index=ticks, dtype="float64")


def _alignment(vel: np.ndarray) -> np.ndarray:
    """|sum v| / sum |v| per tick of ``vel`` (ticks, drones, 3)."""
    vel = np.nan_to_num(vel)
    total = np.linalg.norm(vel.sum(axis=1), axis=1)
    norms = np.linalg.norm(vel, axis=2).sum(axis=1)
    with np.errstate(all="ignore"):
        return np.where(norms > 1e-9, total / norms, np.nan)


def swarm_timeline(state: pd.DataFrame, drones: list[int]) -> pd.DataFrame:
    """Per tick: unified time (earliest drone sample), minimum separation and order."""
    times = state.groupby("tick")[T].min()
    if 2 <= len(drones) <= SMALL_SWARM:   # the rows placed by tick once, for positions and velocities
        state = _last_samples(state)
        ticks = np.sort(state["tick"].unique())
        pos, vel = _lay_out(state, [_position_columns(state), _VEL], drones, ticks)
        sep = pd.Series(_dense_gaps(pos), index=ticks, dtype="float64")
        order = pd.Series(_alignment(vel), index=ticks, dtype="float64")
    else:
        sep, order = separation_by_tick(state, drones), order_by_tick(state, drones)
    return pd.DataFrame({"tick": times.index, T: times.to_numpy(),
                         "separation_m": sep.reindex(times.index).to_numpy(),
                         "order": order.reindex(times.index).to_numpy()})


def row_durations(ticks: np.ndarray, tick_s: float, every_ticks: int = 1) -> np.ndarray:
    """Time each row of a per-tick timeline stands for: the ticks up to the next row, at most
    ``every_ticks`` (the log's period; also the last row's), times ``tick_s``."""
    ticks = np.asarray(ticks, dtype="float64")
    if not len(ticks):
        return np.zeros(0)
    steps = np.diff(ticks, append=ticks[-1] + every_ticks)
    return np.clip(steps, 0, every_ticks) * tick_s


def swarm_summary(swarm: pd.DataFrame, events: pd.DataFrame, tick_s: float,
                  threshold_m: float, every_ticks: int = 1) -> dict[str, float]:
    """Safety and order scalars over the ticks of ``swarm`` (state logged every ``every_ticks``
    ticks of ``tick_s``); event counts over all of ``events``."""
    sep, order = swarm["separation_m"], swarm["order"]
    below = (sep < threshold_m).to_numpy(dtype=bool)
    return {
        "min_separation_m": float(sep.min()) if sep.notna().any() else np.nan,
        "time_below_separation_s": float(row_durations(swarm["tick"].to_numpy(), tick_s,
                                                       every_ticks)[below].sum()),
        "collision_events": float((events["kind"] == "collision").sum()),
        "safety_events": float((events["kind"] == "safety").sum()),
        "order_mean": float(order.mean()) if order.notna().any() else np.nan,
    }
