"""Proximity alerts: the ground alerts exactly the pairs that came closer than the limit, with start
and end times, tells both drones, and can look ahead by a time window."""

from __future__ import annotations

import itertools
import json
import math

import numpy as np
import pytest

from swarmbox.core.messages import DescendantState
from swarmbox.core.proximity import ProximityTracker
from tests.conftest import table

CROSSING = ("algo=crossing", "mission=crossing", "run.proximity_m=10")
TICK_S = 0.025


def _episodes(run_dir):
    ev = table(run_dir, "ground", "events")
    ends = ev[(ev["kind"] == "proximity") & (ev["name"] == "prox_end")]
    return {tuple(json.loads(d)["pair"]): (json.loads(d), t) for d, t in zip(ends["data"], ends["t_s"],
                                                                            strict=True)}


def _close_ticks(run_dir, limit_m):
    """Per pair, the ticks at which the drones' own position estimates were closer than ``limit_m``."""
    pos = {i: table(run_dir, f"drone_{i}", "state").set_index("tick")[["pos_n", "pos_e", "pos_d"]]
           for i in range(4)}
    out = {}
    for a, b in itertools.combinations(range(4), 2):
        j = pos[a].add_suffix("_a").join(pos[b].add_suffix("_b"), how="inner")
        dist = np.linalg.norm(j.iloc[:, :3].to_numpy() - j.iloc[:, 3:].to_numpy(), axis=1)
        ticks = j.index[dist < limit_m]
        if len(ticks):
            out[(a, b)] = (int(ticks.min()), int(ticks.max()), float(dist.min()))
    return out


def _both_drones_of_each_pair_told(d) -> None:
    """The crossing's pairs (0, 1) and (0, 2): the ground sent alerts to 0, 1 and 2, and each drone's
    algorithm hook heard of exactly the drones it came close to."""
    for i, others in {0: {1, 2}, 1: {0}, 2: {0}, 3: set()}.items():
        ev = table(d, f"drone_{i}", "events")
        warned = {json.loads(x)["other"] for x in ev.loc[ev["name"] == "near_miss_warning", "data"]}
        assert warned == others, i
    sent = table(d, "ground", "messages")
    prox = sent[(sent["kind"] == "send") & (sent["type"] == "prox")]
    assert set(prox["dst"]) == {0, 1, 2}


def test_alerts_exactly_the_pairs_that_came_within_10_m_with_start_and_end(run):
    manifest, d = run(*CROSSING)
    assert manifest["status"] == "ok", manifest["reason"]
    episodes, truth = _episodes(d), _close_ticks(d, 10.0)
    assert set(truth) == {(0, 1), (0, 2)}           # the mission's geometry, checked on the logs
    assert set(episodes) == set(truth)
    for pair, (first, last, min_d) in truth.items():
        ep, end_t = episodes[pair]
        # the ground sees a position one tick after the drone had it (the Report's trip)
        assert first * TICK_S < ep["start_t_s"] <= (first + 2) * TICK_S + 1e-9, pair
        assert (last + 1) * TICK_S < end_t <= (last + 3) * TICK_S + 1e-9, pair
        assert ep["breached"] and not ep["predicted"]
        assert ep["min_distance_m"] == pytest.approx(min_d, abs=0.15)
    _both_drones_of_each_pair_told(d)


@pytest.mark.parametrize("topology", ["tree", "leader_follower"])
def test_drones_below_a_direct_inferior_are_alerted_too(run, topology):
    """Drones 1 and 2 report through drone 0 here: the ground still alerts them, addressed directly."""
    manifest, d = run(*CROSSING, f"topology={topology}")
    assert manifest["status"] == "ok", manifest["reason"]
    reports = table(d, "ground", "messages")
    reports = reports[(reports["kind"] == "recv") & (reports["type"] == "report")]
    assert set(reports["src"]) == {0}                # the ground hears only drone 0 directly
    episodes, truth = _episodes(d), _close_ticks(d, 10.0)
    assert set(truth) == set(episodes) == {(0, 1), (0, 2)}
    for pair, (first, last, _) in truth.items():
        ep, end_t = episodes[pair]
        # a forwarded position is one more Report trip (one tick) older than a direct one
        assert first * TICK_S < ep["start_t_s"] <= (first + 3) * TICK_S + 1e-9, pair
        assert (last + 1) * TICK_S < end_t <= (last + 4) * TICK_S + 1e-9, pair
    _both_drones_of_each_pair_told(d)
    for i in (1, 2):   # received straight from the ground, then the all clear
        got = table(d, f"drone_{i}", "messages")
        got = got[(got["kind"] == "recv") & (got["type"] == "prox")]
        assert len(got) > 0 and set(got["src"]) == {-1}, i


def test_the_time_window_warns_before_the_pair_is_close(run):
    manifest, d = run(*CROSSING, "run.proximity_window_s=3")
    assert manifest["status"] == "ok", manifest["reason"]
    episodes = _episodes(d)
    assert set(episodes) == {(0, 1), (0, 2)}        # parallel and distant pairs are not predicted
    for ep, _ in episodes.values():
        assert ep["predicted"] and ep["breached"]
        assert 1.0 < ep["breach_t_s"] - ep["start_t_s"] <= 3.0 + 4 * TICK_S   # noisy velocity


