"""Socratic swarm: auction clearing on hand-made bids, and coverage of a small area."""

import json
import math
from types import SimpleNamespace

import numpy as np
import pandas as pd
from omegaconf import OmegaConf, open_dict

from swarmbox.algorithms.socratic import SocraticGround, decode_points, tile_centres
from swarmbox.run.runner import execute
from tests.conftest import CONF, compose_config, table

PARAMS = OmegaConf.to_container(OmegaConf.load(CONF / "algo" / "socratic.yaml").params)
AREA = [[-30.0, -30.0], [30.0, 30.0]]   # 36 tiles of 10 m


def test_tiles_cover_the_area_row_by_row():
    centres = tile_centres(AREA, 10.0)
    assert centres.shape == (36, 2)
    assert centres[0].tolist() == [-25.0, -25.0] and centres[1].tolist() == [-25.0, -15.0]
    assert centres[-1].tolist() == [25.0, 25.0]
    assert decode_points("1.5,2;-3,4").tolist() == [[1.5, 2.0], [-3.0, 4.0]]
    assert decode_points("").shape == (0, 2)


def test_clearing_gives_each_tile_to_its_best_bidder_and_the_loser_its_next_choice():
    marks = []
    ctx = SimpleNamespace(params={**PARAMS, "area_ne_m": AREA}, stage_time_s=0.0,
                          mark=lambda name, **f: marks.append((name, f)),
                          reports={1: SimpleNamespace(data="3:5=-3.0,6=-4.0"),
                                   2: SimpleNamespace(data="3:5=-2.0,6=-10.0"),
                                   3: SimpleNamespace(data="2:7=-1.0")})     # a stale round: ignored
    ground = SocraticGround()
    ground.exec_once(ctx)
    ground.round, ground.calls = 3, {1: [5, 6], 2: [5, 6], 3: [7]}
    ground._clear(ctx)
    assert ground.claim == {2: 5, 1: 6} and ground.owner == {5: 2, 6: 1}
    assert [f["drone"] for name, f in marks if name == "tile_claimed"] == [2, 1]


def test_a_claim_without_progress_is_released_and_not_offered_to_that_drone_again():
    marks = []
    ctx = SimpleNamespace(params={**PARAMS, "area_ne_m": AREA}, stage_time_s=0.0,
                          mark=lambda name, **f: marks.append((name, f)), reports={})
    ground = SocraticGround()
    ground.exec_once(ctx)
    ground.claim, ground.owner, ground.progress = {4: 0}, {0: 4}, {4: (math.inf, 0.0)}
    stuck = {4: np.array([0.0, 0.0])}                             # 35 m from tile 0, not moving
    for t in (0.0, 1.0, PARAMS["blocked_s"] - 0.5):
        ctx.stage_time_s = t
        ground._check_claims(ctx, stuck, t)
    assert ground.claim == {4: 0}                                  # 7.5 s without progress: kept
    ctx.stage_time_s = PARAMS["blocked_s"] + 0.5
    ground._check_claims(ctx, stuck, ctx.stage_time_s)
    assert ground.claim == {} and ground.owner == {} and ground.avoid == {4: {0}}
    assert marks[-1] == ("tile_released", {"drone": 4, "tile": 0, "reason": "blocked"})
    ground._call(np.array([[-25.0, -25.0]]), [4], 3)                # standing on tile 0 itself
    assert 0 not in ground.calls[4] and len(ground.calls[4]) == 2


def fly(tmp_path, n: int, *overrides: str, prepare=None) -> tuple[dict, object]:
    """Run socratic with ``n`` drones on a 5 m grid over AREA (coverage goal 0.9)."""
    cfg, choices = compose_config(["algo=socratic", "mission=socratic", "run.progress=false",
                                   "algo.params.coverage_goal=0.9", "mission.max_sim_time_s=200", *overrides])
    side = math.ceil(math.sqrt(n))
    with open_dict(cfg):
        cfg.mission.initial_positions = {i: [5.0 * (i % side) - 5, 5.0 * (i // side) - 5] for i in range(n)}
        cfg.mission.swarm_size = n
        cfg.algo.params.area_ne_m = AREA
    return execute(cfg, tmp_path, choices, list(overrides), prepare), tmp_path


def claims_over_time(events: pd.DataFrame) -> list[tuple[str, int, int]]:
    """(claimed | released, drone, tile) in the order the ground logged them."""
    rows = events[events["name"].isin(["tile_claimed", "tile_released"])]
    return [(name, d["drone"], d["tile"]) for name, d in zip(rows["name"], map(json.loads, rows["data"]),
                                                                strict=True)]


def assert_exclusive(claims: list[tuple[str, int, int]]) -> None:
    """At every moment each tile has at most one claimant and each drone at most one tile."""
    owner: dict[int, int] = {}
    for kind, drone, tile in claims:
        if kind == "tile_claimed":
            assert tile not in owner and drone not in owner.values(), (drone, tile, owner)
            owner[tile] = drone
        else:
            assert owner.pop(tile) == drone


def test_swarm_covers_the_area_with_exclusive_claims_and_no_collisions(tmp_path):
    manifest, d = fly(tmp_path, 9)
    assert manifest["status"] == "ok", manifest["reason"]
    ev = table(d, "ground", "events")
    done = json.loads(ev[ev["name"] == "coverage_complete"]["data"].iloc[0])
    assert done["fraction"] >= 0.9
    claims = claims_over_time(ev)
    assert_exclusive(claims)
    assert sum(k == "tile_claimed" for k, _, _ in claims) >= 9
    # Coverage from ground truth, not from the ground's bookkeeping (estimates may be off by cm).
    states = pd.concat([table(d, f"drone_{i}", "state") for i in range(9)])
    flown = states[(states["stage"] == 3) & (states["true_d"] < -4.0)][["true_n", "true_e"]].to_numpy()
    centres = tile_centres(AREA, 10.0)
    near = [np.hypot(*(flown - c).T).min() <= PARAMS["cover_radius_m"] + 0.2 for c in centres]
    assert np.mean(near) >= 0.9
    events = pd.concat([table(d, f"drone_{i}", "events") for i in range(9)])
    assert not (events["kind"] == "collision").any()


def test_a_lost_drone_releases_its_tile_and_the_others_finish(tmp_path):
    manifest, d = fly(tmp_path, 4, prepare=lambda s: s.schedule(25.0, lambda sw: sw.remove_agent(3)))
    assert manifest["status"] == "ok", manifest["reason"]
    ev = table(d, "ground", "events")
    released = [json.loads(x) for x in ev[ev["name"] == "tile_released"]["data"]]
    assert any(r["drone"] == 3 and r["reason"] == "lost" for r in released)
    assert_exclusive(claims_over_time(ev))
    assert json.loads(ev[ev["name"] == "coverage_complete"]["data"].iloc[0])["fraction"] >= 0.9
