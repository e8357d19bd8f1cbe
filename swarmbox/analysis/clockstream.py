"""Clock statistics accumulated window by window, so that unifying a run's clocks holds only its
per-(pair, window) minima, never its messages.

:mod:`swarmbox.analysis.unify` estimates every clock from, per pair of nodes and window of its clock
(``ClockOptions.window_s``), the least-delayed sample each way and the window's first and last time.
Those are minima and maxima: the statistics of a batch of rows (:func:`window_parts`) merge with those
of the next (:func:`merge_parts`) into exactly what the whole table gives, in any order. So
:func:`estimate_clocks_streamed` reads each node's ``messages.parquet`` a Parquet batch at a time (only
the four columns a receive's sample needs) and gives the clock table :func:`~.unify.estimate_clocks`
gives from the loaded table, number for number (``tests/analysis/test_memory_windows.py``). It
estimates one clock per node: a run whose clocks step is unified from its loaded tables
(:func:`~.unify.unify` splits the stepped nodes' lives).
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.compute as pc
import pyarrow.parquet as pq

from swarmbox.analysis import windows
from swarmbox.analysis.load import NET, node_id

#: Columns of a (pair, window) part: its pair (``lo`` < ``hi``), window index, least sample each way
#: (NaN: none), and the first and last time of the window's samples on ``lo``'s clock.
PART = ("lo", "hi", "w", "fwd", "bwd", "t_lo", "t_hi")
_READ = ["t_s", "kind", "src", "t_sent_s"]


def window_parts(a: np.ndarray, b: np.ndarray, t_a: np.ndarray, t_b: np.ndarray, sample: np.ndarray,
                 window_s: float) -> dict[str, np.ndarray]:
    """The statistics of one batch of receive samples (sender ``a``, receiver ``b``, send time ``t_a`` on
    a's clock, receive time ``t_b`` on b's, ``sample`` = t_b - t_a) per (pair, window), sorted by pair
    then window."""
    other = a != b
    if not other.all():   # a node's messages to itself say nothing about clocks
        a, b, t_a, t_b, sample = a[other], b[other], t_a[other], t_b[other], sample[other]
    fwd = a < b
    lo, hi = np.minimum(a, b), np.maximum(a, b)
    t = np.where(fwd, t_a, t_b)   # both directions on the clock of ``lo``
    fwd_s, bwd_s = np.where(fwd, sample, np.nan), np.where(fwd, np.nan, sample)
    return _reduce(lo, hi, np.floor(t / window_s), fwd_s, bwd_s, t, t)


def merge_parts(parts: list[dict[str, np.ndarray]]) -> dict[str, np.ndarray]:
    """One part from several (batches, files): minima of minima, maxima of maxima."""
    if len(parts) == 1:
        return parts[0]
    if not parts:
        return {k: np.zeros(0) for k in PART}
    joined = {k: np.concatenate([p[k] for p in parts]) for k in PART}
    return _reduce(*(joined[k] for k in PART))


def _reduce(lo: np.ndarray, hi: np.ndarray, w: np.ndarray, fwd: np.ndarray, bwd: np.ndarray,
            t_lo: np.ndarray, t_hi: np.ndarray) -> dict[str, np.ndarray]:
    order = np.lexsort((w, hi, lo))
    lo = lo[order]   # one at a time: each unsorted array is freed before the next sorted one is made
    hi = hi[order]
    w = w[order]
    starts = np.flatnonzero(np.concatenate([[True], (lo[1:] != lo[:-1]) | (hi[1:] != hi[:-1])
                                            | (w[1:] != w[:-1])])) if len(lo) else np.zeros(0, dtype=np.intp)
    if not len(starts):
        return {k: np.zeros(0) for k in PART}
    return {"lo": lo[starts], "hi": hi[starts], "w": w[starts],   # fmin: the least that is not NaN
            "fwd": np.fmin.reduceat(fwd[order], starts), "bwd": np.fmin.reduceat(bwd[order], starts),
            "t_lo": np.minimum.reduceat(t_lo[order], starts),
            "t_hi": np.maximum.reduceat(t_hi[order], starts)}


def pair_windows(part: dict[str, np.ndarray]) -> dict[tuple[int, int], dict[str, np.ndarray]]:
    """Per pair (in order), its windows in time order: fwd, bwd, t_lo, t_hi and the middle t_mid."""
    lo, hi = part["lo"], part["hi"]
    if not len(lo):
        return {}
    table = {"fwd": part["fwd"], "bwd": part["bwd"], "t_lo": part["t_lo"], "t_hi": part["t_hi"],
             "t_mid": (part["t_lo"] + part["t_hi"]) / 2}
    first = np.flatnonzero(np.concatenate([[True], (lo[1:] != lo[:-1]) | (hi[1:] != hi[:-1])]))
    bounds = [*first.tolist(), len(lo)]
    return {(int(lo[i]), int(hi[i])): {k: v[i:j] for k, v in table.items()}
            for i, j in zip(bounds[:-1], bounds[1:], strict=True)}


def _receives(path: Path, node: int, batch_rows: int) -> Iterator[tuple[np.ndarray, ...]]:
    """(a, b, t_a, t_b, sample) of the receives in one node's messages file, a batch at a time."""
    pf = pq.ParquetFile(path)
    for batch in pf.iter_batches(batch_size=batch_rows, columns=_READ):
        kind = batch.column("kind")
        recv = pc.fill_null(pc.equal(kind.cast(pa.string()) if pa.types.is_dictionary(kind.type) else kind,
                                     "recv"), False).to_numpy(zero_copy_only=False)
        t_b = _floats(batch.column("t_s"))
        t_a = _floats(batch.column("t_sent_s"))
        keep = np.flatnonzero(recv & np.isfinite(t_b) & np.isfinite(t_a))
        if not len(keep):
            continue
        src = _floats(batch.column("src"))[keep]
        if np.isnan(src).any():
            raise ValueError(f"{path}: a receive with no sender")   # as the loaded table's cast raises
        t_a, t_b = t_a[keep], t_b[keep]
        yield src.astype(np.int64), np.full(len(keep), node, dtype=np.int64), t_a, t_b, t_b - t_a


def _floats(column: pa.Array) -> np.ndarray:
    return pc.cast(column, pa.float64()).to_numpy(zero_copy_only=False)


def run_window_parts(run_dir: Path, window_s: float, batch_rows: int = windows.BATCH_ROWS,
                     problems: list[str] | None = None) -> dict[str, np.ndarray]:
    """The (pair, window) statistics of every node's receives, read file by file, batch by batch; the
    running merge holds one part per node at most between merges."""
    merged: list[dict[str, np.ndarray]] = []
    for ndir in sorted(p for p in (Path(run_dir) / "logs").iterdir() if p.is_dir()):
        node = node_id(ndir.name)
        path = ndir / "messages.parquet"
        if node is None or node == NET or not path.is_file():
            continue
        try:
            parts = [window_parts(*rows, window_s) for rows in _receives(path, node, batch_rows)]
        except (OSError, pa.ArrowException) as exc:
            if problems is not None:
                problems.append(f"{ndir.name}/messages.parquet: unreadable for the clocks ({exc})")
            continue
        merged = [merge_parts([*merged, *parts])]
    return merge_parts(merged)
