"""Runs of consecutive flags, fed a chunk of grid points at a time (the diagnosis' persistence)."""

from __future__ import annotations

import numpy as np


class FlagRuns:
    """Runs of consecutive flags per column, fed chunk by chunk of rows: a run still open at a chunk's
    end goes on in the next. A run of at least ``persist`` rows is an episode whose alarm is its
    ``persist``-th row; what that row showed (value, score, median, IQR) is kept while its chunk is at
    hand."""

    def __init__(self, columns: int, persist: int) -> None:
        self.persist = persist
        self.start = np.full(columns, -1, dtype=np.int64)   # row where the open run began, -1: none
        self.seen: dict[int, tuple] = {}                     # column -> its open run's alarm row values
        self.done: list[tuple[int, int, int, tuple]] = []    # column, alarm row, last row, values

    def feed(self, lo: int, flags: np.ndarray, shown: tuple[np.ndarray, ...]) -> None:
        """Rows ``lo``.. of every column (``flags``: rows x columns); ``shown``: the chunk's values and
        scores (rows x columns) and medians and IQRs (rows)."""
        active = np.flatnonzero(flags.any(axis=0) | (self.start >= 0))
        for j in active.tolist():
            edges = np.diff(np.concatenate([[self.start[j] >= 0], flags[:, j]]).astype("int8"))
            starts = (lo + np.flatnonzero(edges == 1)).tolist()
            stops = (lo + np.flatnonzero(edges == -1)).tolist()
            if self.start[j] >= 0:
                starts.insert(0, int(self.start[j]))
            for k, a in enumerate(starts):
                alarm = a + self.persist - 1
                if lo <= alarm < lo + len(flags) and (k >= len(stops) or stops[k] > alarm):
                    i = alarm - lo   # the run reaches its persistence in this chunk
                    value, score, med, iqr = shown
                    self.seen[j] = (float(value[i, j]), float(score[i, j]), float(med[i]), float(iqr[i]))
                if k < len(stops):
                    self._end(j, a, stops[k])
            self.start[j] = starts[-1] if len(starts) > len(stops) else -1

    def _end(self, j: int, a: int, stop: int) -> None:
        if stop - a >= self.persist:
            self.done.append((j, a + self.persist - 1, stop - 1, self.seen.pop(j)))
        self.seen.pop(j, None)

    def close(self, rows: int) -> list[tuple[int, int, int, tuple]]:
        """Every episode, the runs still open ending at ``rows``."""
        for j in np.flatnonzero(self.start >= 0).tolist():
            self._end(j, int(self.start[j]), rows)
        self.start[:] = -1
        return self.done
