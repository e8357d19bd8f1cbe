"""Socratic swarm (Henderson et al. 2017): area coverage by tile auctions and cost minimization.

The area ``area_ne_m`` is cut into square tiles of ``tile_m``; a tile is covered once any airborne
drone passes within ``cover_radius_m`` of its centre. The mission is complete when the covered
fraction reaches ``coverage_goal``.

Auction (sealed bids, one round every ``auction_period_s``), with the ground as auctioneer:

1. Call: every drone without a tile is sent the round number and its ``candidates`` nearest open
   tiles (neither covered nor claimed).
2. Bids: the drone prices each candidate with its own cost — ``w_dist``·distance + ``w_turn``·(1 −
   cos of the turn toward it) + ``w_crowd``·Σ exp(−|tile − neighbour| / ``sensing_m``) — and reports
   ``−cost`` for each in its Report's ``data``.
3. Clearing (consensus): all bids of the round, best first; a bid wins when neither its tile nor its
   bidder is taken yet, so each tile goes to its best bidder, each drone gets at most one tile and a
   drone that loses every candidate bids again next round.

A claim ends when the tile is covered (by anyone), when its drone is lost, or when the drone makes no
progress toward it (0.5 m closer) for ``blocked_s``: the tile is released for the others and that
drone never bids on it again. Markers: ``tile_claimed``, ``tile_released`` (reason covered / blocked /
lost), ``coverage`` every ``mark_period_s``, ``coverage_complete``.

Motion (drone, receding horizon): each tick the drone scores its own position, the straight step
toward its tile and ``samples`` random steps within ``step_m`` by ``w_goal``·|c − goal| + ``w_vel``·|c −
p| + ``w_sep``·Σ s(|c − n|) over the neighbours the ground relays (those within ``sensing_m``), with
s(d) = 1/max(d − ``body_m``, 0.05), ×10 below ``safe_m``; it flies to the cheapest as a position setpoint
facing its course. Random draws use the drone's seeded ``rng``.

Differences from the reference port: a real auction with bids computed by the drones instead of the
ground's greedy nearest-free-tile choice; claims of blocked or lost drones are released; completion
at a coverage fraction; the separation term is bounded; yaw is set; seeded randomness.
"""

import math
from dataclasses import dataclass, field

import numpy as np
from scipy.spatial import cKDTree

from swarmbox.api import DroneAlgorithm, DroneContext, GroundAlgorithm, GroundContext, Setpoint

CALL, GO, DONE = 0, 1, 2


def tile_centres(area_ne_m: list[list[float]], tile_m: float) -> np.ndarray:
    """Centres (T, 2) of the tiles covering [[n_min, e_min], [n_max, e_max]], row by row (north)."""
    (n0, e0), (n1, e1) = area_ne_m
    ns, es = np.arange(n0 + tile_m / 2, n1, tile_m), np.arange(e0 + tile_m / 2, e1, tile_m)
    return np.array([(n, e) for n in ns for e in es], float)


def decode_points(text: str) -> np.ndarray:
    """"n,e;n,e" -> array (M, 2)."""
    return np.array([q.split(",") for q in text.split(";")], float) if text else np.empty((0, 2))


@dataclass
class SocraticParams:
    """Typed ``params`` (see ``conf/algo/socratic.yaml``)."""

    # [[n_min, e_min], [n_max, e_max]]
    area_ne_m: list[list[float]] = field(default_factory=lambda: [[-80.0, -80.0], [80.0, 80.0]])
    tile_m: float = 10.0
    cover_radius_m: float = 4.0   # a tile is covered when a drone passes this close to its centre
    coverage_goal: float = 0.95   # covered fraction that completes the mission
    altitude_m: float = 5.0
    auction_period_s: float = 0.5   # one call + clearing per period
    candidates: int = 8   # tiles offered to each idle drone per round
    blocked_s: float = 8.0   # a claim without 0.5 m of progress for this long is released
    mark_period_s: float = 1.0
    w_dist: float = 1.0   # bid cost: per metre to the tile
    w_turn: float = 5.0   # bid cost: 1 - cos(turn toward the tile)
    w_crowd: float = 10.0   # bid cost: neighbours near the tile
    step_m: float = 3.0   # motion: reach of one planning step
    samples: int = 50   # motion: random candidate steps per tick
    w_goal: float = 2.0   # motion cost weights
    w_vel: float = 0.5
    w_sep: float = 10.0
    body_m: float = 0.6   # m, two drone radii: separation cost is bounded below this gap
    safe_m: float = 2.0   # m, separation cost x10 below this distance
    sensing_m: float = 8.0   # m, neighbours relayed to each drone


