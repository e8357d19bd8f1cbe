"""Bad configuration fails before the run, naming the cause."""

import pytest
from hydra.errors import ConfigCompositionException
from omegaconf.errors import ConfigKeyError, ValidationError

from swarmbox.run.mission import MissionError, load, load_legacy
from tests.conftest import ROOT, compose_config

LEGACY = ROOT / "experiments" / "missions" / "rq2_sim2real.yaml"


def test_misspelt_key_names_the_key():
    with pytest.raises((ConfigCompositionException, ConfigKeyError)) as err:
        compose_config(["run.tick_hzz=20"])
    assert "tick_hzz" in str(err.value) + str(err.value.__cause__)


def test_wrong_type_names_the_key():
    with pytest.raises((ConfigCompositionException, ValidationError)) as err:
        compose_config(["run.lost_inferior_ticks=soon"])
    assert "lost_inferior_ticks" in str(err.value) + str(err.value.__cause__)


def test_misspelt_key_inside_a_group_file_is_caught(tmp_path):
    (tmp_path / "mission").mkdir()
    (tmp_path / "mission" / "typo.yaml").write_text(
        "name: typo\nswarmsize: 2\ninitial_positions: {0: [0, 0], 1: [5, 0]}\n")
    with pytest.raises((ConfigCompositionException, ConfigKeyError)) as err:
        compose_config([f"hydra.searchpath=[file://{tmp_path}]", "mission=typo"])
    message = str(err.value) + str(err.value.__cause__)
    assert "swarmsize" in message and "typo" in message


def test_legacy_mission_file_loads_unchanged():
    m = load_legacy(LEGACY, 300.0, [])
    assert m.name == "rq2_sim2real" and m.swarm_size == 4
    assert m.initial_positions[3] == (-6.0, -6.0, 0.0)
    assert m.superiors == {0: -1, 1: -1, 2: -1, 3: -1}
    cfg, _ = compose_config([f"mission.file={LEGACY}"])
    assert load(cfg).initial_positions == m.initial_positions


def test_swarm_size_disagreeing_with_positions_is_refused(tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text(LEGACY.read_text().replace("swarm_size: 4", "swarm_size: 5"))
    with pytest.raises(MissionError, match="swarm_size 5 disagrees with the 4 initial_positions"):
        load_legacy(bad, 300.0, [])


def test_missing_mission_file_is_named():
    cfg, _ = compose_config(["mission.file=/nonexistent/m.yaml"])
    with pytest.raises(MissionError, match="no such file: /nonexistent/m.yaml"):
        load(cfg)
