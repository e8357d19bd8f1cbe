"""The mission-area helper of the API layer, and the algorithms that read their area through it."""

import pytest
from omegaconf import open_dict

from swarmbox.api import Area, mission_area, mission_grid
from swarmbox.run.runner import execute
from tests.conftest import compose_config

VALUES = {0: (-50.0, -20.0), 1: (30.0, 40.0, 7.0), 2: (3, 4)}


def test_area_is_read_from_values_0_and_1_as_given():
    area = mission_area(VALUES, "demo")
    assert area == Area(-50.0, -20.0, 30.0, 40.0)
    n0, e0, n1, e1 = area                       # unpacks like the plain 4-tuple it replaces
    assert (n0, e0, n1, e1) == (-50.0, -20.0, 30.0, 40.0)
    assert area.center == (-10.0, 10.0) and area.size == (80.0, 60.0)
    assert type(mission_area({0: [0, 0], 1: [2, 3]}, "demo").n_max) is int   # no conversion


def test_grid_is_read_from_value_2():
    assert mission_grid(VALUES, "demo") == (3, 4)
    assert mission_grid({2: [2.0, 2.0]}, "demo", min_cells=2) == (2, 2)


@pytest.mark.parametrize(("values", "message"), [
    ({0: [0, 0]}, "demo: mission.values needs 0: [north_min, east_min] and 1: [north_max, east_max]"),
    ({0: [0], 1: [1, 1]}, "demo: mission.values needs 0"),
    ({0: [0, 0], 1: [0, 5]}, "demo: empty area [0, 0] .. [0, 5]"),
    ({0: [0, 0], 1: [5, -1]}, "demo: empty area"),
])
def test_a_bad_area_is_refused_naming_the_algorithm(values, message):
    with pytest.raises(ValueError, match=message.replace("[", r"\[").replace("]", r"\]")):
        mission_area(values, "demo")


@pytest.mark.parametrize(("values", "min_cells", "message"), [
    ({}, 1, r"demo: mission.values needs 2: \[rows, cols\]"),
    ({2: [3]}, 1, r"demo: mission.values needs 2"),
    ({2: ["a", 2]}, 1, r"demo: mission.values needs 2"),
    ({2: [1, 4]}, 2, r"demo: grid \[1, 4\] needs at least 2 rows and columns"),
])
def test_a_bad_grid_is_refused(values, min_cells, message):
    with pytest.raises(ValueError, match=message):
        mission_grid(values, "demo", min_cells)


@pytest.mark.parametrize(("algo", "values", "cause"), [
    ("airview", {0: [0.0, 0.0], 1: [0.0, 40.0]}, "airview: empty area [0.0, 0.0] .. [0.0, 40.0]"),
    ("network", {0: [0.0, 0.0], 1: [40.0, 40.0], 2: [1, 4]}, "network: grid [1.0, 4.0] needs at least 2"),
    ("tracking", {0: [0.0, 0.0], 1: [40.0, 40.0]}, "tracking: mission.values needs 2: [rows, cols]"),
])
def test_area_algorithms_fail_a_run_with_the_helpers_message(tmp_path, algo, values, cause):
    cfg, choices = compose_config([f"algo={algo}", f"mission={algo}", "run.progress=false"])
    with open_dict(cfg):
        cfg.mission.values = values
        cfg.mission.max_sim_time_s = 5.0
    manifest = execute(cfg, tmp_path / algo, choices, [])
    assert manifest["status"] == "failed" and cause in manifest["reason"], manifest["reason"]
