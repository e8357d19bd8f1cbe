"""Whole-run benchmarks: real-time factor and agent-ticks per second of the tick loop.

Run with ``python -m pytest tests/bench --benchmark-enable``; the figures land in
``extra_info`` (rtf = simulated seconds per wall second of the tick loop).
"""

import math

import pytest
from omegaconf import open_dict

from swarmbox.run.runner import execute
from tests.conftest import compose_config


def grid(n: int, spacing_m: float = 5.0) -> dict[int, list[float]]:
    side = math.ceil(math.sqrt(n))
    return {i: [spacing_m * (i % side), spacing_m * (i // side)] for i in range(n)}


def one_run(tmp_path_factory, overrides, positions=None):
    cfg, choices = compose_config([*overrides, "run.progress=false"])
    if positions is not None:
        with open_dict(cfg):
            cfg.mission.initial_positions = positions
            cfg.mission.swarm_size = len(positions)
    manifest = execute(cfg, tmp_path_factory.mktemp("bench"), choices, list(overrides))
    assert manifest["status"] == "ok", manifest["reason"]
    return manifest


def record(benchmark, manifest, n):
    benchmark.extra_info.update(
        drones=n, sim_time_s=manifest["sim_time_s"], loop_wall_s=round(manifest["wall_time_s"], 4),
        rtf=round(manifest["real_time_factor"], 1),
        agent_ticks_per_s=round(n * manifest["ticks"] / manifest["wall_time_s"]))


def test_default_formation_4_drones(benchmark, tmp_path_factory):
    manifest = benchmark.pedantic(one_run, args=(tmp_path_factory, []), rounds=3, iterations=1)
    record(benchmark, manifest, 4)


@pytest.mark.slow
@pytest.mark.parametrize("n", [36, 100])
def test_hover_grid(benchmark, tmp_path_factory, n):
    overrides = ["algo=hover", "mission=hover", "algo.params.hover_s=20"]
    manifest = benchmark.pedantic(one_run, args=(tmp_path_factory, overrides, grid(n)), rounds=1,
                                  iterations=1)
    record(benchmark, manifest, n)
