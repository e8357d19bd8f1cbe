"""Proximity alerts on the ground node: which pairs of drones are (or are about to be) too close.

The ground sees every drone through the Reports it receives (direct inferiors and the descendants
they forward). Each tick the tracker finds the pairs closer than ``distance_m`` by those reported
positions and, with a look-ahead ``window_s`` > 0, also the pairs that will come closer than
``distance_m`` within the window if both keep their current velocity (closest point of approach;
velocities are differenced from consecutive reported positions, so forwarded descendants are
covered too). A pair stays in one *episode* from the first tick it is alerted to the first tick it
is not, and each episode is logged with its start, end and the smallest distance seen.

Pure logic (numpy/scipy only) so a ground node on a field laptop can run it at the tick rate.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass
from itertools import chain, combinations
from operator import itemgetter

import numpy as np

from swarmbox.core.messages import DescendantState

Pair = tuple[int, int]   # (lower id, higher id)
DIRECT_PAIRS_UP_TO = 24         # up to this many drones, check every pair directly
_ID, _POS = itemgetter(0), itemgetter(2)   # DescendantState's drone_id and pos_ned_m, read in C


@dataclass(slots=True)
class Episode:
    """One pair's alert, from the tick it started to the tick it ended."""

    pair: Pair
    start_t_s: float            # ground clock
    start_distance_m: float
    predicted: bool             # started on the look-ahead, before the pair was actually close
    min_distance_m: float
    breached: bool              # the pair did come closer than the distance
    breach_t_s: float | None = None


class ProximityTracker:
    """Alerted pairs per tick, and the episodes they form."""

    def __init__(self, distance_m: float, window_s: float = 0.0) -> None:
        if distance_m <= 0 or window_s < 0:
            raise ValueError(f"run.proximity_m must be > 0 and run.proximity_window_s >= 0, "
                             f"got {distance_m} and {window_s}")
        self.distance_m, self.window_s = float(distance_m), float(window_s)
        self.active: dict[Pair, Episode] = {}
        self._near = NeighbourList()
        self._last: dict[int, tuple[float, tuple[float, float, float]]] = {}
        self._vel: dict[int, tuple[float, float, float]] = {}

    def update(self, now_s: float, view: tuple[DescendantState, ...]
               ) -> tuple[dict[Pair, float], list[Episode], list[Episode]]:
        """One tick: returns (alerted pair -> current distance, episodes started, episodes ended)."""
        if self.window_s > 0:
            self._velocities(now_s, view)
        alerted = self._alerted(view)
        if not alerted and not self.active:   # the usual tick: nobody close, nothing open
            return {}, [], []
        started, ended = [], []
        for pair, (dist, predicted) in alerted.items():
            ep = self.active.get(pair)
            if ep is None:
                ep = self.active[pair] = Episode(pair, now_s, dist, predicted, dist, False)
                started.append(ep)
            ep.min_distance_m = min(ep.min_distance_m, dist)
            if not ep.breached and dist < self.distance_m:
                ep.breached, ep.breach_t_s = True, now_s
        for pair in [p for p in self.active if p not in alerted]:
            ended.append(self.active.pop(pair))
        return {p: d for p, (d, _) in alerted.items()}, started, ended

    # -- geometry -------------------------------------------------------------------------------
    def _alerted(self, view: tuple[DescendantState, ...]) -> dict[Pair, tuple[float, bool]]:
        if len(view) < 2:
            return {}
        reach = self.distance_m
        if self.window_s:
            reach += self.window_s * self._max_closing_speed()
        out: dict[Pair, tuple[float, bool]] = {}
        for a, b in self._near.pairs(view, reach):
            da, db = view[a], view[b]
            if da.drone_id == db.drone_id:   # seen directly and forwarded, during a handover
                continue
            dist = math.dist(da.pos_ned_m, db.pos_ned_m)
            pair = (da.drone_id, db.drone_id) if da.drone_id < db.drone_id else (db.drone_id, da.drone_id)
            if dist < self.distance_m:
                out[pair] = (dist, False)
            elif self.window_s > 0 and self._closes_in(da, db):
                out[pair] = (dist, True)
        return out

    def _closes_in(self, a: DescendantState, b: DescendantState) -> bool:
        va, vb = self._vel.get(a.drone_id), self._vel.get(b.drone_id)
        if va is None or vb is None:
            return False
        rel_p = [pa - pb for pa, pb in zip(a.pos_ned_m, b.pos_ned_m, strict=True)]
        rel_v = [x - y for x, y in zip(va, vb, strict=True)]
        vv = sum(v * v for v in rel_v)
        if vv <= 1e-12:
            return False
        t_cpa = min(max(-sum(p * v for p, v in zip(rel_p, rel_v, strict=True)) / vv, 0.0), self.window_s)
        closest = math.dist([p + v * t_cpa for p, v in zip(rel_p, rel_v, strict=True)], (0.0, 0.0, 0.0))
        return closest < self.distance_m

    def _velocities(self, now_s: float, view: tuple[DescendantState, ...]) -> None:
        for d in view:
            prev = self._last.get(d.drone_id)
            if prev is not None and now_s > prev[0] and prev[1] != d.pos_ned_m:
                dt = now_s - prev[0]
                self._vel[d.drone_id] = tuple((x - y) / dt for x, y in zip(d.pos_ned_m, prev[1],
                                                                           strict=True))
            if prev is None or prev[1] != d.pos_ned_m:
                self._last[d.drone_id] = (now_s, d.pos_ned_m)

    def _max_closing_speed(self) -> float:
        if not self._vel:
            return 0.0
        return 2.0 * max(math.hypot(*v) for v in self._vel.values())


