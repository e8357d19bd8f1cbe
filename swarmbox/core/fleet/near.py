"""Whether any two of a set of points may be within a distance: a cheap, conservative test that lets
the ground skip its proximity tracker in the ticks where no pair can be close.

Small sets are checked pair by pair; larger ones keep a Verlet list like the tracker's own
(:class:`swarmbox.core.proximity.NeighbourList`): the pairs within ``limit + 2 * SKIN_M`` when the list
was built stay the only candidates until some point has moved more than ``SKIN_M``. The answer may
be a false "maybe" (then the tracker decides), never a false "no": the limit carries a margin wider
than the tracker's own rounding.
"""

from __future__ import annotations

import functools

import numpy as np

from swarmbox.core.proximity import kd_tree

_DIRECT_UP_TO = 48


@functools.cache
def _pairs(n: int) -> tuple[np.ndarray, np.ndarray]:
    return np.triu_indices(n, 1)


def _margin(limit_m: float) -> float:
    return limit_m * (1 + 1e-6) + 1e-6


class NearPairs:
    SKIN_M = 1.0

    def __init__(self) -> None:
        self._origin = np.empty((0, 3))
        self._ids = np.empty(0, np.intp)
        self._radius = -1.0
        self._cand = (np.empty(0, np.intp), np.empty(0, np.intp))

    def maybe(self, pts: np.ndarray, ids: np.ndarray, limit_m: float) -> bool:
        """Whether two of ``pts`` (n, 3; point ``j`` belongs to ``ids[j]``) may be closer than ``limit_m``."""
        n = len(pts)
        if n < 2:
            return False
        limit = _margin(limit_m)
        if n <= _DIRECT_UP_TO:
            a, b = _pairs(n)
            gap = pts[a] - pts[b]
            return bool((np.einsum("ij,ij->i", gap, gap) <= limit * limit).any())
        if not np.array_equal(ids, self._ids) or not self._valid(pts, limit):
            self._rebuild(pts, ids, limit)
        a, b = self._cand
        if not len(a):
            return False
        gap = pts[a] - pts[b]
        return bool((np.einsum("ij,ij->i", gap, gap) <= limit * limit).any())

    def _valid(self, pts: np.ndarray, limit: float) -> bool:
        moved = pts - self._origin
        most = float(np.sqrt(np.einsum("ij,ij->i", moved, moved).max()))
        return limit + 2.0 * most <= self._radius

    def _rebuild(self, pts: np.ndarray, ids: np.ndarray, limit: float) -> None:
        self._origin, self._ids = pts.copy(), ids.copy()
        self._radius = limit + 2.0 * self.SKIN_M
        found = kd_tree()(pts).query_pairs(self._radius, output_type="ndarray")
        found = found.reshape(-1, 2)
        self._cand = (found[:, 0].astype(np.intp), found[:, 1].astype(np.intp))
