"""One full RQ4 delivery run (5 drones, 100 packages of the paper's dataset 1): wall time and
real-time factor, the unit of cost of the 180-run benchmark.

Run with ``python -m pytest tests/bench/test_bench_delivery.py --benchmark-enable``; ``extra_info``
holds the simulated time, the tick-loop wall time and the real-time factor.
"""

import json

import pandas as pd
import pytest

from swarmbox.run.runner import execute
from tests.conftest import compose_config

OVERRIDES = ["+experiment=rq4_delivery", "algo=delivery_distance_dynamic", "seed=0", "run.progress=false"]


def one_run(tmp_path_factory, jit: str) -> tuple[dict, object]:
    overrides = [*OVERRIDES, f"backend.jit={jit}"]
    cfg, choices = compose_config(overrides)
    run_dir = tmp_path_factory.mktemp("bench_delivery")
    return execute(cfg, run_dir, choices, overrides), run_dir


@pytest.mark.slow
@pytest.mark.parametrize("jit", ["never", "always"])   # numpy / the compiled kernel (loaded before the loop)
def test_full_paper_delivery_run(benchmark, tmp_path_factory, jit):
    manifest, run_dir = benchmark.pedantic(one_run, args=(tmp_path_factory, jit), rounds=1, iterations=1)
    assert manifest["status"] == "ok", manifest["reason"]
    events = pd.read_parquet(run_dir / "logs" / "ground" / "events.parquet")
    delivered = [json.loads(d)["package"] for d in events.loc[events["name"] == "delivered", "data"]]
    assert sorted(delivered) == list(range(100))
    benchmark.extra_info.update(
        drones=manifest["n_drones"], sim_time_s=manifest["sim_time_s"],
        loop_wall_s=round(manifest["wall_time_s"], 3), rtf=round(manifest["real_time_factor"], 1))