@functools.cache
def kd_tree() -> type:
    """scipy's cKDTree, imported on first use: small swarms never need it, so runs start faster."""
    from scipy.spatial import cKDTree

    return cKDTree


class NeighbourList:
    """Candidate pairs for ``_pairs_within`` that stay valid while the swarm moves little (a Verlet list).

    A rebuild finds every pair within ``limit + 2 * SKIN_M`` of the current positions (k-d tree).
    Until some drone has moved more than ``SKIN_M`` from where it was then, no other pair can have come
    within ``limit``, so each tick only measures the stored candidates. The pairs returned are those
    of ``_pairs_within`` (a margin of rounding wider): the caller re-checks each with exact distances.
    Small swarms (up to ``DIRECT_PAIRS_UP_TO``) are checked directly every tick.
    """

    SKIN_M = 1.0

    def __init__(self) -> None:
        self._ids: tuple[int, ...] = ()
        self._origin = np.empty((0, 3))
        self._radius = -1.0
        self._cand = (np.empty(0, np.intp), np.empty(0, np.intp))

    def pairs(self, view: tuple[DescendantState, ...], limit_m: float) -> list[tuple[int, int]]:
        n = len(view)
        if n <= DIRECT_PAIRS_UP_TO:
            return _pairs_within(view, limit_m)
        pts = np.fromiter(chain.from_iterable(map(_POS, view)), float, 3 * n).reshape(-1, 3)
        ids = tuple(map(_ID, view))
        if ids != self._ids or not self._valid(pts, limit_m):
            self._rebuild(pts, ids, limit_m)
        a, b = self._cand
        if not len(a):
            return []
        gap = pts[a] - pts[b]
        near = np.einsum("ij,ij->i", gap, gap) <= (limit_m * (1 + 1e-9) + 1e-9) ** 2
        return list(zip(a[near].tolist(), b[near].tolist(), strict=True))

    def _valid(self, pts: np.ndarray, limit_m: float) -> bool:
        moved = pts - self._origin
        most = float(np.sqrt(np.einsum("ij,ij->i", moved, moved).max()))
        return limit_m + 2.0 * most <= self._radius

    def _rebuild(self, pts: np.ndarray, ids: tuple[int, ...], limit_m: float) -> None:
        self._ids, self._origin = ids, pts
        self._radius = limit_m + 2.0 * self.SKIN_M
        # built for one query: an unbalanced, non-compact tree builds faster and finds the same pairs
        tree = kd_tree()(pts, balanced_tree=False, compact_nodes=False)
        found = tree.query_pairs(self._radius, output_type="ndarray")
        found = found[np.lexsort((found[:, 1], found[:, 0]))] if len(found) else found.reshape(0, 2)
        self._cand = (found[:, 0].astype(np.intp), found[:, 1].astype(np.intp))


def _pairs_within(view: tuple[DescendantState, ...], limit_m: float) -> list[tuple[int, int]]:
    """Index pairs closer than ``limit_m`` (3-D), checking every pair (small swarms), in index order."""
    dist, points = math.dist, enumerate(map(_POS, view))
    return [(a, b) for (a, pa), (b, pb) in combinations(points, 2) if dist(pa, pb) < limit_m]
