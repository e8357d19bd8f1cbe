"""The analyzer on a real formation run from the runner (not synthetic logs)."""

import subprocess
import sys

import pytest

from swarmbox.analysis import figures
from swarmbox.analysis.report import analyze_run
from tests.conftest import ROOT

# ``formation_run``: a short formation on wifi with a skewed clock (tests/analysis/conftest.py)


def test_metrics_of_a_real_run(formation_run):
    a = analyze_run(formation_run)
    s = a.scalars
    assert s["mission_duration_s"] > 10
    assert s["collision_events"] == 0 and s["min_separation_m"] > 3.0
    assert 0.0 < s["formation_error_m_mean"] < 3.0   # position-only tracking lags ~ speed / MPC_XY_P
    assert 0.005 < s["loss_ratio"] < 0.02                     # wifi: 1 % loss
    assert 5.0 <= s["latency_ms_mean"] <= 8.5                 # wifi: 5 ms + U(0, 3) ms
    clocks = a.clocks.set_index("node")
    assert clocks.loc[2, "offset_s"] == pytest.approx(0.5, abs=0.025)


def test_figures_of_a_real_run(formation_run):
    a = analyze_run(formation_run)
    fig = figures.trajectories(a.run.tables["state"])
    assert len(fig.axes[0].get_lines()) == 4
    proc = subprocess.run([sys.executable, "-m", "swarmbox.analyze", str(formation_run)], cwd=ROOT,
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr[-2000:]
    pngs = sorted(p.name for p in (formation_run / "figures").glob("*.png"))
    assert "trajectories.png" in pngs and len(pngs) >= 3
    assert all((formation_run / "figures" / p).stat().st_size > 5000 for p in pngs)
