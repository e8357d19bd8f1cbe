"""Bad input to a tuning study: one line naming the cause, exit 2, and nothing written (the sweep
directory is not even created)."""

from __future__ import annotations

import pytest

from tests.tune.helpers import tune

BASE = ["hydra/sweeper=tune", "algo=flocking", "hydra.sweeper.objective=flock_order_mean"]
P_REP = "algo.params.p_rep=interval(0.1,2)"

SLOW = pytest.mark.slow


def case(name: str, overrides: list[str], says: str, *marks) -> object:
    return pytest.param(overrides, says, id=name, marks=marks)


CASES = [
    case("metric", [P_REP, "hydra.sweeper.objective=flock_orderr_mean"],
         "hydra.sweeper.objective: unknown metric 'flock_orderr_mean' for algo flocking"),
    case("metric-of-another-algo", ["algo=hover", "algo.params.hover_s=interval(1,3)"],
         "unknown metric 'flock_order_mean' for algo hover"),
    case("group-option", [P_REP, "algo=flockingg"], "Could not find 'algo/flockingg'"),
    case("undeclared-key", ["algo.params.p_repp=interval(0.1,2)"],
         "algo.params.p_repp: algorithm 'flocking' declares no parameter 'p_repp'"),
    case("n-trials", [P_REP, "hydra.sweeper.n_trials=0"], "hydra.sweeper.n_trials must be >= 1, got 0"),
    case("no-direction", [P_REP, "hydra.sweeper.objective=order_mean"],
         "hydra.sweeper.directions: higher or lower for 'order_mean' (the metric has no better direction)",
         SLOW),
    case("seed", ["seed=interval(0,9)"], "seed: the tuner chooses the seeds", SLOW),
    case("group-search", ["mission=choice(flocking,hover)"], "mission: a config group", SLOW),
    case("range-end", ["run.tick_hz=interval(0,40)"],
         "run.tick_hz=0.0: run.tick_hz must be a finite number > 0", SLOW),
    case("held-out-overlap", [P_REP, "hydra.sweeper.heldout_first_seed=3"],
         "held-out seeds 3..12 overlap the tuning seeds 0..4", SLOW),
    case("typo", [P_REP, "hydra.sweeper.n_trialz=3"], "Key 'n_trialz' not in 'TuneSweeperConf'", SLOW),
    case("no-space", [], "nothing to search", SLOW),
    case("no-callback", [P_REP, "~hydra.callbacks.tune"], "hydra.callbacks.tune is missing", SLOW),
]


@pytest.mark.parametrize(("overrides", "says"), CASES)
def test_bad_input_is_one_line_exit_2_and_nothing_written(tmp_path, overrides, says):
    sweep = tmp_path / "sweep"
    proc = tune(sweep, *overrides, base=BASE, timeout=120)
    lines = [ln for ln in proc.stderr.splitlines() if ln.strip()]
    assert proc.returncode == 2, proc.stderr[-2000:]
    assert len(lines) == 1 and lines[0].startswith("error: ") and says in lines[0], proc.stderr
    assert lines[0].endswith("(nothing was run or written)")
    assert not sweep.exists()
