"""Put every node's records on one timeline: the ground clock.

Clock model of a node X (ground and the simulated network are the reference, o = d = 0)::

    t_local = o_X + (1 + d_X) * t_ground        (o_X offset in s, d_X drift, reported in ppm)

A message A -> B received by B gives ``recv_B - sent_A = delay + off_B(t) - off_A(t)`` with
``off_X(t) = t_local - t_ground``. Per pair of nodes that talk both ways and per window of
``window_s`` (on A's clock), the minimum of each direction is the least-delayed message
(minimum-delay filtering); half their difference cancels a symmetric delay and gives
``off_B - off_A`` at the window's middle, half their sum the one-way delay. With at least
``min_drift_windows`` windows a Theil-Sen line through those points gives the pair's relative offset
and drift, otherwise their median gives a constant offset. A pair heard in one direction only
contributes ``min sample - typical delay`` with a low weight. Pair estimates are then solved for
per-node offset and drift by weighted least squares over the communication graph, anchored at the
ground, so a drone that talks only to its leader is still placed on the ground clock. A node with no
path to the ground keeps offset 0 (method ``assumed``).

A node whose clock *steps* (jumps by more than ``step_min_s``) is not one line: each stretch between
steps is a clock of its own (:mod:`swarmbox.analysis.clock_steps`), estimated and applied as above,
listed in the clock table as the node's ``life`` 1, 2, ... with ``from_u`` (when it began) and
``step_s`` (the jump), and reported in the run's problems.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd
from scipy import stats

from swarmbox.analysis import clock_steps, clockstream, sampling
from swarmbox.analysis.load import GROUND, NET, RunData, node_id, read_streamed

#: Name of the unified-time column added to every table (seconds on the ground clock).
T = "t_u"


@dataclass(frozen=True, slots=True)
class ClockOptions:
    window_s: float = 5.0
    min_drift_windows: int = 4
    one_way_weight: float = 0.05
    step_min_s: float = 0.1      # a larger jump of a drone's clock is a step (0: never split)


@dataclass(frozen=True, slots=True)
class PairEstimate:
    a: int
    b: int
    offset_s: float     # off_b - off_a at ground time 0
    drift: float        # d_b - d_a (dimensionless)
    delay_s: float      # median minimum one-way delay
    weight: float
    windows: int
    method: str         # two-way | one-way


def _int64(values: np.ndarray) -> np.ndarray:
    """As pandas casts: an unknown (NaN) id raises rather than becoming a number."""
    if values.dtype.kind in "iu":
        return values.astype(np.int64)
    return pd.Series(values, copy=False).astype("int64").to_numpy()


def clock_samples(messages: pd.DataFrame) -> pd.DataFrame:
    """One row per received message: ``a`` sender, ``b`` receiver, ``t_a`` (sender clock), ``sample``."""
    return pd.DataFrame(_sample_arrays(messages))


def _sample_arrays(messages: pd.DataFrame) -> dict[str, np.ndarray]:
    """The columns of :func:`clock_samples` as arrays (a frame would copy them into one block)."""
    node = messages["node"].to_numpy()
    t_b = messages["t_s"].to_numpy(dtype=np.float64)
    t_a = messages["t_sent_s"].to_numpy(dtype=np.float64)
    keep = (messages["kind"] == "recv").to_numpy(dtype=bool) & (node != NET)
    keep &= np.isfinite(t_b) & np.isfinite(t_a)
    rows = np.flatnonzero(keep)   # one mask, several columns: positions are cheaper to apply
    t_a, t_b = t_a[rows], t_b[rows]
    return {"a": _int64(messages["src"].to_numpy()[rows]), "b": _int64(node[rows]),
            "t_a": t_a, "t_b": t_b, "sample": t_b - t_a}


def window_minima(fwd: pd.DataFrame, bwd: pd.DataFrame, window_s: float) -> pd.DataFrame:
    """Per window on a's clock: min forward (a->b) and backward (b->a) sample and the window middle.

    ``fwd`` holds the samples of a->b messages, ``bwd`` those of b->a; both are placed on a's clock
    (a's send time for a->b, a's receive time for b->a).
    """
    parts = pd.concat([
        pd.DataFrame({"t": fwd["t_a"], "fwd": fwd["sample"], "bwd": np.nan}),
        pd.DataFrame({"t": bwd["t_b"], "fwd": np.nan, "bwd": bwd["sample"]}),
    ])
    parts["w"] = np.floor(parts["t"] / window_s)
    grouped = parts.groupby("w")
    out = grouped.agg(fwd=("fwd", "min"), bwd=("bwd", "min"), t_lo=("t", "min"), t_hi=("t", "max"))
    out["t_mid"] = (out["t_lo"] + out["t_hi"]) / 2
    return out.reset_index(drop=True)


def all_window_minima(samples: pd.DataFrame | dict[str, np.ndarray],
                      window_s: float) -> dict[tuple[int, int], pd.DataFrame]:
    """:func:`window_minima` of every node pair (a < b) heard at least one way, in one grouping.

    One sort of all samples by (pair, window) instead of one pass per pair: the cost is linear in the
    messages (n log n), whatever the number of nodes; the windows of a pair are in time order.
    """
    return {pair: pd.DataFrame(columns) for pair, columns in _window_arrays(samples, window_s).items()}


def _window_arrays(samples: pd.DataFrame | dict[str, np.ndarray],
                   window_s: float) -> dict[tuple[int, int], dict[str, np.ndarray]]:
    """The columns of :func:`all_window_minima`'s frames, as arrays."""
    a, b, t_a, t_b, sample = (np.asarray(samples[c]) for c in ("a", "b", "t_a", "t_b", "sample"))
    return clockstream.pair_windows(clockstream.window_parts(a, b, t_a, t_b, sample, window_s))


