"""The ground node of the fleet core: the object core's :class:`~swarmbox.core.ground.GroundNode`, its
stage machine and hooks unchanged, with its direct inferiors kept as arrays instead of one object
and one Report per drone.

A batch of delivered Reports updates the arrays in a few numpy calls; only a drone that joins,
rejoins or is lost goes through Python (it logs an event). What the node's methods and the hooks'
context read — the inferiors, the alive Reports, the head-count, the descendants — is computed
from the arrays, and the views the hooks see are built only when they ask for them. Proximity
alerts run the object core's tracker, but only in a tick where some pair may be within reach (a
conservative test over the reported positions) or an episode is open.
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping
from types import MappingProxyType
from typing import Any

import numpy as np

from swarmbox.api import DescendantState, InferiorReport
from swarmbox.core.fleet.near import NearPairs
from swarmbox.core.ground import GroundNode, _ids
from swarmbox.core.messages import Report, TaskAck
from swarmbox.core.node import STAGE_OF
from swarmbox.core.stages import Stage

_ABORT = int(Stage.ABORT)


class _InferiorView:
    """One direct inferior as the object core's ``_Inferior`` reads (``report``, ``alive``, ...)."""

    __slots__ = ("_g", "_k")

    def __init__(self, ground: FleetGround, k: int) -> None:
        self._g, self._k = ground, k

    @property
    def alive(self) -> bool:
        return bool(self._g.alive[self._k])

    @property
    def silent_ticks(self) -> int:
        return int(self._g.silent[self._k])

    @property
    def received(self) -> int:
        return int(self._g.received[self._k])

    @property
    def report(self) -> Report:
        g, k = self._g, self._k
        disc = g.rep_disc[k]
        return Report(0, float(g.rep_sent[k]), g.drone_ids[k], -1, int(g.rep_stage[k]),
                      bool(g.rep_complete[k]), 1, int(g.rep_alive[k]), tuple(g.rep_pos[k].tolist()),
                      tuple(g.rep_vel[k].tolist()), None if np.isnan(disc[0]) else tuple(disc.tolist()),
                      g.rep_data[k], ())


class _Inferiors(Mapping):
    """The inferiors that ever reported, in the order they joined."""

    def __init__(self, ground: FleetGround) -> None:
        self._g = ground

    def _k(self, drone_id: Any) -> int:
        k = self._g.index.get(drone_id)
        if k is None or not self._g.joined[k]:
            raise KeyError(drone_id)
        return k

    def __getitem__(self, drone_id: Any) -> _InferiorView:
        return _InferiorView(self._g, self._k(drone_id))

    def __contains__(self, drone_id: object) -> bool:
        k = self._g.index.get(drone_id)
        return k is not None and bool(self._g.joined[k])

    def __iter__(self) -> Iterator[int]:
        return iter(self._g.in_join_order().tolist())

    def __len__(self) -> int:
        return int(self._g.joined.sum())