class SocraticGround(GroundAlgorithm):
    """Auctioneer and coverage bookkeeper; relays each drone's neighbours to it every tick."""

    Params = SocraticParams

    def exec_once(self, ctx: GroundContext) -> None:
        p = ctx.params
        self.centres = tile_centres(p["area_ne_m"], float(p["tile_m"]))
        self.tree = cKDTree(self.centres)
        self.covered = np.zeros(len(self.centres), bool)
        self.claim: dict[int, int] = {}          # drone -> tile
        self.owner: dict[int, int] = {}          # tile -> drone
        self.progress: dict[int, tuple[float, float]] = {}   # drone -> (best distance, since)
        self.avoid: dict[int, set[int]] = {}     # tiles a drone gave up on
        self.calls: dict[int, list[int]] = {}    # this round's candidates per drone
        self.round, self.start_s, self.done = 0, None, False
        self.next_auction_s = self.next_mark_s = 0.0

    def exec_loop(self, ctx: GroundContext) -> None:
        p, reps, now = ctx.params, ctx.reports, ctx.stage_time_s
        alt = float(p["altitude_m"])
        if self.start_s is None:
            if not reps or any(-r.pos_ned_m[2] < alt - 0.5 for r in reps.values()):
                return
            self.start_s = now
        ids = sorted(reps)
        pos = np.array([reps[d].pos_ned_m[:2] for d in ids])
        self._cover(ctx, pos, ids)
        self._check_claims(ctx, dict(zip(ids, pos, strict=True)), now)
        if not self.done and self.covered.mean() >= float(p["coverage_goal"]):
            self.done, self.next_mark_s = True, now
            ctx.mark("coverage_complete", fraction=float(self.covered.mean()), tiles=int(self.covered.sum()))
        if now >= self.next_mark_s:
            self.next_mark_s = now + float(p["mark_period_s"])
            ctx.mark("coverage", fraction=float(self.covered.mean()), claimed=len(self.claim))
        if not self.done and now >= self.next_auction_s:
            self.next_auction_s = now + float(p["auction_period_s"])
            self._clear(ctx)
            self._call(pos, ids, int(p["candidates"]))
        neighbours = cKDTree(pos).query_ball_point(pos, float(p["sensing_m"]))
        for k, d in enumerate(ids):
            near = ";".join(f"{pos[j, 0]:.2f},{pos[j, 1]:.2f}" for j in neighbours[k] if j != k)
            if self.done:
                ctx.send_task(d, code=DONE, reliable=False)
            elif d in self.claim:
                n, e = self.centres[self.claim[d]].tolist()
                ctx.send_task(d, code=GO, waypoint_ned_m=(n, e, -alt), data=f"|{near}", reliable=False)
            else:
                cands = ",".join(map(str, self.calls.get(d, ())))
                ctx.send_task(d, code=CALL, data=f"{self.round}:{cands}|{near}", reliable=False)

    def _cover(self, ctx: GroundContext, pos: np.ndarray, ids: list[int]) -> None:
        for k, tiles in enumerate(self.tree.query_ball_point(pos, float(ctx.params["cover_radius_m"]))):
            for t in tiles:
                if not self.covered[t]:
                    self.covered[t] = True
                    if t in self.owner:
                        self._release(ctx, self.owner[t], "covered", by=ids[k])

    def _check_claims(self, ctx: GroundContext, pos: dict[int, np.ndarray], now: float) -> None:
        """Release the claims of lost drones and of drones that stopped getting closer."""
        for d, tile in list(self.claim.items()):
            if d not in pos:
                self._release(ctx, d, "lost")
                continue
            dist = float(np.hypot(*(pos[d] - self.centres[tile])))
            best, since = self.progress[d]
            if dist < best - 0.5:
                self.progress[d] = (dist, now)
            elif now - since > float(ctx.params["blocked_s"]):
                self.avoid.setdefault(d, set()).add(tile)
                self._release(ctx, d, "blocked")

    def _release(self, ctx: GroundContext, drone: int, reason: str, **fields: int) -> None:
        tile = self.claim.pop(drone)
        del self.owner[tile]
        ctx.mark("tile_released", drone=drone, tile=tile, reason=reason, **fields)

    def _clear(self, ctx: GroundContext) -> None:
        """Award this round's bids, best first, to a free tile and a free bidder."""
        bids = []
        for d, cands in self.calls.items():
            rep = ctx.reports.get(d)
            head, _, body = rep.data.partition(":") if rep is not None else ("", "", "")
            if head != str(self.round) or d in self.claim or not body:
                continue
            for item in body.split(","):
                tile, _, value = item.partition("=")
                if int(tile) in cands:
                    bids.append((float(value), d, int(tile)))
        for value, d, tile in sorted(bids, reverse=True):
            if d not in self.claim and tile not in self.owner and not self.covered[tile]:
                self.claim[d], self.owner[tile] = tile, d
                self.progress[d] = (math.inf, ctx.stage_time_s)
                ctx.mark("tile_claimed", drone=d, tile=tile, bid=value)

    def _call(self, pos: np.ndarray, ids: list[int], k: int) -> None:
        """Open a round: each drone without a tile gets its ``k`` nearest open tiles."""
        self.round += 1
        free = np.flatnonzero(~self.covered)
        free = free[[t not in self.owner for t in free]]
        self.calls = {}
        if not len(free):
            return
        tree = cKDTree(self.centres[free])
        for i, d in enumerate(ids):
            if d not in self.claim:
                near = np.atleast_1d(tree.query(pos[i], k=min(k, len(free)))[1])
                self.calls[d] = [int(free[j]) for j in near if int(free[j]) not in self.avoid.get(d, ())]