def two_way_estimate(a: int, b: int, win: pd.DataFrame | dict[str, np.ndarray],
                     opts: ClockOptions) -> PairEstimate | None:
    """Relative clock of b with respect to a from the windows where both directions were heard."""
    fwd, bwd, t_mid = (np.asarray(win[c], dtype=np.float64) for c in ("fwd", "bwd", "t_mid"))
    both = ~np.isnan(fwd) & ~np.isnan(bwd)
    n = int(both.sum())
    if not n:
        return None
    fwd, bwd, t_mid = fwd[both], bwd[both], t_mid[both]
    rel = (fwd - bwd) / 2
    delay = float(np.median((fwd + bwd) / 2))
    if n >= opts.min_drift_windows and np.ptp(t_mid) > 0:
        slope, intercept, _, _ = stats.theilslopes(rel, t_mid)
    else:
        slope, intercept = 0.0, float(np.median(rel))
    return PairEstimate(a, b, float(intercept), float(slope), delay, float(n), n, "two-way")


def one_way_estimate(a: int, b: int, win: pd.DataFrame | dict[str, np.ndarray], opts: ClockOptions,
                     typical_delay_s: float) -> PairEstimate | None:
    """Relative clock from one direction only, assuming the typical delay of the two-way pairs."""
    fwd, bwd = (np.asarray(win[c], dtype=np.float64) for c in ("fwd", "bwd"))
    if not np.isnan(fwd).all():
        rel = float(np.nanmin(fwd)) - typical_delay_s
    elif not np.isnan(bwd).all():
        rel = typical_delay_s - float(np.nanmin(bwd))
    else:
        return None
    return PairEstimate(a, b, rel, 0.0, typical_delay_s, opts.one_way_weight, 0, "one-way")


def estimate_pairs(samples: pd.DataFrame | dict[str, np.ndarray], opts: ClockOptions) -> list[PairEstimate]:
    """Two-way estimates for every pair heard both ways, then one-way ones for the rest."""
    return pair_estimates(_window_arrays(samples, opts.window_s), opts)


def pair_estimates(wins: dict[tuple[int, int], dict[str, np.ndarray]],
                   opts: ClockOptions) -> list[PairEstimate]:
    """:func:`estimate_pairs` from the pairs' window statistics."""
    two_way = [e for p, w in wins.items() if (e := two_way_estimate(*p, w, opts))]
    typical = float(np.median([e.delay_s for e in two_way])) if two_way else 0.0
    done = {(e.a, e.b) for e in two_way}
    one_way = [e for p, w in wins.items() if p not in done and (e := one_way_estimate(*p, w, opts, typical))]
    return two_way + one_way