class FleetGround(GroundNode):
    """A GroundNode whose direct inferiors are the whole fleet (a centralized topology), as arrays."""

    def __init__(self, algorithm: Any, drone_ids: list[int], **kw: Any) -> None:
        n = len(drone_ids)
        self.drone_ids = list(drone_ids)
        self.ids = np.array(drone_ids, dtype=np.int64)
        self.index = {d: k for k, d in enumerate(drone_ids)}
        self.joined, self.alive = np.zeros(n, bool), np.zeros(n, bool)
        self.join_seq, self.alive_seq = np.zeros(n, np.int64), np.zeros(n, np.int64)
        self._order = 0
        self.silent, self.received = np.zeros(n, np.int64), np.zeros(n, np.int64)
        self.rep_stage, self.rep_complete = np.zeros(n, np.int64), np.zeros(n, bool)
        self.rep_alive, self.rep_t = np.zeros(n, np.int64), np.zeros(n)
        # its send time and GNSS discrepancy (NaN: none): the live monitor's latency and ``disc m``
        self.rep_sent, self.rep_disc = np.zeros(n), np.full((n, 3), np.nan)
        self.rep_pos, self.rep_vel = np.zeros((n, 3)), np.zeros((n, 3))
        self.rep_data = np.full(n, "", dtype=object)
        self._views: dict[str, Any] = {}
        self._near = NearPairs()
        self.due: np.ndarray | None = None   # this tick's Reports (network.ITEM records, set by the fleet)
        self.acks: list[TaskAck] = []
        super().__init__(algorithm, **kw)
        self.inferiors = _Inferiors(self)   # type: ignore[assignment]

    # -- the inbox, as arrays ---------------------------------------------------------------------
    def _drain_inbox(self) -> None:
        due, self.due = self.due, None
        for ack in self.acks:
            self.on_ack(ack)
        self.acks = []
        if due is None or not len(due):
            return
        self._views.clear()
        k = due["srci"] - 1   # drone index of each Report, in hand-over order
        new = ~(self.joined[k] & self.alive[k])
        if new.any():
            self._arrivals(k, new)
        counts = np.bincount(k, minlength=len(self.received))
        self.received += counts
        if counts.max() > 1:   # each drone's latest Report (several arrive in one tick with jitter)
            last = len(k) - 1 - np.unique(k[::-1], return_index=True)[1]
        else:
            last = np.arange(len(k))
        src = k[last]
        self.silent[src] = 0
        self.rep_stage[src], self.rep_complete[src] = due["stage"][last], due["complete"][last]
        self.rep_alive[src] = due["alive"][last]
        if (due["data"] >= 0).any() or (self.rep_data[src] != "").any():
            texts = [self.net.text(key) for key in due["data"].tolist()]   # released, latest kept
            self.rep_data[src] = [texts[i] for i in last.tolist()]
        self.rep_pos[src], self.rep_vel[src] = due["pos"][last], due["vel"][last]
        self.rep_t[src], self.rep_sent[src] = self.clock.now(), due["t_sent"][last]
        self.rep_disc[src] = due["disc"][last]

    def _arrivals(self, k: np.ndarray, new: np.ndarray) -> None:
        """Drones joining or coming back, in hand-over order (Node.on_report's events)."""
        for drone in dict.fromkeys(k[new].tolist()):
            if not self.joined[drone]:
                self.joined[drone], self.join_seq[drone] = True, self._next()
                self.received[drone] = 0   # counted with the batch: 1 on joining, as _Inferior does
                self.event("topology", "inferior_joined", self.drone_ids[drone])
            elif not self.alive[drone]:
                self.event("topology", "inferior_rejoined", self.drone_ids[drone])
            else:
                continue
            self.alive[drone], self.alive_seq[drone] = True, self._next()

    def _next(self) -> int:
        self._order += 1
        return self._order

    def age_inferiors(self) -> None:
        self.silent[self.joined] += 1
        lost = np.flatnonzero(self.alive & (self.silent > self.timing.lost_inferior_ticks))
        if not len(lost):
            return
        self._views.clear()
        for k in lost[np.argsort(self.join_seq[lost])].tolist():
            drone = self.drone_ids[k]
            self.alive[k] = False
            self.event("topology", "inferior_lost", drone, silent_ticks=int(self.silent[k]))
            for seq, retries in self.outbox.forget(drone):
                self.event("error", "task_undelivered", drone, seq=seq, retries=retries,
                           incarnation=self.incarnation, reason="receiver lost")

    # -- what the node and its hooks read ---------------------------------------------------------
    def in_join_order(self) -> np.ndarray:
        joined = np.flatnonzero(self.joined)
        return self.ids[joined[np.argsort(self.join_seq[joined])]]

    def _alive_order(self) -> np.ndarray:
        """Alive drones' indices in the order of the object core's ``_alive`` dict (re-inserted on
        rejoining)."""
        alive = np.flatnonzero(self.alive)
        return alive[np.argsort(self.alive_seq[alive])]

    def alive_reports(self) -> Mapping[int, InferiorReport]:
        view = self._views.get("alive")
        if view is None:
            ks = self._alive_order().tolist()
            reports = {self.drone_ids[k]: InferiorReport(
                self.drone_ids[k], STAGE_OF[int(self.rep_stage[k])], bool(self.rep_complete[k]),
                tuple(self.rep_pos[k].tolist()), tuple(self.rep_vel[k].tolist()), self.rep_data[k],
                float(self.rep_t[k])) for k in ks}
            view = self._views["alive"] = MappingProxyType(reports)
        return view

    def inferiors_complete(self) -> bool:
        alive = self.alive & (self.rep_stage != _ABORT)
        return bool((self.rep_complete[alive] & (self.rep_stage[alive] == int(self.stage))).all())

    def head_count(self) -> tuple[int, int]:
        return int(self.alive.sum()), int(self.rep_alive[self.alive].sum())

    def descendants(self) -> tuple[DescendantState, ...]:
        view = self._views.get("descendants")
        if view is None:
            joined = np.flatnonzero(self.joined)
            ks = joined[np.argsort(self.join_seq[joined])]
            ks = ks[self.alive[ks]].tolist()
            view = self._views["descendants"] = tuple(
                DescendantState(self.drone_ids[k], int(self.rep_stage[k]), tuple(self.rep_pos[k].tolist()))
                for k in ks)
        return view

    def _commands_none(self) -> bool:
        """GroundNode._commands_none over the arrays (every alive inferior aborted: hold, then abort)."""
        alive = self.alive
        if self.stage is Stage.LANDING or not alive.any() or (self.rep_stage[alive] != _ABORT).any():
            self._orphaned_since = None
            return False
        tick = self.time.tick
        if self._orphaned_since is None:
            self._orphaned_since = tick
        if tick - self._orphaned_since <= self.timing.lost_superior_ticks + self.timing.lost_inferior_ticks:
            return True
        direct = [d for d in self.in_join_order().tolist() if self.alive[self.index[d]]]
        self.enter(Stage.ABORT, f"every drone the ground commands aborted ({_ids(direct)}) and none "
                                f"took over: the {self.stage.name} was cut short")
        return True

    def _proximity_alerts(self) -> None:
        """The object core's alerts, run only when some pair may be close or an episode is open.
        With a look-ahead (``proximity_window_s`` > 0) the tracker runs every tick, as on the object
        core: it differences each tick's reported positions into the velocities it predicts with."""
        tracker = self.proximity
        if self.prox_pairs or tracker.active or tracker.window_s > 0:
            super()._proximity_alerts()
            return
        alive = np.flatnonzero(self.alive)
        if self._near.maybe(self.rep_pos[alive], alive, tracker.distance_m):
            super()._proximity_alerts()
