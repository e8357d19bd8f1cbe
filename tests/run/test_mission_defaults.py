"""An algorithm brings its own mission; a mission file keeps its name and its own mission data."""

import numpy as np
import pytest

from swarmbox.run import mission
from tests.conftest import CONF, compose_config


@pytest.mark.parametrize("algo", sorted(p.stem for p in (CONF / "algo").glob("*.yaml")))
def test_each_algorithm_alone_brings_its_mission(algo):
    cfg, choices = compose_config([f"algo={algo}"])
    # a batch port (hover_batch ...) brings the mission of the algorithm it ports
    own = "delivery" if algo.startswith("delivery") else algo.removesuffix("_batch")
    assert choices["mission"] == own and cfg.mission.name == own


def test_mission_on_the_command_line_and_experiments_still_win():
    assert compose_config(["algo=airview", "mission=hover"])[1]["mission"] == "hover"
    rq4 = compose_config(["+experiment=rq4_delivery", "algo=delivery_none_rr"])[1]
    assert rq4["mission"] == "delivery_paper"
    assert compose_config(["+experiment=rq3_drift"])[1]["mission"] == "formation9"


LEGACY = """drone_config:
  initial_positions: {0: [0, 0], 1: [5, 0]}
  superiors: {0: -1, 1: -1}
mission_config:
  type: two_drops
  swarm_size: 2
  values: {0: [10, 10], 1: [-10, 20]}
"""


def test_a_mission_file_keeps_its_packages_under_the_delivery_preset(tmp_path):
    path = tmp_path / "two_drops.yaml"
    path.write_text(LEGACY)
    cfg, _ = compose_config(["algo=delivery_distance_dynamic", f"mission.file={path}"])
    assert cfg.mission.generator is not None            # the delivery mission's generator is there ...
    m = mission.load(cfg, np.random.default_rng(0))
    assert m.name == "two_drops" and m.values == {0: (10.0, 10.0), 1: (-10.0, 20.0)}   # ... and unused


def test_a_mission_file_without_values_is_filled_by_the_generator(tmp_path):
    path = tmp_path / "bare.yaml"
    path.write_text(LEGACY.replace("  values: {0: [10, 10], 1: [-10, 20]}\n", ""))
    cfg, _ = compose_config(["algo=delivery_distance_dynamic", f"mission.file={path}",
                             "mission.generator.count=7"])
    assert len(mission.load(cfg, np.random.default_rng(0)).values) == 7


def test_a_run_from_a_mission_file_records_the_files_mission(run, tmp_path):
    path = tmp_path / "two_hover.yaml"
    path.write_text(LEGACY.replace("two_drops", "two_hover"))
    manifest, _ = run("algo=hover", f"mission.file={path}", "algo.params.hover_s=1")
    assert manifest["status"] == "ok", manifest["reason"]
    assert manifest["choices"]["mission"] == "two_hover"
