"""Fixtures: synthetic run and sweep directories with hand-computable metrics."""

from __future__ import annotations

from pathlib import Path

import pytest

from tests.analysis.synthetic import Scenario, build_run


@pytest.fixture
def make_run(tmp_path: Path):
    """Build a synthetic run from keyword overrides of :class:`Scenario`."""
    counter = iter(range(1000))

    def _make(name: str | None = None, **fields) -> Path:
        return build_run(tmp_path / (name or f"run{next(counter)}"), Scenario(**fields))

    return _make


def sweep_scenarios() -> list[tuple[str, Scenario]]:
    """2 algorithms x 5 seeds. Per seed, ``slow`` lands 40 ticks (1 s) later than ``fast`` and every
    drone of ``slow`` completes 40 ticks later, so paired differences are exactly +1 s."""
    out = []
    for algo, extra in (("fast", 0), ("slow", 40)):
        for seed in range(5):
            land = 300 + 8 * seed + extra
            complete = {d: 120 + 10 * d + 4 * seed + extra for d in range(4)}
            sc = Scenario(ticks=400, ground_stages={1: 0, 2: 20, 3: 40, 4: land, 5: 390},
                          complete_ticks=complete, seed=seed,
                          choices={"algo": algo, "mission": "synthetic"})
            out.append((f"{algo}_{seed}", sc))
    return out


@pytest.fixture(scope="session")
def sweep_dir(tmp_path_factory) -> Path:
    root = tmp_path_factory.mktemp("sweep")
    for i, (_, sc) in enumerate(sweep_scenarios()):
        build_run(root / str(i), sc)   # directory names carry no meaning
    return root


SHORT = ("algo.params.start_s=3", "algo.params.angular_rate_rad_s=0.25", "algo.params.complete_after_s=10",
         "network=wifi", "run.clocks={drone_2: {offset_s: 0.5, drift_ppm: 100}}")


@pytest.fixture(scope="session")
def formation_run(tmp_path_factory) -> Path:
    """A real formation run from the runner: short, on the lossy wifi network, drone 2's clock skewed."""
    from tests.conftest import run_config

    run_dir = tmp_path_factory.mktemp("real") / "formation"
    manifest = run_config(run_dir, SHORT)
    assert manifest["status"] == "ok", manifest["reason"]
    return run_dir
