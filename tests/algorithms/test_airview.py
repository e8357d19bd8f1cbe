"""Airview (RQ5 case 1): sectors partition the area, and the swarm covers it."""

import json
import math

import pytest
from omegaconf import open_dict

from swarmbox.algorithms.airview import CoverageMap, assign_sectors, lawnmower, split_area
from swarmbox.run.runner import execute
from tests.conftest import compose_config, table

AREA = (-22.5, -22.5, 37.5, 37.5)   # 60 m x 60 m around a 2 x 2 launch grid


def fly(tmp_path, n: int, area=AREA, *overrides: str):
    """Run airview with ``n`` drones on a 5 m grid over ``area``; returns (manifest, run dir)."""
    cfg, choices = compose_config(["algo=airview", "mission=airview16", "run.progress=false", *overrides])
    side = math.ceil(math.sqrt(n))
    with open_dict(cfg):
        cfg.mission.initial_positions = {i: [5.0 * (i % side), 5.0 * (i // side)] for i in range(n)}
        cfg.mission.swarm_size = n
        cfg.mission.values = {0: list(area[:2]), 1: list(area[2:])}
        cfg.mission.max_sim_time_s = 150.0
    return execute(cfg, tmp_path, choices, []), tmp_path


@pytest.mark.parametrize("count", [1, 4, 7, 36])
def test_sectors_tile_the_area_exactly(count):
    sectors = split_area(AREA, count)
    assert len(sectors) == count
    assert sum((n1 - n0) * (e1 - e0) for n0, e0, n1, e1 in sectors) == pytest.approx(60 * 60)
    for a in range(count):
        for b in range(a + 1, count):
            sa, sb = sectors[a], sectors[b]
            overlap_n = min(sa[2], sb[2]) - max(sa[0], sb[0])
            overlap_e = min(sa[3], sb[3]) - max(sa[1], sb[1])
            assert overlap_n <= 1e-9 or overlap_e <= 1e-9


def test_lawnmower_with_the_footprint_covers_its_sector():
    sector = (0.0, 0.0, 33.0, 50.0)
    path = lawnmower(sector, 10.0, (-5.0, -5.0))
    assert path[0] == pytest.approx((33 / 8, 5.0))          # corner nearest the start, legs along east
    cov = CoverageMap(sector, 5.0)
    for (n0, e0), (n1, e1) in zip(path, path[1:], strict=False):
        for k in range(101):
            cov.observe(n0 + (n1 - n0) * k / 100, e0 + (e1 - e0) * k / 100)
    assert cov.covered_frac == 1.0


def test_assignment_sends_each_drone_to_a_near_sector():
    homes = {0: (0.0, 0.0), 1: (0.0, 100.0)}
    sectors = [(0.0, 90.0, 20.0, 110.0), (0.0, -10.0, 20.0, 10.0)]
    assert assign_sectors(homes, sectors) == {0: sectors[1], 1: sectors[0]}


def test_four_drones_cover_the_area_and_come_home(tmp_path):
    manifest, d = fly(tmp_path, 4)
    assert manifest["status"] == "ok", manifest["reason"]
    ev = table(d, "ground", "events")
    cov = [json.loads(x)["covered_frac"] for x in ev[ev["name"] == "coverage"]["data"]]
    assert cov == sorted(cov) and cov[-1] >= 0.99           # covered fraction only grows, to ~all
    t90 = ev[ev["name"] == "coverage_90"]["t_s"]
    assert len(t90) == 1 and t90.iloc[0] < 60.0
    sectors = {json.loads(x)["drone"]: json.loads(x)["sector"]
               for x in ev[ev["name"] == "sector_assigned"]["data"]}
    assert sorted(sectors) == [0, 1, 2, 3]
    for i in range(4):
        st = table(d, f"drone_{i}", "state")
        assert not (table(d, f"drone_{i}", "events")["kind"] == "collision").any()
        # The drone swept its own sector (well inside its edges for a good while).
        n0, e0, n1, e1 = sectors[i]
        sweep = st[(st["tick"] > ev[ev["name"] == "coverage_90"]["tick"].iloc[0] - 400)
                   & (st["true_n"].between(n0 + 3, n1 - 3)) & (st["true_e"].between(e0 + 3, e1 - 3))]
        assert len(sweep) > 100
        last = st.iloc[-1]
        home = (5.0 * (i % 2), 5.0 * (i // 2))
        assert last["landed"] and math.hypot(last["true_n"] - home[0], last["true_e"] - home[1]) < 1.5