def _reachable(pairs: list[PairEstimate], anchors: set[int]) -> set[int]:
    adj: dict[int, set[int]] = {}
    for e in pairs:
        adj.setdefault(e.a, set()).add(e.b)
        adj.setdefault(e.b, set()).add(e.a)
    seen, queue = set(anchors), deque(anchors)
    while queue:
        for nxt in adj.get(queue.popleft(), ()):
            if nxt not in seen:
                seen.add(nxt)
                queue.append(nxt)
    return seen


def solve_clocks(pairs: list[PairEstimate], nodes: list[int]) -> pd.DataFrame:
    """Per-node offset and drift relative to the ground by weighted least squares over pair estimates."""
    anchors = {GROUND, NET}
    free = sorted(_reachable(pairs, anchors) - anchors)
    col = {n: i for i, n in enumerate(free)}
    used = [e for e in pairs if (e.a in col or e.a in anchors) and (e.b in col or e.b in anchors)]
    solution = np.zeros((len(free), 2))
    if free and used:
        design = np.zeros((len(used), len(free)))
        rhs = np.array([[e.offset_s, e.drift] for e in used])
        for row, e in enumerate(used):
            if e.b in col:
                design[row, col[e.b]] += 1.0
            if e.a in col:
                design[row, col[e.a]] -= 1.0
        w = np.sqrt([e.weight for e in used])[:, None]
        solution = np.linalg.lstsq(design * w, rhs * w, rcond=None)[0]
    rows = []
    for n in sorted(set(nodes) | anchors):
        method = _method(n, col, used)
        off, drift = solution[col[n]] if n in col else (0.0, 0.0)
        rows.append({"node": n, "offset_s": float(off), "drift_ppm": float(drift) * 1e6, "method": method,
                     "pairs": sum(1 for e in used if n in (e.a, e.b))})
    return pd.DataFrame(rows)


def _method(node: int, col: dict[int, int], used: list[PairEstimate]) -> str:
    if node in (GROUND, NET):
        return "reference"
    if node not in col:
        return "assumed"
    mine = [e for e in used if node in (e.a, e.b)]
    return "two-way" if any(e.method == "two-way" for e in mine) else "one-way"


def estimate_clocks(messages: pd.DataFrame, nodes: list[int],
                    opts: ClockOptions | None = None) -> pd.DataFrame:
    """Estimated clock of every node: columns node, offset_s, drift_ppm, method, pairs."""
    opts = opts or ClockOptions()
    return solve_clocks(estimate_pairs(_sample_arrays(messages), opts), nodes)


def estimate_clocks_streamed(run_dir: str | Path, nodes: list[int], opts: ClockOptions | None = None,
                             problems: list[str] | None = None) -> pd.DataFrame:
    """:func:`estimate_clocks` of a run's messages, read from its files a Parquet batch at a time: what is
    held is the per-(pair, window) statistics (:mod:`.clockstream`), whatever the run's length."""
    opts = opts or ClockOptions()
    part = clockstream.run_window_parts(Path(run_dir), opts.window_s, problems=problems)
    return solve_clocks(pair_estimates(clockstream.pair_windows(part), opts), nodes)


def to_unified(t_local: pd.Series, node: pd.Series, clocks: pd.DataFrame) -> pd.Series:
    """Map node-local times to ground time with each node's estimated offset and drift (a node with
    no estimate, or a NaN one, keeps 0)."""
    ids = clocks["node"].to_numpy(dtype=np.int64)
    nodes = node.to_numpy()
    if nodes.dtype.kind not in "iu":
        nodes = node.astype("int64").to_numpy()   # as pandas casts: an unknown (NaN) node raises
    first = np.unique(ids, return_index=True)[1]   # a node listed twice: its first estimate

    def per_node(column: str) -> np.ndarray:
        values = clocks[column].to_numpy(dtype=np.float64)[first]
        return np.append(np.where(np.isnan(values), 0.0, values), 0.0)   # then 0 for an unknown node

    slot = _slots(ids[first], nodes)
    out = per_node("offset_s")[slot]
    np.subtract(t_local.to_numpy(dtype=np.float64), out, out=out)
    scale = (per_node("drift_ppm") * 1e-6)[slot]
    scale += 1.0
    out /= scale   # (t - offset) / (1 + drift), in place: these arrays span every message
    return pd.Series(out, index=t_local.index, copy=False)


