"""Run or sweep from the command line: Hydra does not compose the config an extra time to find out."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest
from hydra._internal.hydra import Hydra
from hydra.types import RunMode

from swarmbox.run import mode
from tests.conftest import ROOT


@pytest.mark.parametrize("overrides, expected", [
    ([], None),
    (["seed=1", "algo=hover"], None),
    (["hydra.mode=MULTIRUN", "seed=0,1"], RunMode.MULTIRUN),
    (["hydra.mode=run"], RunMode.RUN),
    (["hydra.mode=RUN", "hydra.mode=MULTIRUN"], RunMode.MULTIRUN),
    (["hydra.mode=sideways"], None),   # Hydra refuses the override itself, naming it
])
def test_the_mode_comes_from_the_overrides(overrides, expected):
    assert mode.mode_from_overrides(overrides) is expected


def test_hydra_no_longer_composes_to_find_the_mode(monkeypatch):
    def refuse(*args, **kwargs):
        raise AssertionError("composed")

    monkeypatch.setattr(Hydra, "compose_config", refuse)
    monkeypatch.setattr(Hydra, "get_mode", Hydra.get_mode)   # undone after the test
    mode.install()
    assert Hydra.get_mode(object.__new__(Hydra), "config", ["hydra.mode=MULTIRUN"]) is RunMode.MULTIRUN


def test_a_mode_override_still_starts_a_sweep_without_dash_m(tmp_path):
    sweep = tmp_path / "sweep"
    proc = subprocess.run([sys.executable, "-m", "swarmbox.run", "algo=hover", "mission=hover", "seed=0,1",
                           "hydra.mode=MULTIRUN", f"hydra.sweep.dir={sweep}", "~hydra.callbacks.analyze"],
                          cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr[-2000:]
    seeds = sorted(json.loads((d / "run.json").read_text())["seed"] for d in sweep.iterdir() if d.is_dir())
    assert seeds == [0, 1]
