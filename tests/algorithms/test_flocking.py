"""Optimized flocking: the model's terms on hand-made cases, and a flock in the walled arena."""

import json

import numpy as np
import pandas as pd
import pytest
from omegaconf import OmegaConf, open_dict
from scipy.spatial import cKDTree

from swarmbox.algorithms.flocking import braking_curve, flocking_velocities, nearest_surface, order_parameter
from swarmbox.run.runner import execute
from tests.conftest import CONF, compose_config, table

PARAMS = OmegaConf.to_container(OmegaConf.load(CONF / "algo" / "flocking.yaml").params)
WALL = {"kind": "segment", "a": [60.0, -60.0], "b": [60.0, 60.0], "radius_m": 0.5}   # north wall
NORTH = np.array([[1.0, 0.0]])


def test_braking_curve_is_zero_then_linear_then_square_root():
    a, p = 3.0, 2.0
    assert braking_curve(-1.0, a, p) == 0.0 and braking_curve(0.0, a, p) == 0.0
    assert braking_curve(0.5, a, p) == pytest.approx(1.0)                       # r·p while r·p < a/p
    assert braking_curve(2.0, a, p) == pytest.approx(np.sqrt(2 * a * 2.0 - (a / p) ** 2))
    r_switch = a / p ** 2                                                        # continuous at the switch
    assert braking_curve(r_switch - 1e-9, a, p) == pytest.approx(braking_curve(r_switch + 1e-9, a, p))


def test_nearest_surface_of_each_obstacle_kind():
    pts = np.array([[0.0, 5.0]])
    _, d = nearest_surface({"kind": "segment", "a": [-1, 0], "b": [1, 0], "radius_m": 0.5}, pts)
    assert d[0] == pytest.approx(4.5)
    _, d = nearest_surface({"kind": "circle", "center": [0, 0], "radius_m": 2.0}, pts)
    assert d[0] == pytest.approx(3.0)
    surface, d = nearest_surface({"kind": "box", "center": [0, 0], "size": [2, 4]}, pts)
    assert d[0] == pytest.approx(3.0) and surface[0] == pytest.approx([0.0, 2.0])


def one_drone(n_m: float, vel: list[float]) -> np.ndarray:
    return flocking_velocities(np.array([[n_m, 0.0]]), np.array([vel]), NORTH, [WALL], PARAMS)[0]


def test_wall_brakes_a_drone_flying_at_it_and_leaves_a_distant_one_alone():
    assert one_drone(0.0, [4.0, 0.0]) == pytest.approx([PARAMS["v_flock"], 0.0])     # 60 m away: no effect
    # 9.5 m from the wall at 4 m/s: |v_s - v_i| = 17.6 m/s exceeds D(9.2) = 7.4 m/s, so the shill agent
    # turns the drone back along the normal (the reference's v_i - v_s with an outward shill velocity
    # would leave it flying at the wall at 1.8 m/s).
    near = one_drone(50.0, [4.0, 0.0])
    assert near[0] < 0.0 and abs(near[1]) < 1e-9
    along = flocking_velocities(np.array([[20.0, 0.0]]), np.array([[0.0, 4.0]]), NORTH, [WALL], PARAMS)[0]
    assert along == pytest.approx([0.0, PARAMS["v_flock"]])       # 39.5 m away, flying along it


def test_repulsion_pushes_close_drones_apart_and_alignment_matches_velocities():
    pos = np.array([[0.0, 0.0], [0.0, 2.0]])
    heading = np.array([[1.0, 0.0], [1.0, 0.0]])
    still = flocking_velocities(pos, np.array([[1e-3, 0.0], [1e-3, 0.0]]), heading, [], PARAMS)
    push = PARAMS["p_rep"] * (PARAMS["r0_rep"] - 2.0)
    assert still[0] == pytest.approx([PARAMS["v_flock"], -push]) and still[1][1] == pytest.approx(push)
    far = np.array([[0.0, 0.0], [0.0, 30.0]])                        # beyond r0_rep: alignment only
    crossing = flocking_velocities(far, np.array([[4.0, 0.0], [0.0, 4.0]]), heading, [], PARAMS)
    gap = np.hypot(4.0, 4.0) - PARAMS["v_frict"]                      # |v_ij| beyond the tolerated v_frict
    assert crossing[0] == pytest.approx([4.0, 0.0] - PARAMS["C_frict"] * gap * np.array([1, -1]) / np.sqrt(2))
    assert order_parameter(crossing) > order_parameter(np.array([[4.0, 0.0], [0.0, 4.0]]))


def fly(tmp_path, positions: dict[int, list[float]], *overrides: str) -> tuple[dict, object]:
    """Run the flocking mission with the drones at ``positions``; returns (manifest, run dir)."""
    cfg, choices = compose_config(["algo=flocking", "mission=flocking", "run.progress=false", *overrides])
    with open_dict(cfg):
        cfg.mission.initial_positions, cfg.mission.swarm_size = positions, len(positions)
    return execute(cfg, tmp_path, choices, list(overrides)), tmp_path


def horizontal_order(states: pd.DataFrame) -> pd.Series:
    by_tick = states.groupby("tick")
    total = np.hypot(by_tick["vel_n"].sum(), by_tick["vel_e"].sum())
    return total / by_tick.apply(lambda s: np.hypot(s["vel_n"], s["vel_e"]).sum())


def test_flock_orders_itself_without_collisions_or_leaving_the_arena(tmp_path):
    grid = {i: [5.0 * (i % 4) - 7.5, 5.0 * (i // 4) - 7.5] for i in range(16)}
    manifest, d = fly(tmp_path, grid, "algo.params.flock_s=40", "mission.max_sim_time_s=90")
    assert manifest["status"] == "ok", manifest["reason"]
    ev = table(d, "ground", "events")
    start = ev[ev["name"] == "flock_start"]["t_s"].iloc[0]
    states = pd.concat([table(d, f"drone_{i}", "state") for i in range(16)])
    flying = states[(states["t_s"] > start + 10) & (states["t_s"] < start + 40)]
    order = horizontal_order(flying)
    assert order.mean() > 0.95 and order.min() > 0.8, (order.mean(), order.min())
    assert np.hypot(flying["vel_n"], flying["vel_e"]).mean() > 3.0                # self-propelled
    events = pd.concat([table(d, f"drone_{i}", "events") for i in range(16)])
    assert not (events["kind"] == "collision").any()
    wall = 60.0 - 0.5 - 0.3                           # wall line - wall radius - drone radius
    assert states["true_n"].abs().max() < wall and states["true_e"].abs().max() < wall
    pts = [g[["true_n", "true_e"]].to_numpy() for _, g in flying.groupby("tick")]
    seps = [cKDTree(p).query(p, k=2)[0][:, 1].min() for p in pts]
    assert min(seps) > 1.0
    marks = [json.loads(x) for x in ev[ev["name"] == "flock"]["data"]]
    assert min(m["wall_min_m"] for m in marks) > 5.0 and marks[-1]["order"] > 0.9