class SocraticDrone(DroneAlgorithm):
    """Bids for tiles when called; flies to its tile by sampled cost minimization."""

    Params = SocraticParams

    def exec_once(self, ctx: DroneContext) -> None:
        self.centres = tile_centres(ctx.params["area_ne_m"], float(ctx.params["tile_m"]))

    def exec_loop(self, ctx: DroneContext) -> Setpoint | None:
        p, task = ctx.params, ctx.last_task
        alt = float(p["altitude_m"])
        if task is None:
            n, e, _ = ctx.home_ned_m
            return Setpoint.position(n, e, -alt)
        head, _, near = task.data.partition("|")
        pos = np.array(ctx.pos_ned_m[:2])
        ctx.report_data = self._bids(ctx, pos, head, decode_points(near)) if task.code == CALL else ""
        if task.code != GO or task.waypoint_ned_m is None:
            return None   # hold the last setpoint
        step = self._step(ctx, pos, np.array(task.waypoint_ned_m[:2]), decode_points(near))
        course = step - pos
        yaw = math.atan2(course[1], course[0]) if np.hypot(*course) > 0.3 else None
        return Setpoint.position(float(step[0]), float(step[1]), -alt, yaw)

    def _bids(self, ctx: DroneContext, pos: np.ndarray, head: str, others: np.ndarray) -> str:
        """"round:tile=bid,..." for the called candidates (bid = −cost, higher wins)."""
        p = ctx.params
        rnd, _, cands = head.partition(":")
        if not cands:
            return ""
        tiles = [int(t) for t in cands.split(",")]
        to = self.centres[tiles] - pos
        dist = np.maximum(np.hypot(*to.T), 1e-6)
        vel = np.array(ctx.vel_ned_m_s[:2])
        speed = float(np.hypot(*vel))
        turn = 1.0 - (to @ vel) / (dist * speed) if speed > 0.3 else np.zeros(len(tiles))
        crowd = np.zeros(len(tiles))
        if len(others):
            gaps = np.hypot(*(self.centres[tiles][:, None, :] - others[None, :, :]).transpose(2, 0, 1))
            crowd = np.exp(-gaps / float(p["sensing_m"])).sum(axis=1)
        cost = float(p["w_dist"]) * dist + float(p["w_turn"]) * turn + float(p["w_crowd"]) * crowd
        return f"{rnd}:" + ",".join(f"{t}={-c:.3f}" for t, c in zip(tiles, cost.tolist(), strict=True))

    def _step(self, ctx: DroneContext, pos: np.ndarray, goal: np.ndarray, others: np.ndarray) -> np.ndarray:
        """The cheapest of: stay, the straight step toward ``goal``, ``samples`` random steps; the
        separation cost of a step counts each neighbour's closest approach along it."""
        p = ctx.params
        reach = float(p["step_m"])
        to = goal - pos
        direct = pos + to * min(1.0, reach / max(float(np.hypot(*to)), 1e-9))
        sampled = ctx.rng.uniform(-reach, reach, size=(int(p["samples"]), 2))
        steps = np.vstack([np.zeros(2), direct - pos, sampled])
        cands = pos + steps
        cost = float(p["w_goal"]) * np.hypot(*(cands - goal).T) + float(p["w_vel"]) * np.hypot(*steps.T)
        if len(others):
            rel = others - pos                                    # (M, 2)
            t = np.clip(steps @ rel.T / np.maximum((steps * steps).sum(axis=1), 1e-9)[:, None], 0.0, 1.0)
            d = np.hypot(*(t[:, :, None] * steps[:, None, :] - rel[None, :, :]).transpose(2, 0, 1))
            s = 1.0 / np.maximum(d - float(p["body_m"]), 0.05) * np.where(d < float(p["safe_m"]), 10.0, 1.0)
            cost += float(p["w_sep"]) * np.where(d < float(p["sensing_m"]), s, 0.0).sum(axis=1)
        return cands[int(np.argmin(cost))]

    def exec_complete(self, ctx: DroneContext) -> bool:
        return ctx.last_task is not None and ctx.last_task.code == DONE
