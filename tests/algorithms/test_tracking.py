"""Tracking (RQ5 case 5): the tracker stays on the target; sentinels rendezvous on sector entry."""

import json
import math

import numpy as np
import pytest
from omegaconf import open_dict

from swarmbox.algorithms.tracking import RandomWalkTarget, ring_slots, sector_of, standby_points
from swarmbox.run.runner import execute
from tests.conftest import compose_config, table

AREA = (-50.0, -50.0, 50.0, 50.0)
N = 9   # the reference's fleet: a tracker and two sentinels per quadrant


@pytest.fixture(scope="module")
def chase(tmp_path_factory):
    cfg, choices = compose_config(["algo=tracking", "mission=tracking", "run.progress=false",
                                   "algo.params.start_s=8", "algo.params.duration_s=75"])
    with open_dict(cfg):
        cfg.mission.initial_positions = {i: [5.0 * (i // 3) - 5, 5.0 * (i % 3) - 5] for i in range(N)}
        cfg.mission.swarm_size = N
        cfg.mission.values = {0: [-50.0, -50.0], 1: [50.0, 50.0], 2: [2, 2]}
        cfg.mission.max_sim_time_s = 120.0
    d = tmp_path_factory.mktemp("tracking")
    return execute(cfg, d, choices, []), d


def markers(d, name):
    ev = table(d, "ground", "events").query(f"name == '{name}'")
    return [(t, json.loads(x)) for t, x in zip(ev["t_s"], ev["data"], strict=True)]


def test_geometry_helpers():
    corners = [(-1, -1), (1, -1), (-1, 1), (1, 1), (99, 99)]
    assert [sector_of(p, AREA, (2, 2)) for p in corners] == [0, 2, 1, 3, 3]
    pts = standby_points(AREA, (2, 2), [2, 2, 2, 1], 0.5)
    assert pts[3] == [(25.0, 25.0)] and all(sector_of(p, AREA, (2, 2)) == s for s in range(4) for p in pts[s])
    ring = ring_slots(3, 5.0, 4.0)   # the reference's triangle: tracker (-5, 0), sentinels (2.5, -/+4.33)
    assert ring[0] == pytest.approx((-5.0, 0.0)) and ring[1] == pytest.approx((2.5, -4.330), abs=1e-3)
    wide = ring_slots(8, 5.0, 4.0)
    assert min(math.dist(wide[a], wide[(a + 1) % 8]) for a in range(8)) == pytest.approx(4.0)


def test_target_walk_is_seeded_bounded_and_at_speed():
    walks = [RandomWalkTarget(np.random.default_rng(3), AREA, 10.0, 4.0) for _ in range(2)]
    path = []
    for _ in range(4000):
        for w in walks:
            w.step(0.025)
        path.append((walks[0].pos, walks[1].pos))
    assert all(a == b for a, b in path)
    steps = np.diff(np.array([a for a, _ in path]), axis=0)
    assert np.hypot(*steps.T).max() <= 4.0 * 0.025 + 1e-9
    assert all(-40 <= n <= 40 and -40 <= e <= 40 for (n, e), _ in path)


def test_tracker_stays_on_the_target(chase):
    manifest, d = chase
    assert manifest["status"] == "ok", manifest["reason"]
    dist = np.array([m["distance_m"] for _, m in markers(d, "tracking")])
    acquired = int(np.argmax(dist < 7.0))
    assert dist[0] > 20 and acquired < 15            # it had to fly out, and got there fast
    held = dist[acquired:]
    assert len(held) > 45 and held.max() < 14.0 and np.median(held) < 6.0   # ring radius 5 m


def test_entering_a_sector_triggers_a_rendezvous(chase):
    _, d = chase
    entries = markers(d, "sector_entry")
    meets = markers(d, "rendezvous")
    assert any(m["previous"] >= 0 for _, m in entries)    # the target did cross sectors
    ends = [t for t, _ in entries[1:]] + [math.inf]
    for (t0, entry), t1 in zip(entries, ends, strict=True):
        if t1 - t0 > 12.0:   # every sector visited long enough got its two sentinels to the target
            hit = [m for t, m in meets if t0 <= t <= t1 and m["sector"] == entry["sector"]]
            assert len(hit) == 1 and hit[0]["delay_s"] < 12.0 and len(hit[0]["drones"]) == 2, entry
    assert len(meets) >= 2
    for i in range(N):
        assert not (table(d, f"drone_{i}", "events")["kind"] == "collision").any()

