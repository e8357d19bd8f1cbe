"""Chevron (RQ5 case 3): followers hold their V slots around the leader's reported state."""

import json
import math

import numpy as np
import pandas as pd
import pytest
from omegaconf import open_dict

from swarmbox.algorithms.chevron import FOLLOW, RETURN, circle_angle, circle_point
from swarmbox.run.runner import execute
from tests.conftest import compose_config, table

N = 7
SMALL = ["algo.params.radius_m=20", "algo.params.speed_m_s=2", "algo.params.start_s=8",
         "algo.params.ramp_s=4"]


def chevron(n: int, spacing_m: float = 3.0) -> dict[int, list[float]]:
    out = {0: [0.0, 0.0]}
    for i in range(1, n):
        k = (i + 1) // 2
        out[i] = [-spacing_m * k, -spacing_m * k if i % 2 else spacing_m * k]
    return out


@pytest.fixture(scope="module")
def flight(tmp_path_factory):
    """Seven drones of the 3 m chevron fly one 20 m circle (about 70 s of formation flight)."""
    cfg, choices = compose_config(["algo=chevron", "mission=chevron", "run.progress=false", *SMALL])
    with open_dict(cfg):
        cfg.mission.initial_positions = chevron(N)
        cfg.mission.superiors = {i: (-1 if i == 0 else 0) for i in range(N)}
        cfg.mission.swarm_size = N
        cfg.mission.max_sim_time_s = 120.0
    d = tmp_path_factory.mktemp("chevron")
    return execute(cfg, d, choices, []), d


def test_circle_profile_is_continuous_and_closes():
    omega, total, ramp = 0.2, 2 * math.pi, 4.0
    ts = np.linspace(0, total / omega + ramp, 2001)
    theta = np.array([circle_angle(t, omega, total, ramp)[0] for t in ts])
    rate = np.array([circle_angle(t, omega, total, ramp)[1] for t in ts])
    assert theta[0] == 0 and theta[-1] == pytest.approx(total) and rate[-1] == pytest.approx(0, abs=1e-9)
    assert np.all(np.diff(theta) >= -1e-12) and rate.max() == pytest.approx(omega)
    assert np.abs(np.diff(rate)).max() <= omega / ramp * (ts[1] - ts[0]) + 1e-9   # bounded acceleration
    p = {"radius_m": 10, "speed_m_s": 2, "ramp_s": ramp, "start_s": 0, "laps": 1}
    assert circle_point(p, 1e6, (0.0, 0.0))[0] == RETURN
    phase, pos, _, _ = circle_point(p, 10.0, (0.0, 0.0))
    assert phase == FOLLOW and math.hypot(pos[0], pos[1] + 10) == pytest.approx(10)


def formation_errors(d) -> pd.DataFrame:
    """Each follower's true distance to its slot around the leader's true position and heading."""
    lead = table(d, "drone_0", "state").set_index("tick")
    homes = chevron(N)
    cols = {}
    for i in range(1, N):
        st = table(d, f"drone_{i}", "state").set_index("tick")
        ticks = st.index.intersection(lead.index)
        lo, fo = lead.loc[ticks], st.loc[ticks]
        on, oe = homes[i]
        c, s = np.cos(lo["yaw_rad"]), np.sin(lo["yaw_rad"])
        cols[i] = np.hypot(fo["true_n"] - (lo["true_n"] + c * on - s * oe),
                           fo["true_e"] - (lo["true_e"] + s * on + c * oe))
    return pd.DataFrame(cols)


def test_formation_error_settles_on_the_circle(flight):
    manifest, d = flight
    assert manifest["status"] == "ok", manifest["reason"]
    exec_tick = table(d, "ground", "stages").query("name == 'EXECUTION'")["tick"].iloc[0]
    lap_s = 2 * math.pi * 20 / 2 + 4
    follow = formation_errors(d).loc[lambda f: (f.index > exec_tick + 8 * 40)
                                     & (f.index < exec_tick + (8 + lap_s) * 40)]
    assert len(follow) > 40 * 30
    cruise = follow.loc[(follow.index > exec_tick + (8 + 4 + 3) * 40)
                        & (follow.index < exec_tick + (8 + lap_s - 4) * 40)]
    assert cruise.to_numpy().max() < 0.25 and cruise.to_numpy().mean() < 0.1   # settled on the circle
    assert follow.to_numpy().max() < 1.0          # speeding up and slowing down included
    # The leader really flew the 20 m circle (the formation turned through 360 degrees).
    lead = table(d, "drone_0", "state")
    assert 38.0 < lead["true_n"].max() - lead["true_n"].min() < 42.0
    # Each follower's own marker agrees: small errors once the circle is under way.
    for i in range(1, N):
        ev = table(d, f"drone_{i}", "events")
        errs = [json.loads(x)["error_m"] for x in ev[ev["name"] == "formation_error"]["data"]]
        assert len(errs) > 30 and np.median(errs) < 0.2


def test_ground_commands_only_the_leader_and_everyone_lands_home(flight):
    _, d = flight
    sent = table(d, "ground", "messages").query("kind == 'send' and type == 'task'")
    assert set(sent["dst"]) == {0}
    relayed = table(d, "drone_0", "messages").query("kind == 'send' and type == 'task'")
    assert set(relayed["dst"]) == set(range(1, N))
    for i, (hn, he) in chevron(N).items():
        last = table(d, f"drone_{i}", "state").iloc[-1]
        assert last["landed"] and math.hypot(last["true_n"] - hn, last["true_e"] - he) < 1.5
        assert not (table(d, f"drone_{i}", "events")["kind"] == "collision").any()
