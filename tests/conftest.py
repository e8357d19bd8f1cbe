"""Shared fixtures: compose a run config exactly as ``python -m swarmbox.run`` does, and run it."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from hydra import compose, initialize_config_dir
from hydra.core.global_hydra import GlobalHydra
from omegaconf import DictConfig, OmegaConf, open_dict

from swarmbox.run.config import register
from swarmbox.run.runner import execute, run_choices

ROOT = Path(__file__).resolve().parents[1]
CONF = ROOT / "swarmbox" / "conf"

register()


def pytest_collection_modifyitems(config, items):
    """Benchmarks (tests/bench) are slow tests: CI runs them with ``-m slow``."""
    bench = ROOT / "tests" / "bench"
    for item in items:
        if bench in Path(item.fspath).parents:
            item.add_marker(pytest.mark.slow)


def compose_config(overrides: list[str] | tuple[str, ...] = ()) -> tuple[DictConfig, dict[str, str]]:
    GlobalHydra.instance().clear()
    with initialize_config_dir(config_dir=str(CONF), version_base="1.3"):
        cfg = compose("config", overrides=list(overrides), return_hydra_config=True)
    hydra_choices = OmegaConf.to_container(cfg.hydra.runtime.choices)
    with open_dict(cfg):
        del cfg["hydra"]
    choices = run_choices(cfg, hydra_choices)
    return cfg, choices


def run_config(run_dir: Path, overrides: list[str] | tuple[str, ...] = (), prepare=None) -> dict:
    """Compose and execute one run in-process; returns run.json."""
    cfg, choices = compose_config([*overrides, "run.progress=false"])
    execute(cfg, run_dir, choices, list(overrides), prepare)
    return json.loads((run_dir / "run.json").read_text())


@pytest.fixture
def run(tmp_path):
    counter = iter(range(1000))

    def _run(*overrides: str, name: str | None = None, prepare=None) -> tuple[dict, Path]:
        run_dir = tmp_path / (name or f"run{next(counter)}")
        return run_config(run_dir, overrides, prepare), run_dir

    return _run


def table(run_dir: Path, node: str, name: str):
    import pandas as pd

    return pd.read_parquet(run_dir / "logs" / node / f"{name}.parquet")


def sweep_job(sweep_dir: Path, seed: int) -> Path:
    """The directory of a sweep's job with ``seed=<seed>`` among its overrides (jobs are named by their
    overrides, swarmbox/run/dirname.py); a path that does not exist when that job has none yet."""
    found = [p for p in Path(sweep_dir).glob("*") if f"seed={seed}" in p.name.split(",")]
    assert len(found) <= 1, found
    return found[0] if found else Path(sweep_dir) / f"<no job with seed={seed}>"