def _slots(ids: np.ndarray, nodes: np.ndarray) -> np.ndarray:
    """Position of each of ``nodes`` in the sorted distinct ``ids``, ``len(ids)`` when absent.

    Node ids span a small range: a lookup table over it beats a binary search per row.
    """
    if not len(ids) or not len(nodes):
        return np.full(len(nodes), len(ids), dtype=np.intp)
    lo, hi = min(int(ids[0]), int(nodes.min())), max(int(ids[-1]), int(nodes.max()))
    if hi - lo > max(len(nodes), 1 << 16):   # ids far apart: the table would be too large
        slot = np.searchsorted(ids, nodes)
        slot[(slot == len(ids)) | (np.append(ids, 0)[slot] != nodes)] = len(ids)
        return slot
    table = np.full(hi - lo + 1, len(ids), dtype=np.intp)
    table[ids - lo] = np.arange(len(ids))
    return table[np.subtract(nodes, lo, dtype=np.intp)]


def unify(run: RunData, opts: ClockOptions | None = None, sent_times: bool = True) -> pd.DataFrame:
    """Estimate clocks and add the unified time ``t_u`` to every table of ``run`` (in place).

    Messages also get ``t_sent_u`` (unless ``sent_times`` is False; no metric reads it): the sender's
    ``t_sent_s`` mapped with the sender's clock.
    Returns the clock table, with the configured truth from ``run.json`` (``clocks``) beside it; a clock
    step adds a row per life of the node and a line to ``run.problems``.
    """
    opts = opts or ClockOptions()
    tick_s = sampling.tick_s(run)
    steps = (clock_steps.find_steps(run.tables["state"], tick_s, opts.step_min_s)
             if opts.step_min_s > 0 else [])
    if steps:
        if "messages" in run.streamed:   # the lives are told apart in each node's whole log
            read_streamed(run, "messages")
        return _unify_lives(run, opts, steps, tick_s, sent_times)
    return _unify_plain(run, opts, sent_times)


def _unify_plain(run: RunData, opts: ClockOptions, sent_times: bool) -> pd.DataFrame:
    """:func:`unify` with one clock per node (from the files, batch by batch, when the messages were left
    there)."""
    if "messages" in run.streamed:
        clocks = estimate_clocks_streamed(run.path, run.nodes, opts)
    else:
        clocks = estimate_clocks(run.tables["messages"], run.nodes, opts)
    for name, frame in run.tables.items():
        if name != "messages":
            frame[T] = to_unified(frame["t_s"], frame["node"], clocks)
    unify_messages(run, clocks, sent_times)
    clocks = clocks.assign(life=0, from_u=np.nan, step_s=0.0)
    return _with_truth(clocks, run.manifest.get("clocks") or {})


def unify_messages(run: RunData, clocks: pd.DataFrame, sent_times: bool = True) -> None:
    """``t_u`` (and ``t_sent_u``, the sender's stamp on the ground clock) of the messages, one clock
    per node."""
    msgs = run.tables["messages"]
    msgs[T] = to_unified(msgs["t_s"], msgs["node"], clocks)
    if sent_times:
        msgs["t_sent_u"] = to_unified(msgs["t_sent_s"], msgs["src"].fillna(GROUND), clocks)


