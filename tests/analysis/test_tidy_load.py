"""``swarmbox.load``: tidy frames labelled with run, algo, mission, seed and node; a light import."""

import subprocess
import sys

import pandas as pd
import pytest

import swarmbox
from tests.conftest import ROOT, run_config


@pytest.fixture(scope="module")
def sweep(tmp_path_factory):
    root = tmp_path_factory.mktemp("tidy")
    for seed in (0, 1):
        manifest = run_config(root / f"job{seed}", ["algo=hover", f"seed={seed}", "mission.swarm_size=2",
                                                    "mission.initial_positions=null",
                                                    "mission.initial_positions={0:[0,0],1:[5,0]}"])
        assert manifest["status"] == "ok", manifest["reason"]
    return root


def test_sweep_rows_say_which_run_and_node_they_came_from(sweep):
    logs = swarmbox.load(sweep)
    assert set(logs) == {"state", "messages", "stages", "events", "setpoints", "runs"}
    state = logs.state
    assert list(state.columns[:5]) == ["run", "algo", "mission", "seed", "node"]
    assert set(state["run"]) == {"job0", "job1"} and set(state["algo"]) == {"hover"}
    assert set(state["node"]) == {"drone_0", "drone_1"}
    for (run, node), rows in state.groupby(["run", "node"], observed=True):   # each node's own file
        own = pd.read_parquet(sweep / run / "logs" / node / "state.parquet")
        assert len(rows) == len(own) and rows["t_s"].tolist() == own["t_s"].tolist()
    assert state.groupby("run", observed=True)["seed"].first().to_dict() == {"job0": 0, "job1": 1}
    assert {"ground", "drone_0", "drone_1"} <= set(logs.stages["node"])
    assert logs.runs.set_index("run").loc["job1", "status"] == "ok"


def test_one_run_and_a_subset_of_tables(sweep):
    logs = swarmbox.load(sweep / "job0", tables=["events"])
    assert set(logs) == {"events", "runs"} and set(logs.events["run"]) == {"job0"}
    with pytest.raises(ValueError, match="statez"):
        swarmbox.load(sweep, tables=["statez"])
    with pytest.raises(FileNotFoundError, match="no run directory"):
        swarmbox.load(sweep / "nothing")


def test_import_swarmbox_stays_light():
    code = ("import sys, swarmbox; "
            "print(sorted(m for m in ('pandas', 'matplotlib', 'scipy') if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"
