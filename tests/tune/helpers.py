"""A small tuning study on the command line, as a user runs it (flocking, a short mission)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pandas as pd

from tests.conftest import ROOT

#: Two flocking gains, two objectives (order up, separation up), short flights, no end-of-sweep analysis.
STUDY = ["hydra/sweeper=tune", "hydra/launcher=swarmbox", "hydra.launcher.n_jobs=2", "algo=flocking",
         "algo.params.flock_s=5", "algo.params.p_rep=interval(0.2,2)",
         "algo.params.C_frict=tag(log,interval(0.01,0.5))",
         "hydra.sweeper.objective=[flock_order_mean,flock_min_separation_m_min]",
         "hydra.sweeper.n_trials=2", "hydra.sweeper.seeds=2", "hydra.sweeper.heldout_seeds=5",
         "~hydra.callbacks.analyze"]


def tune(sweep_dir: Path, *overrides: str, base=STUDY, timeout: float = 600,
         python: str = sys.executable) -> subprocess.CompletedProcess:
    return subprocess.run([python, "-m", "swarmbox.run", "-m", *base, f"hydra.sweep.dir={sweep_dir}",
                           *overrides], cwd=ROOT, capture_output=True, text=True, timeout=timeout)


def trials(sweep_dir: Path) -> pd.DataFrame:
    return pd.read_csv(sweep_dir / "tune" / "trials.csv")
