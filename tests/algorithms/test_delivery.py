"""The RQ4 delivery benchmark: planning rules, datasets, configs, and flown missions.

Flown missions use a reduced budget (15 packages in a 100 m x 100 m square) so that the nine
algorithms x two seeds fly in well under a minute.
"""

from __future__ import annotations

import json
import math
import random
from collections import Counter
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from hydra import compose, initialize_config_dir
from hydra.core.global_hydra import GlobalHydra
from hydra.utils import get_class

from swarmbox.algorithms.delivery import DeliveryDrone, DeliveryGround
from swarmbox.algorithms.delivery_plan import (
    ASSIGNS,
    SORTS,
    Package,
    assign_packages,
    decode_ids,
    decode_packages,
    encode_ids,
    encode_packages,
    paper_points,
    random_points,
    sort_packages,
    strategy_of,
)
from swarmbox.run.build import rng_for
from swarmbox.run.mission import load
from tests.conftest import CONF, ROOT, compose_config, run_config, table

ALGOS = [f"delivery_{s}_{a}" for s in SORTS for a in ASSIGNS]
SMALL = ("mission=delivery", "mission.generator.count=15", "mission.generator.half_size_m=50")
SEEDS = (0, 1)
N_SMALL = 15


# -- datasets ------------------------------------------------------------------------------------

def test_paper_dataset_1_matches_the_published_points():
    points = paper_points(dataset=1)
    assert len(points) == 100 and list(points) == list(range(100))
    assert points[0] == [-66.0, 45.0] and points[1] == [95.0, -84.0]
    assert all(-100 <= c <= 100 and c == int(c) for p in points.values() for c in p)


def test_paper_datasets_ignore_global_random_state_and_offset_shifts_k():
    random.seed(12345)
    a = paper_points(np.random.default_rng(7), dataset=0, dataset_offset=1)
    random.seed(999)
    b = paper_points(None, dataset=1)
    assert a == b
    assert paper_points(dataset=2) != b
    longer = paper_points(dataset=1, count=101)
    assert len(longer) == 101 and {k: longer[k] for k in range(100)} == b   # a prefix of the same stream


def test_random_points_are_seeded_and_inside_the_square():
    a = random_points(np.random.default_rng(3), count=200, half_size_m=40.0)
    b = random_points(np.random.default_rng(3), count=200, half_size_m=40.0)
    c = random_points(np.random.default_rng(4), count=200, half_size_m=40.0)
    assert a == b and a != c
    coords = np.array(list(a.values()))
    assert coords.shape == (200, 2) and np.abs(coords).max() <= 40.0
    assert coords.std(axis=0) == pytest.approx([40 / math.sqrt(3)] * 2, rel=0.15)   # uniform spread


def test_paper_preset_maps_seed_to_dataset_seed_plus_one():
    cfg, _ = compose_config(["+experiment=rq4_delivery", "seed=4"])
    mission = load(cfg, rng_for(4, "dataset"))
    assert mission.swarm_size == 5
    assert mission.initial_positions == {i: (5.0 * i, 0.0, 0.0) for i in range(5)}
    expected = paper_points(dataset=5)
    assert {k: list(v) for k, v in mission.values.items()} == expected


# -- planning ------------------------------------------------------------------------------------

PKGS = [Package(0, 10, 0), Package(1, -5, 0), Package(2, 0, 3), Package(3, 0, -3), Package(4, 3, 4),
        Package(5, -4, -3)]


def test_sorting_rules():
    ids = lambda ps: [p.id for p in ps]  # noqa: E731
    assert ids(sort_packages(PKGS[::-1], "none")) == [0, 1, 2, 3, 4, 5]
    # atan2(E, N): (-4,-3) -2.50, (0,-3) -pi/2, (10,0) 0, (3,4) 0.93, (0,3) pi/2, (-5,0) pi
    assert ids(sort_packages(PKGS, "azimuth")) == [5, 3, 0, 4, 2, 1]
    # distances 10, 5, 3, 3, 5, 5: ties keep id order
    assert ids(sort_packages(PKGS, "distance")) == [2, 3, 1, 4, 5, 0]


@pytest.mark.parametrize("count, size", [(100, 5), (10, 5), (7, 3), (3, 5), (0, 2)])
def test_assignment_covers_every_package_once_and_balances(count, size):
    ordered = [Package(i, float(i), 0.0) for i in range(count)]
    drones = [10 + d for d in range(size)]
    for method in ("block", "rr"):
        plan = assign_packages(ordered, drones, method)
        assert list(plan) == drones
        flat = [p.id for d in drones for p in plan[d]]
        assert sorted(flat) == list(range(count))
        sizes = [len(plan[d]) for d in drones]
        assert max(sizes) - min(sizes) <= 1
        for d in drones:   # each drone keeps the sorted order
            assert [p.id for p in plan[d]] == sorted(p.id for p in plan[d])
    block = assign_packages(ordered, drones, "block")
    assert [p.id for d in drones for p in block[d]] == list(range(count))   # contiguous blocks
    rr = assign_packages(ordered, drones, "rr")
    assert all(p.id % size == i for i, d in enumerate(drones) for p in rr[d])


