"""Adaptive swarm: the planner on hand-made maps, and a formation escaping the cup to the goal."""

import math

import numpy as np
import pandas as pd
import pytest
from omegaconf import OmegaConf, open_dict

from swarmbox.algorithms.adaptive_plan import avoid, clearance, edge_free, resample, rrt, shortcut, surface
from swarmbox.run.runner import execute
from tests.conftest import CONF, compose_config, table

PARAMS = OmegaConf.to_container(OmegaConf.load(CONF / "algo" / "adaptive.yaml").params, resolve=False)
WALL = {"kind": "box", "center": [10.0, 0.0], "size": [2.0, 30.0]}   # a wall across the way north


def test_surface_of_a_box_from_outside_and_inside():
    assert surface(WALL, 20.0, 0.0) == pytest.approx((11.0, 0.0, 9.0, 1.0, 0.0))
    n, e, d, un, ue = surface(WALL, 10.5, 3.0)               # inside: out through the nearer face
    assert (n, e, d, un, ue) == pytest.approx((11.0, 3.0, -0.5, 1.0, 0.0))
    assert clearance([WALL, {"kind": "circle", "center": [0.0, 0.0], "radius_m": 1.0}], 0.0, 3.0) == 2.0


def test_avoid_pushes_away_removes_motion_into_the_wall_and_keeps_motion_along_it():
    here, gain, influence = np.array([7.0, 0.0]), 2.0, 3.0          # 2 m south of the wall
    push = gain * (1 / 2 - 1 / 3) / 4
    assert avoid([WALL], here, np.zeros(2), influence, gain) == pytest.approx([-push, 0.0])
    into = avoid([WALL], here, np.array([1.0, 0.0]), influence, gain)
    assert into == pytest.approx([1.0 - (1.0 - 2 / 3) - push, 0.0])  # a third of it removed at 2 of 3 m
    along = avoid([WALL], here, np.array([0.0, 2.0]), influence, gain)
    assert along == pytest.approx([-push, 2.0])
    assert avoid([WALL], np.zeros(2), np.array([1.0, 1.0]), influence, gain).tolist() == [1.0, 1.0]


def plan(seed: int, obstacles: list, goal=(20.0, 0.0), iters: int = 3000):
    p = {**PARAMS, "rrt_max_iters": iters}
    bounds = np.array([[-10.0, -30.0], [30.0, 30.0]])
    return rrt(np.zeros(2), np.array(goal), obstacles, bounds, np.random.default_rng(seed), p)


def test_rrt_goes_around_the_wall_keeping_the_clearance_and_is_reproducible():
    path = plan(1, [WALL])
    assert path is not None and np.allclose(path[0], [0, 0]) and np.allclose(path[-1], [20, 0])
    margin = float(PARAMS["clearance_m"])
    assert all(edge_free([WALL], a, b, margin) for a, b in zip(path[:-1], path[1:], strict=True))
    assert max(abs(q[1]) for q in path) > 15.0 + margin            # around an end of the wall
    assert all(np.allclose(a, b) for a, b in zip(path, plan(1, [WALL]), strict=True))
    short = shortcut(path, [WALL], np.random.default_rng(2), 80, margin)
    length = lambda ps: sum(math.dist(a, b) for a, b in zip(ps[:-1], ps[1:], strict=True))  # noqa: E731
    assert length(short) <= length(path) + 1e-9
    assert all(edge_free([WALL], a, b, margin) for a, b in zip(short[:-1], short[1:], strict=True))
    points = resample(short, 3.0)
    assert max(math.dist(a, b) for a, b in zip(points[:-1], points[1:], strict=True)) <= 3.0 + 1e-9


def test_rrt_gives_up_after_its_iteration_cap_when_the_goal_is_enclosed():
    cage = [{"kind": "circle", "center": [20.0, 0.0], "radius_m": 6.0}]   # the goal is inside it
    assert plan(0, cage, iters=300) is None


def fly(tmp_path, positions: dict[int, list[float]], *overrides: str) -> tuple[dict, object]:
    """Run the adaptive mission with drone 0 leading the others from ``positions``."""
    cfg, choices = compose_config(["algo=adaptive", "mission=adaptive", "run.progress=false", *overrides])
    with open_dict(cfg):
        cfg.mission.initial_positions, cfg.mission.swarm_size = positions, len(positions)
        cfg.mission.superiors = {i: (-1 if i == 0 else 0) for i in positions}
    return execute(cfg, tmp_path, choices, list(overrides)), tmp_path


def test_formation_escapes_the_cup_and_reaches_the_goal_without_touching_an_obstacle(tmp_path):
    swarm = {0: [3.0, 0.0], **{1 + k: [-3.0 * (k // 4), 3.0 * (k % 4) - 4.5] for k in range(8)}}
    manifest, d = fly(tmp_path, swarm, "mission.max_sim_time_s=240")
    assert manifest["status"] == "ok", manifest["reason"]
    ground = table(d, "ground", "events")
    assert (ground["name"] == "goal_reached").sum() == 1
    events = pd.concat([table(d, f"drone_{i}", "events") for i in swarm])
    assert not (events["kind"] == "collision").any(), events[events["kind"] == "collision"]
    goal = PARAMS["goal_ne_m"]
    reach = 7.5 + float(PARAMS["slot_tolerance_m"]) + float(PARAMS["goal_radius_m"])   # widest offset 7.5 m
    for i in swarm:
        st = table(d, f"drone_{i}", "state")
        done = st[st["stage"] == 3].iloc[-1]                       # where EXECUTION ended
        assert math.hypot(done["true_n"] - goal[0], done["true_e"] - goal[1]) < reach, i
    leader = table(d, "drone_0", "state")
    assert leader["true_n"].max() > 39.0          # it left the cup over the end of its west wall
