"""Run or sweep from the command line: ``-m`` or a ``hydra.mode=MULTIRUN`` override starts a sweep."""

from __future__ import annotations

import json
import subprocess
import sys

from tests.conftest import ROOT


def test_a_mode_override_still_starts_a_sweep_without_dash_m(tmp_path):
    sweep = tmp_path / "sweep"
    proc = subprocess.run([sys.executable, "-m", "swarmbox.run", "algo=hover", "mission=hover", "seed=0,1",
                           "hydra.mode=MULTIRUN", f"hydra.sweep.dir={sweep}", "~hydra.callbacks.analyze"],
                          cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr[-2000:]
    seeds = sorted(json.loads((d / "run.json").read_text())["seed"] for d in sweep.iterdir() if d.is_dir())
    assert seeds == [0, 1]