def _unify_lives(run: RunData, opts: ClockOptions, steps: list[clock_steps.Step], tick_s: float,
                 sent_times: bool) -> pd.DataFrame:
    """:func:`unify` of a run where some clocks step: every life of a node is a clock of its own.

    A step is kept only when the messages confirm it (the lives' estimated clocks differ by at least
    half of ``step_min_s`` there): a real-time node that stalls and catches up also moves its local
    time against its ticks, but not its clock against the others'."""
    ids = clock_steps.clock_ids(run.tables, steps, tick_s)
    msgs = run.tables["messages"]
    remapped = pd.DataFrame({"node": ids["messages"], "src": ids["messages_src"], "kind": msgs["kind"],
                             "t_s": msgs["t_s"], "t_sent_s": msgs["t_sent_s"]})
    lives = sorted({int(i) for i in np.concatenate(list(ids.values())) if i >= clock_steps.LIFE_STRIDE})
    clocks = estimate_clocks(remapped, [*run.nodes, *lives], opts)
    confirmed = _confirmed(steps, clocks, opts.step_min_s / 2)
    if len(confirmed) < len(steps):
        if not confirmed:
            return _unify_plain(run, opts, sent_times)
        return _unify_lives(run, opts, confirmed, tick_s, sent_times)
    for name, frame in run.tables.items():
        frame[T] = to_unified(frame["t_s"], pd.Series(ids[name], index=frame.index), clocks)
    if sent_times:
        src = pd.Series(ids["messages_src"], index=msgs.index)
        msgs["t_sent_u"] = to_unified(msgs["t_sent_s"], src, clocks)
    clock_id = clocks["node"].to_numpy(dtype=np.int64)
    life = np.where(clock_id >= 0, clock_id // clock_steps.LIFE_STRIDE, 0)
    clocks = clocks.assign(node=clock_id - life * clock_steps.LIFE_STRIDE, life=life)
    clocks = _life_starts(clocks, run.tables["state"], ids["state"])
    clocks = clocks.sort_values(["node", "life"], kind="stable").reset_index(drop=True)
    clocks = _with_truth(clocks, run.manifest.get("clocks") or {})
    run.problems.extend(clock_steps.describe(steps, clocks))
    return clocks


def _confirmed(steps: list[clock_steps.Step], clocks: pd.DataFrame, least_s: float) -> list[clock_steps.Step]:
    """The steps whose two lives' estimated clocks differ by at least ``least_s`` at the step."""
    est = clocks.set_index("node")
    kept = []
    for s in steps:
        life = sum(o.node == s.node and o.tick <= s.tick for o in steps)
        after, before = s.node + life * clock_steps.LIFE_STRIDE, s.node + (life - 1) * clock_steps.LIFE_STRIDE
        if after not in est.index or before not in est.index:
            continue
        reading = [float(est.loc[n, "offset_s"]) + (1 + float(est.loc[n, "drift_ppm"]) * 1e-6) * s.t_s
                   for n in (after, before)]
        if abs(reading[0] - reading[1]) >= least_s:
            kept.append(s)
    return kept


def _life_starts(clocks: pd.DataFrame, state: pd.DataFrame, state_ids: np.ndarray) -> pd.DataFrame:
    """``from_u``: the first unified state time of each life ≥ 1; ``step_s``: the jump of the node's
    reading there, this life's clock minus the previous life's."""
    first = pd.Series(state[T].to_numpy(), index=state_ids).groupby(level=0).min()
    by_id = {(int(n), int(k)): (o, d) for n, k, o, d in
             clocks[["node", "life", "offset_s", "drift_ppm"]].itertuples(index=False)}
    from_u, step = [], []
    for n, k in clocks[["node", "life"]].itertuples(index=False):
        if k == 0:
            from_u.append(np.nan)
            step.append(0.0)
            continue
        t = float(first.get(n + k * clock_steps.LIFE_STRIDE, np.nan))
        (o1, d1), (o0, d0) = by_id[(n, k)], by_id.get((n, k - 1), (0.0, 0.0))
        from_u.append(t)
        step.append((o1 + (1 + d1 * 1e-6) * t) - (o0 + (1 + d0 * 1e-6) * t))
    return clocks.assign(from_u=from_u, step_s=step)


def _with_truth(clocks: pd.DataFrame, truth: dict) -> pd.DataFrame:
    """The configured clocks beside the estimates (unknown, NaN, after a step: no config says it)."""
    true = {node_id(str(k)): v for k, v in truth.items() if isinstance(v, dict)}
    first = (clocks["life"] == 0).to_numpy()
    clocks["true_offset_s"] = np.where(first, [float(true.get(n, {}).get("offset_s", 0.0))
                                               for n in clocks["node"]], np.nan)
    clocks["true_drift_ppm"] = np.where(first, [float(true.get(n, {}).get("drift_ppm", 0.0))
                                                for n in clocks["node"]], np.nan)
    clocks["offset_error_ms"] = (clocks["offset_s"] - clocks["true_offset_s"]) * 1e3
    return clocks