def test_block_on_the_paper_size_is_twenty_consecutive_packages_each():
    ordered = [Package(i, 0.0, 0.0) for i in range(100)]
    plan = assign_packages(ordered, [0, 1, 2, 3, 4], "block")
    assert all([p.id for p in plan[d]] == list(range(20 * d, 20 * d + 20)) for d in range(5))


def test_unknown_strategy_names_the_allowed_values():
    assert strategy_of({"sort": "distance", "assign": "rr"}).preplanned
    assert not strategy_of({"sort": "none", "assign": "dynamic"}).preplanned
    with pytest.raises(ValueError, match="unknown sort 'spiral'; allowed values: none, azimuth, distance"):
        strategy_of({"sort": "spiral", "assign": "rr"})
    with pytest.raises(ValueError, match="unknown assign 'auction'; allowed values: block, rr, dynamic"):
        strategy_of({"sort": "none", "assign": "auction"})
    with pytest.raises(ValueError, match="not a pre-assignment method"):
        assign_packages(PKGS, [0], "dynamic")


def test_message_codecs_round_trip():
    pkgs = [Package(3, -66.0, 45.0), Package(17, 0.1, -99.9)]
    assert decode_packages(encode_packages(pkgs)) == pkgs
    assert decode_packages("") == [] and decode_ids("") == []
    assert decode_ids(encode_ids([5, 0, 12])) == [5, 0, 12]


# -- configs -------------------------------------------------------------------------------------

@pytest.mark.parametrize("algo", ALGOS)
def test_every_algorithm_config_composes_with_its_strategy(algo):
    cfg, choices = compose_config([f"algo={algo}", "mission=delivery"])
    _, sort, assign = algo.split("_")
    assert choices["algo"] == algo and cfg.algo.name == algo
    assert strategy_of(cfg.algo.params) == (sort, assign)
    assert get_class(cfg.algo.drone._target_) is DeliveryDrone
    assert get_class(cfg.algo.ground._target_) is DeliveryGround
    assert {m.name for m in cfg.algo.metrics} >= {"delivery_wait_s"}


def test_every_delivery_config_file_is_one_of_the_nine():
    files = {p.stem for p in (CONF / "algo").glob("delivery*.yaml")}
    assert files == set(ALGOS)   # their shared base, conf/delivery_base.yaml, is no algo= option


def test_experiment_preset_sweeps_the_nine_algorithms_over_twenty_datasets():
    cfg, _ = compose_config(["+experiment=rq4_delivery"])
    assert cfg.mission.name == "delivery_paper"
    GlobalHydra.instance().clear()
    with initialize_config_dir(config_dir=str(CONF), version_base="1.3"):
        full = compose("config", overrides=["+experiment=rq4_delivery"], return_hydra_config=True)
    params = full.hydra.sweeper.params
    assert sorted(params.algo.split(",")) == sorted(ALGOS)
    assert params.seed == "range(20)"
    assert full.hydra.launcher._target_.endswith("SwarmBoxLauncher")


@pytest.mark.parametrize("mission, drones, packages", [("delivery16", 16, 101), ("delivery36", 36, 180)])
def test_scale_missions_use_grids_and_paper_dataset_one(mission, drones, packages):
    cfg, _ = compose_config(["algo=delivery_distance_dynamic", f"mission={mission}"])
    m = load(cfg, rng_for(0, "dataset"))
    side = int(math.sqrt(drones))
    assert m.swarm_size == drones
    assert m.initial_positions[side + 1] == (5.0, 5.0, 0.0)
    assert m.initial_positions[drones - 1] == (5.0 * (side - 1), 5.0 * (side - 1), 0.0)
    assert {k: list(v) for k, v in m.values.items()} == paper_points(dataset=1, count=packages)
    top_alt_m = 10.0 + 2.0 * (drones - 1)   # the last drone lands from here at 0.7 m/s (+2 s disarm)
    assert cfg.run.timeouts_s.LANDING > top_alt_m / 0.7 + 2.0


# -- flown missions ------------------------------------------------------------------------------

