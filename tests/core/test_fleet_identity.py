"""The fleet core (``run.core=fleet``) writes the object core's logs, table for table.

Each case flies the same config and seed through both cores and compares every Parquet table of
the run exactly (and run.json's outcome), so any difference in a stage, a message, a drop, a clock
reading or a setpoint fails it. What the fleet core does not cover is refused up front.
"""

from __future__ import annotations

import json
import re
from pathlib import Path

import pandas as pd
import pytest
from omegaconf import OmegaConf, open_dict
from pandas.testing import assert_frame_equal

from swarmbox.bench.hover import grid
from swarmbox.run.build import ConfigError
from swarmbox.run.runner import execute
from tests.conftest import compose_config

#: run.json entries that must agree (wall times and the config's own run.core differ by design)
_OUTCOME = ("status", "reason", "sim_time_s", "ticks", "safety", "tasks_refused", "problems", "n_drones")


def _fly(run_dir: Path, core: str, overrides: list[str], homes: dict[int, list[float]] | None) -> dict:
    cfg, choices = compose_config([*overrides, f"run.core={core}", "run.progress=false"])
    if homes is not None:
        with open_dict(cfg):
            cfg.mission.initial_positions = homes
            cfg.mission.swarm_size = len(homes)
    execute(cfg, run_dir, choices, overrides)
    return json.loads((run_dir / "run.json").read_text())


def _tables(run_dir: Path) -> list[Path]:
    return sorted(p.relative_to(run_dir) for p in (run_dir / "logs").rglob("*.parquet"))


def assert_same_run(tmp_path: Path, overrides: list[str], homes: dict[int, list[float]] | None = None,
                    algos: tuple[str, str] | None = None) -> dict:
    """Both cores fly ``overrides``; every table and the outcome must be equal. Returns run.json.
    ``algos``: the object core's and the fleet core's algorithm override (a per-drone algorithm and
    its batch port), added to ``overrides``."""
    obj_algo, fleet_algo = [algos[0]] if algos else [], [algos[1]] if algos else []
    obj = _fly(tmp_path / "object", "object", [*obj_algo, *overrides], homes)
    fleet = _fly(tmp_path / "fleet", "fleet", [*fleet_algo, *overrides], homes)
    assert {k: obj.get(k) for k in _OUTCOME} == {k: fleet.get(k) for k in _OUTCOME}
    files = _tables(tmp_path / "object")
    assert files == _tables(tmp_path / "fleet")
    for f in files:   # in the order the logs are written: per node, as the rows happened
        assert_frame_equal(pd.read_parquet(tmp_path / "object" / f), pd.read_parquet(tmp_path / "fleet" / f),
                           check_exact=True, obj=str(f))
    return obj


HOVER = ["algo=hover", "mission=hover", "algo.params.hover_s=2"]


@pytest.mark.parametrize("seed", [0, 1, 2])
@pytest.mark.parametrize("n", [1, 5, 36])
def test_hover_logs_equal(tmp_path, n, seed):
    manifest = assert_same_run(tmp_path, [*HOVER, f"seed={seed}"], grid(n))
    assert manifest["status"] == "ok", manifest["reason"]


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_formation_logs_equal(tmp_path, seed):
    """Formation: the ground streams a task to every drone every tick (message objects beside the
    batch traffic)."""
    manifest = assert_same_run(tmp_path, ["algo=formation", f"seed={seed}"])
    assert manifest["status"] == "ok", manifest["reason"]


@pytest.mark.parametrize("seed", [0, 1, 2])
@pytest.mark.parametrize("network", [
    ["network=wifi"],                                          # latency, jitter and loss
    ["network.loss_prob=0.3"],                                 # loss on a constant-delay network
    ["network.latency_ms=60"],                                 # more than two ticks in flight
    ["network.jitter_ms=80", "network.latency_ms=10"],         # heavy reordering
])
def test_impaired_network_logs_equal(tmp_path, network, seed):
    assert_same_run(tmp_path, [*HOVER, *network, f"seed={seed}"], grid(9))


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_formation_on_a_lossy_jittery_network_logs_equal(tmp_path, seed):
    assert_same_run(tmp_path, ["algo=formation", "network=wifi", "network.loss_prob=0.1", f"seed={seed}"])


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_liveness_logs_equal(tmp_path, seed):
    """Short liveness limits on a lossy network: drones are lost and rejoin at the ground, and lose
    their superior and abort (failsafe events, the ground's head-count and min_alive)."""
    assert_same_run(tmp_path, [*HOVER, "network.loss_prob=0.6", "run.lost_inferior_ticks=2",
                               "run.lost_superior_ticks=4", f"seed={seed}"], grid(6))
    events = pd.read_parquet(tmp_path / "fleet" / "logs" / "ground" / "events.parquet")
    assert {"inferior_lost", "inferior_rejoined"} <= set(events["name"])


def test_coarse_state_rows_and_node_clocks_logs_equal(tmp_path):
    clocks = "run.clocks={drone_2: {offset_s: 0.5, drift_ppm: 100}, ground: {offset_s: -0.1}}"
    assert_same_run(tmp_path, [*HOVER, "run.state_every_ticks=4", "network=wifi", clocks], grid(5))


def test_proximity_alerts_logs_equal(tmp_path):
    """Drones launched 1.5 m apart: the ground alerts the pairs (ProxAlerts, episodes) from the start."""
    homes = {i: [1.5 * i, 0.0] for i in range(4)}
    assert_same_run(tmp_path, [*HOVER, "network=wifi"], homes)
    events = pd.read_parquet(tmp_path / "fleet" / "logs" / "ground" / "events.parquet")
    assert "prox_start" in set(events["name"])


