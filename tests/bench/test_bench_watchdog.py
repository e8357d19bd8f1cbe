"""Cost of the hook watchdog: the same 36-drone flocking run with ``run.hook_timeout_s`` on and off.

Run with ``python -m pytest tests/bench/test_bench_watchdog.py --benchmark-enable``; compare the two
rows (``extra_info`` holds the tick-loop wall time). The interleaved ratio in docs/errors.md comes
from ``python -m tests.bench.test_bench_watchdog`` (alternating runs, one process).
"""

from __future__ import annotations

import sys
import tempfile
from pathlib import Path

import pytest

from swarmbox.run.runner import execute
from tests.conftest import compose_config

BASE = ["algo=flocking", "mission=flocking", "mission.max_sim_time_s=40", "run.progress=false"]


def one_run(limit: str, root: Path) -> dict:
    overrides = [*BASE, f"run.hook_timeout_s={limit}"]
    cfg, choices = compose_config(overrides)
    return execute(cfg, Path(tempfile.mkdtemp(dir=root)), choices, overrides)


@pytest.mark.parametrize("limit", ["null", "10"])
def test_flocking_with_and_without_watchdog(benchmark, tmp_path, limit):
    manifest = benchmark.pedantic(one_run, args=(limit, tmp_path), rounds=3, iterations=1)
    assert manifest["ticks"] > 0
    benchmark.extra_info.update(loop_wall_s=round(manifest["wall_time_s"], 3), ticks=manifest["ticks"])


if __name__ == "__main__":
    import os

    rounds = int(sys.argv[1]) if len(sys.argv) > 1 else 5
    with tempfile.TemporaryDirectory() as tmp:
        walls: dict[str, list[float]] = {"null": [], "10": []}
        for _ in range(rounds):
            for limit in walls:
                walls[limit].append(one_run(limit, Path(tmp))["wall_time_s"])
        off, on = sorted(walls["null"]), sorted(walls["10"])
        print(f"load average {os.getloadavg()}; tick-loop wall s, off: {off}; on: {on}")
        print(f"median on/off = {on[len(on) // 2] / off[len(off) // 2]:.3f}")