def markers(run_dir: Path, node: str, name: str) -> pd.DataFrame:
    ev = table(run_dir, node, "events")
    rows = ev[(ev["kind"] == "marker") & (ev["name"] == name)].sort_values(["t_s", "tick"], kind="stable")
    return rows.assign(fields=rows["data"].map(json.loads))


def arrivals(run_dir: Path, n_drones: int = 5) -> dict[int, list[int]]:
    """Package ids each drone reached, in the order it reached them."""
    return {d: [f["package"] for f in markers(run_dir, f"drone_{d}", "arrived")["fields"]]
            for d in range(n_drones)}


def assigned(run_dir: Path) -> dict[int, list[int]]:
    """Package ids the ground assigned to each drone, in assignment order."""
    out: dict[int, list[int]] = {}
    for f in markers(run_dir, "ground", "assigned")["fields"]:
        out.setdefault(f["drone"], []).extend(f["packages"])
    return out


@pytest.fixture(scope="module")
def small_sweep(tmp_path_factory) -> dict[tuple[str, int], tuple[dict, Path]]:
    """Every algorithm x seed on the small mission (run once for the module)."""
    root = tmp_path_factory.mktemp("delivery")
    out = {}
    for algo in ALGOS:
        for seed in SEEDS:
            run_dir = root / f"{algo}_{seed}"
            out[(algo, seed)] = run_config(run_dir, [f"algo={algo}", f"seed={seed}", *SMALL]), run_dir
    return out


@pytest.mark.slow   # flies the nine algorithms x seeds (module fixture)
@pytest.mark.parametrize("algo", ALGOS)
def test_every_package_is_delivered_exactly_once(small_sweep, algo):
    for seed in SEEDS:
        manifest, d = small_sweep[(algo, seed)]
        assert manifest["status"] == "ok", manifest["reason"]
        flown = Counter(p for ps in arrivals(d).values() for p in ps)
        assert flown == Counter(range(N_SMALL))
        delivered = markers(d, "ground", "delivered")["fields"]
        assert sorted(f["package"] for f in delivered) == list(range(N_SMALL))
        by_drone = {f["package"]: f["drone"] for f in delivered}
        assert all(by_drone[p] == drone for drone, ps in arrivals(d).items() for p in ps)
        assert markers(d, "ground", "duplicate").empty
        stages = list(table(d, "ground", "stages")["name"])
        assert stages[-2:] == ["LANDING", "TERMINATION"]


@pytest.mark.slow   # flies the nine algorithms x seeds (module fixture)
@pytest.mark.parametrize("algo", ALGOS)
def test_drones_fly_their_packages_in_the_sorted_assigned_order(small_sweep, algo):
    _, sort, assign = algo.split("_")
    for seed in SEEDS:
        _, d = small_sweep[(algo, seed)]
        plan = markers(d, "ground", "plan")["fields"].iloc[0]
        order = plan["order"]
        keys = [sort_key(sort, p, *paper_like_points(d)[p]) for p in order]
        assert keys == sorted(keys)
        got = assigned(d)
        assert arrivals(d) == {drone: got.get(drone, []) for drone in range(5)}
        if assign == "dynamic":   # handed out one at a time, in the global sorted order
            handed = [f["packages"][0] for f in markers(d, "ground", "assigned")["fields"]]
            assert handed == order
        else:
            expected = assign_packages([Package(p, 0.0, 0.0) for p in order], list(range(5)), assign)
            assert got == {drone: [p.id for p in ps] for drone, ps in expected.items()}


def sort_key(rule: str, pid: int, north_m: float, east_m: float) -> float:
    keys = {"none": pid, "azimuth": math.atan2(east_m, north_m), "distance": math.hypot(north_m, east_m)}
    return keys[rule]


def paper_like_points(run_dir: Path) -> dict[int, tuple[float, float]]:
    """The run's packages, read back from the drones' arrival markers."""
    out = {}
    for drone in range(5):
        for f in markers(run_dir, f"drone_{drone}", "arrived")["fields"]:
            out[f["package"]] = (f["north_m"], f["east_m"])
    return out


@pytest.mark.slow   # flies the nine algorithms x seeds (module fixture)
def test_each_drone_completes_once_back_home_after_its_last_delivery(small_sweep):
    _, d = small_sweep[("delivery_distance_block", 0)]
    for drone in range(5):
        ev = table(d, f"drone_{drone}", "events")
        done = ev[(ev["kind"] == "progress") & (ev["name"] == "exec_complete")]
        last_return = markers(d, f"drone_{drone}", "returned")["t_s"].max()
        assert len(done) == 1 and done["t_s"].iloc[0] == pytest.approx(last_return)