@pytest.mark.parametrize(("override", "what"), [
    ("run.runtime=processes", "run.runtime=processes"),
])
def test_what_the_fleet_core_does_not_cover_is_refused_before_anything_is_written(tmp_path, override, what):
    cfg, choices = compose_config([*HOVER, override, "run.core=fleet", "run.progress=false"])
    refused = rf"run.core=fleet does not cover {re.escape(what)}.* yet; use run.core=object"
    with pytest.raises(ConfigError, match=refused):
        execute(cfg, tmp_path / "run", choices, [override])
    assert not (tmp_path / "run").exists()


def test_an_unknown_core_is_refused(tmp_path):
    cfg, choices = compose_config([*HOVER, "run.core=arrays", "run.progress=false"])
    with pytest.raises(ConfigError, match="run.core must be one of object, fleet, got 'arrays'"):
        execute(cfg, tmp_path / "run", choices, [])
    assert not (tmp_path / "run").exists()


#: The RQ4 CI preset (conf/experiment/rq4_delivery_ci.yaml): its mission, state interval and nine algorithms
_RQ4_CI = OmegaConf.load(Path(__file__).parents[2] / "swarmbox/conf/experiment/rq4_delivery_ci.yaml")
RQ4_ALGOS = str(_RQ4_CI.hydra.sweeper.params.algo).split(",")
_RQ4_OVERRIDES = ["mission=delivery", f"mission.generator.count={_RQ4_CI.mission.generator.count}",
                  f"mission.generator.half_size_m={_RQ4_CI.mission.generator.half_size_m}",
                  f"run.state_every_ticks={_RQ4_CI.run.state_every_ticks}"]


def _rq4_ci_run(tmp_path: Path, algo: str, seed: int) -> None:
    """One run of the RQ4 CI preset on both cores: reliable tasks (acknowledged, re-sent), Report
    texts, five drones."""
    manifest = assert_same_run(tmp_path, [f"algo={algo}", *_RQ4_OVERRIDES, f"seed={seed}"])
    assert manifest["status"] == "ok", manifest["reason"]


@pytest.mark.parametrize("seed", [0, 1])
@pytest.mark.parametrize("algo", RQ4_ALGOS)
def test_rq4_ci_runs_logs_equal(tmp_path, algo, seed):
    _rq4_ci_run(tmp_path, algo, seed)


@pytest.mark.slow
@pytest.mark.seeds
@pytest.mark.parametrize("seed", range(2, 20))
@pytest.mark.parametrize("algo", RQ4_ALGOS)
def test_rq4_ci_runs_logs_equal_on_twenty_seeds(tmp_path, algo, seed):
    """Seeds 2-19 of the nine algorithms: with the two above, the 20 seeds of the RQ4 study."""
    _rq4_ci_run(tmp_path, algo, seed)


def test_the_rq4_identity_runs_fly_the_preset():
    """The runs above are the preset's: nine delivery algorithms, its mission and its own override keys
    (a key the preset gains and the runs above lack fails here)."""
    assert len(RQ4_ALGOS) == 9 and all(a.startswith("delivery_") for a in RQ4_ALGOS)
    assert sorted(_RQ4_CI) == ["defaults", "hydra", "mission", "run"]
    assert sorted(_RQ4_CI.run) == ["progress", "state_every_ticks"]
    assert sorted(_RQ4_CI.mission) == ["generator"]
    assert sorted(_RQ4_CI.mission.generator) == ["count", "half_size_m"]
    assert {"override /mission": "delivery"} in OmegaConf.to_container(_RQ4_CI.defaults)


@pytest.mark.parametrize("algo", ["crossing", "formation9", "flocking"])
def test_shipped_missions_logs_equal(tmp_path, algo):
    manifest = assert_same_run(tmp_path, [f"algo={algo}"])
    assert manifest["status"] == "ok", manifest["reason"]


#: Every committed mission and an algorithm that flies it (the algorithm's own mission unless named)
COMMITTED_MISSIONS = {
    "adaptive": "adaptive", "airview": "airview", "airview16": "airview", "chevron": "chevron",
    "chevron200": "chevron", "crossing": "crossing", "delivery": "delivery_distance_dynamic",
    "delivery16": "delivery_distance_dynamic", "delivery36": "delivery_azimuth_rr",
    "delivery_paper": "delivery_none_block", "flocking": "flocking", "flocking200": "flocking",
    "formation": "formation", "formation36": "formation", "formation9": "formation9", "hover": "hover",
    "network": "network", "network200": "network", "socratic": "socratic", "tracking": "tracking",
    "file:experiments/missions/rq2_sim2real.yaml": "formation",
}


def test_every_committed_mission_is_flown_on_both_cores():
    root = Path(__file__).parents[2]
    shipped = {p.stem for p in (root / "swarmbox/conf/mission").glob("*.yaml")}
    shipped |= {f"file:{p.relative_to(root)}" for p in (root / "experiments/missions").glob("*.yaml")}
    assert shipped == set(COMMITTED_MISSIONS)


@pytest.mark.slow
@pytest.mark.seeds
@pytest.mark.parametrize("mission", sorted(COMMITTED_MISSIONS))
def test_every_committed_mission_logs_equal(tmp_path, mission):
    """Each committed mission, as its algorithm flies it, through both cores: the same logs."""
    where = f"mission.file={mission[5:]}" if mission.startswith("file:") else f"mission={mission}"
    manifest = assert_same_run(tmp_path, [f"algo={COMMITTED_MISSIONS[mission]}", where])
    assert manifest["status"] in ("ok", "aborted"), manifest["reason"]