def _view(*points):
    return tuple(DescendantState(i, 3, p) for i, p in enumerate(points))


def test_tracker_episodes_and_prediction():
    tr = ProximityTracker(5.0, window_s=2.0)
    pairs, started, _ = tr.update(0.0, _view((0, 0, 0), (20, 0, 0), (0, 30, 0)))
    assert pairs == {} and started == []
    # 0 and 1 close at 8 m/s: 12 m apart, closest approach within 1.5 s -> predicted
    pairs, started, _ = tr.update(0.5, _view((2, 0, 0), (18, 0, 0), (0, 30, 0)))
    assert list(pairs) == [(0, 1)] and started[0].predicted and not started[0].breached
    pairs, _, _ = tr.update(1.0, _view((6, 0, 0), (10, 0, 0), (0, 30, 0)))
    assert pairs[(0, 1)] == pytest.approx(4.0) and tr.active[(0, 1)].breach_t_s == 1.0
    _, _, ended = tr.update(3.0, _view((6, 0, 0), (30, 0, 0), (0, 30, 0)))
    assert [e.pair for e in ended] == [(0, 1)] and ended[0].min_distance_m == pytest.approx(4.0)
    with pytest.raises(ValueError, match="run.proximity_m"):
        ProximityTracker(0.0)


def test_the_kd_tree_path_finds_exactly_the_pairs_of_the_direct_check():
    """Above ``DIRECT_PAIRS_UP_TO`` drones candidate pairs come from a k-d tree: the same pairs, in the
    same order, as checking every pair (clustered points, many at the limit's scale)."""
    from swarmbox.core.proximity import DIRECT_PAIRS_UP_TO, NeighbourList

    rng = np.random.default_rng(7)
    for n in (DIRECT_PAIRS_UP_TO + 1, 80, 300):
        pts = rng.normal(0.0, 4.0, size=(n, 3)).round(1)   # rounding makes ties at the limit likely
        view = tuple(DescendantState(i, 3, tuple(map(float, p))) for i, p in enumerate(pts))
        brute = [(a, b) for a, b in itertools.combinations(range(n), 2)
                 if math.dist(view[a].pos_ned_m, view[b].pos_ned_m) < 2.0]
        found = NeighbourList().pairs(view, 2.0)
        exact = [(a, b) for a, b in found if math.dist(view[a].pos_ned_m, view[b].pos_ned_m) < 2.0]
        assert exact == brute   # candidates at exactly the limit are dropped by the caller's check


def _brute(view, limit_m):
    return [(a, b) for a, b in itertools.combinations(range(len(view)), 2)
            if math.dist(view[a].pos_ned_m, view[b].pos_ned_m) < limit_m]


def test_the_neighbour_list_finds_the_pairs_of_the_direct_check_while_the_swarm_moves():
    """Candidates kept between rebuilds: every tick the same pairs as checking every pair, while drones
    drift, one darts across the swarm (forcing rebuilds), the limit changes and a drone drops out."""
    from swarmbox.core.proximity import NeighbourList

    rng = np.random.default_rng(11)
    near = NeighbourList()
    n = 90
    pos = rng.uniform(-12.0, 12.0, size=(n, 3))
    ids = list(range(n))
    rebuilds = 0
    for tick in range(300):
        pos += rng.normal(0.0, 0.04, size=pos.shape)
        pos[0] = (-15.0 + 0.2 * tick, 0.0, 0.0)   # sweeps through the whole swarm
        if tick == 150:
            del ids[17]
        limit = 2.0 + 0.5 * math.sin(tick / 20.0)
        view = tuple(DescendantState(i, 3, tuple(map(float, pos[i]))) for i in ids)
        before = near._radius, near._ids
        got = near.pairs(view, limit)
        rebuilds += (near._radius, near._ids) != before
        assert got == _brute(view, limit), tick
    assert 10 < rebuilds < 200   # candidates were reused, and rebuilt when drones moved


def test_a_tracker_on_the_neighbour_list_alerts_exactly_as_one_checking_every_pair(monkeypatch):
    from swarmbox.core import proximity

    rng = np.random.default_rng(3)
    n, frames = 60, []
    pos, vel = rng.uniform(-10.0, 10.0, size=(n, 3)), rng.normal(0.0, 1.5, size=(n, 3))
    for _ in range(120):
        pos = pos + 0.025 * vel
        frames.append(tuple(DescendantState(i, 3, tuple(map(float, p))) for i, p in enumerate(pos)))

    def replay(tracker):
        out = []
        for k, view in enumerate(frames):
            pairs, started, ended = tracker.update(0.025 * k, view)
            out.append((pairs, [e.pair for e in started], [(e.pair, e.min_distance_m) for e in ended]))
        return out

    fast = replay(proximity.ProximityTracker(1.5, window_s=1.0))
    monkeypatch.setattr(proximity.NeighbourList, "pairs", lambda self, view, limit: _brute(view, limit))
    assert fast == replay(proximity.ProximityTracker(1.5, window_s=1.0))
    assert sum(len(p) for p, _, _ in fast) > 50   # the swarm did produce alerts