@pytest.mark.slow   # flies the nine algorithms x seeds (module fixture)
def test_cruise_altitudes_separate_the_drones(small_sweep):
    _, d = small_sweep[("delivery_none_rr", 0)]
    for drone in range(5):
        st = table(d, f"drone_{drone}", "state")
        cruise = st[(st["stage"] == 3) & (st["true_d"] < -5)]
        assert cruise["true_d"].median() == pytest.approx(-10.0 - 2.0 * drone, abs=0.3)


@pytest.mark.slow   # flies the nine algorithms x seeds (module fixture)
def test_distance_sort_shortens_the_average_wait_of_dynamic_assignment(small_sweep):
    """Shortest trips first lowers the mean delivery wait (shortest-processing-time rule)."""
    for seed in SEEDS:
        waits = {algo: markers(small_sweep[(algo, seed)][1], "ground", "delivered")["t_s"].mean()
                 for algo in ("delivery_none_dynamic", "delivery_distance_dynamic")}
        assert waits["delivery_distance_dynamic"] < 0.95 * waits["delivery_none_dynamic"]


@pytest.mark.slow   # flies the nine algorithms x seeds (module fixture)
def test_same_seed_same_logs_other_seed_other_dataset(small_sweep, tmp_path):
    manifest, again = run_config(tmp_path / "again", ["algo=delivery_azimuth_dynamic", "seed=1", *SMALL]), \
        tmp_path / "again"
    _, first = small_sweep[("delivery_azimuth_dynamic", 1)]
    _, other = small_sweep[("delivery_azimuth_dynamic", 0)]
    assert manifest["status"] == "ok"
    for node in ("ground", "drone_2"):
        pd.testing.assert_frame_equal(table(first, node, "events"), table(again, node, "events"))
    pd.testing.assert_frame_equal(table(first, "drone_3", "state"), table(again, "drone_3", "state"))
    assert paper_like_points(first) != paper_like_points(other)


@pytest.mark.parametrize("algo", ["delivery_distance_dynamic", "delivery_none_block"])
def test_lossy_network_still_delivers_every_package_exactly_once(tmp_path, algo):
    manifest = run_config(tmp_path / "r", [f"algo={algo}", "network.loss_prob=0.2", *SMALL])
    assert manifest["status"] == "ok", manifest["reason"]
    d = tmp_path / "r"
    assert Counter(p for ps in arrivals(d).values() for p in ps) == Counter(range(N_SMALL))
    assert sorted(f["package"] for f in markers(d, "ground", "delivered")["fields"]) == list(range(N_SMALL))
    drops = table(d, "net", "messages")
    assert len(drops) > 0
    if algo.endswith("dynamic"):   # some assignment or its ack was lost, and the command re-sent
        assert drops["type"].isin(["task", "ack"]).any()
        sent = table(d, "ground", "messages").query("kind == 'send' and type == 'task'")
        assert len(sent) > len(markers(d, "ground", "assigned")) + 5


def test_fewer_packages_than_drones_every_drone_still_completes(tmp_path):
    manifest = run_config(tmp_path / "r", ["algo=delivery_distance_block", "mission=delivery",
                                           "mission.generator.count=3", "mission.generator.half_size_m=20"])
    assert manifest["status"] == "ok", manifest["reason"]
    d = tmp_path / "r"
    assert sum(len(ps) for ps in arrivals(d).values()) == 3
    for drone in range(5):
        ev = table(d, f"drone_{drone}", "events")
        assert (ev["name"] == "exec_complete").sum() == 1


def test_unknown_sort_fails_the_run_with_the_allowed_values(tmp_path):
    manifest = run_config(tmp_path / "r", ["algo=delivery_distance_dynamic", "algo.params.sort=spiral",
                                           *SMALL])
    assert manifest["status"] == "failed"
    assert "unknown sort 'spiral'; allowed values: none, azimuth, distance" in manifest["reason"]


def test_ci_baseline_covers_every_algorithm_and_its_tolerances_load():
    from swarmbox.analysis.compare import load_config, load_summary

    base = ROOT / "results" / "baselines" / "rq4_ci"
    summary = load_summary(base / "summary.csv")
    assert set(summary["algo"]) == set(ALGOS)
    counts = summary[summary["metric"] == "delivery_wait_s_count"].set_index("algo")["value"]
    assert (counts == N_SMALL).all()
    config = load_config(base / "tolerances.yaml")
    assert config.tolerance("real_time_factor", "higher").ignore
    for metric in ("delivery_wait_s_count", "mission_duration_s"):   # deterministic: float noise only
        tol = config.tolerance(metric, "lower")
        assert tol.rtol <= 1e-9 and tol.atol <= 1e-9 and not tol.ignore
