"""One source of truth per plug-in: every algorithm class has a config, every config instantiates."""

import importlib
import inspect

import pytest
from hydra.utils import instantiate

from swarmbox.api import DroneAlgorithm, FleetAlgorithm, GroundAlgorithm
from tests.conftest import CONF, ROOT, compose_config

ALGO_CONFIGS = sorted(p.stem for p in (CONF / "algo").glob("*.yaml") if not p.stem.endswith("_base"))


@pytest.mark.parametrize("name", ALGO_CONFIGS)
def test_every_algo_config_composes_and_instantiates(name):
    cfg, _ = compose_config([f"algo={name}"])
    drone = instantiate(cfg.algo.drone)
    assert isinstance(drone, DroneAlgorithm | FleetAlgorithm)
    if cfg.algo.ground is not None:
        assert isinstance(instantiate(cfg.algo.ground), GroundAlgorithm)


def _algorithm_classes():
    for path in sorted((ROOT / "swarmbox" / "algorithms").glob("*.py")):
        if path.stem.startswith("_"):
            continue
        module = importlib.import_module(f"swarmbox.algorithms.{path.stem}")
        for _, cls in inspect.getmembers(module, inspect.isclass):
            roles = DroneAlgorithm | FleetAlgorithm | GroundAlgorithm
            if cls.__module__ == module.__name__ and issubclass(cls, roles):
                yield f"{cls.__module__}.{cls.__qualname__}"


def test_every_algorithm_class_has_a_config():
    targets = set()
    for name in ALGO_CONFIGS:
        cfg, _ = compose_config([f"algo={name}"])
        targets.add(cfg.algo.drone._target_)
        if cfg.algo.ground is not None:
            targets.add(cfg.algo.ground._target_)
    missing = sorted(set(_algorithm_classes()) - targets)
    assert not missing, f"algorithm classes without a config in conf/algo/: {missing}"
