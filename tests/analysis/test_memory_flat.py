"""Peak memory flat in run length where the analyzer works window by window: the clock statistics of a
200-drone hover, read batch by batch, take the same peak for a flight four times longer, while reading
the messages whole (what the analyzer did) grows with it; the message flow, matched per window and
finished a window at a time, holds no more than one window beyond the flow it returns, and the link
statistics, grouped a few senders at a time, no more than a chunk. Each measurement is a fresh
process's peak resident size (VmHWM, reset after warming up) over the one call."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import pandas as pd
import pytest

from swarmbox.analysis import clockstream, unify, windows
from swarmbox.analysis.load import load_run
from swarmbox.analysis.report import ANALYZED_COLUMNS
from swarmbox.bench.hover import hover_run
from tests.analysis.test_memory_windows import FAULTY
from tests.conftest import ROOT, run_config

DRONES = 200
#: Allowed rise of the batch-wise peak for 4x the flight: a batch's buffers and allocator noise (it
#: rose by ~3 MB here, while the whole-table read rose by ~115 MB).
MARGIN = 10 * 2**20

_PEAK = """
import json, sys
from pathlib import Path
from swarmbox.analysis import clockstream, unify, windows
from swarmbox.analysis.load import load_run

def status(key):
    with open("/proc/self/status") as f:
        return next(int(line.split()[1]) * 1024 for line in f if line.startswith(key))

run_dir, how, warm = Path(sys.argv[1]), sys.argv[2], Path(sys.argv[3])
nodes = load_run(run_dir, {t: ("t_s",) for t in ("state", "messages", "stages", "events", "setpoints")}).nodes
unify.estimate_clocks_streamed(warm, nodes)   # imports and pools, before the peak is reset
with open("/proc/self/clear_refs", "w") as f:
    f.write("5")   # VmHWM from here on
before = status("VmRSS")
if how == "batches":
    clocks = unify.estimate_clocks_streamed(run_dir, nodes)
else:
    msgs = load_run(run_dir, {"messages": ("t_s", "kind", "src", "t_sent_s")}).tables["messages"]
    clocks = unify.estimate_clocks(msgs, nodes)
print(json.dumps({"rise": status("VmHWM") - before, "nodes": len(clocks)}))
"""


@pytest.fixture(scope="module")
def hovers(tmp_path_factory):
    root = tmp_path_factory.mktemp("flat")
    runs = {}
    for name, hover_s in (("short", 3.0), ("long", 40.0)):
        manifest = hover_run(DRONES, hover_s, root / name)
        assert manifest["status"] == "ok", manifest["reason"]
        runs[name] = (root / name, manifest["sim_time_s"])
    assert runs["long"][1] >= 4 * runs["short"][1] - 1.0
    return runs


def _rise(run_dir, how: str, warm) -> int:
    out = subprocess.run([sys.executable, "-c", _PEAK, str(run_dir), how, str(warm)], capture_output=True,
                         text=True, cwd=ROOT, check=True)
    got = json.loads(out.stdout)
    assert got["nodes"] == DRONES + 2   # the drones, the ground and the network
    return got["rise"]


def test_clock_statistics_peak_is_flat_in_run_length(hovers):
    warm = hovers["short"][0]
    batches = {k: _rise(d, "batches", warm) for k, (d, _) in hovers.items()}
    whole = {k: _rise(d, "whole", warm) for k, (d, _) in hovers.items()}
    assert whole["long"] - whole["short"] > 5 * MARGIN, whole   # the sizes are large enough to tell
    assert batches["long"] - batches["short"] < MARGIN, batches
    assert batches["long"] < whole["short"], (batches, whole)


@pytest.fixture(scope="module")
def faulty(tmp_path_factory):
    run_dir = tmp_path_factory.mktemp("flat") / "faulty"
    assert run_config(run_dir, FAULTY)["status"] == "ok"
    return run_dir


@pytest.mark.parametrize("batch_rows", [997, 1 << 16])
def test_clocks_from_batches_equal_those_of_the_loaded_table(hovers, faulty, batch_rows):
    """Also on a run with a clock step and a lost node (one clock per node: what the messages say)."""
    opts = unify.ClockOptions()
    for run_dir in (faulty, hovers["long"][0]):
        run = load_run(run_dir, ANALYZED_COLUMNS)
        whole = unify.estimate_clocks(run.tables["messages"], run.nodes)
        part = clockstream.run_window_parts(run_dir, opts.window_s, batch_rows=batch_rows)
        got = unify.solve_clocks(unify.pair_estimates(clockstream.pair_windows(part), opts), run.nodes)
        pd.testing.assert_frame_equal(whole, got, check_exact=True)
        streamed = unify.estimate_clocks_streamed(run_dir, run.nodes)
        pd.testing.assert_frame_equal(whole, streamed, check_exact=True)
        assert (whole["method"] == "two-way").sum() >= 3


_FLOW_PEAK = """
import json, sys
from pathlib import Path
from swarmbox.analysis import flow, flowstream, network, sampling, windows
from swarmbox.analysis.load import load_run
from swarmbox.analysis.report import ANALYZED_COLUMNS
from swarmbox.analysis.unify import unify

def status(key):
    with open("/proc/self/status") as f:
        return next(int(line.split()[1]) * 1024 for line in f if line.startswith(key))

def joined(parts, pieces, logged, t_end, tick_s):   # the pieces joined, then finished (as before)
    return flow.finish_flow(flowstream._joined(parts, pieces), logged, t_end, tick_s)

run_dir, how = Path(sys.argv[1]), sys.argv[2]
if how == "joined":
    flowstream._finish = joined
run = load_run(run_dir, ANALYZED_COLUMNS, streamed=("messages",))
clocks = unify(run)
args = (sampling.tick_s(run), sampling.max_latency_s(run))
with open("/proc/self/clear_refs", "w") as f:
    f.write("5")
before = status("VmRSS")
got, _, _ = flowstream.run_flow(run, clocks, *args)
rise = status("VmHWM") - before
if how.startswith("links"):
    windows.TOUCH_ROWS = 1 << 16 if how == "links" else 1 << 40
    with open("/proc/self/clear_refs", "w") as f:
        f.write("5")
    before = status("VmRSS")
    network.link_stats(got, 10.0)
    rise = status("VmHWM") - before
print(json.dumps({"rise": rise, "flow": int(got.memory_usage(deep=True).sum()), "rows": len(got)}))
"""


def _flow_rise(run_dir, how: str) -> dict:
    """The lower of two measurements: the resident-memory peak only ever gains noise (the allocator
    keeping freed blocks, pages collapsed into huge pages by the kernel while other processes run)."""
    env = {**os.environ, windows.ENV: "2"}   # windows a fraction of either flight
    runs = [subprocess.run([sys.executable, "-c", _FLOW_PEAK, str(run_dir), how], capture_output=True,
                           text=True, cwd=ROOT, check=True, env=env) for _ in range(2)]
    return min((json.loads(r.stdout) for r in runs), key=lambda got: got["rise"])


def test_the_flow_holds_one_window_beyond_itself(hovers):
    """run_flow's peak minus the flow it returns: flat for a flight four times longer, where joining the
    matched windows before finishing them grew with it (by the join of every window's sends)."""
    got = {k: _flow_rise(d, "pieces") for k, (d, _) in hovers.items()}
    joined = {k: _flow_rise(d, "joined") for k, (d, _) in hovers.items()}
    assert got["long"]["rows"] > 4 * got["short"]["rows"] > 0
    beyond = {k: v["rise"] - v["flow"] for k, v in got.items()}
    joined_beyond = {k: v["rise"] - v["flow"] for k, v in joined.items()}
    assert joined_beyond["long"] - joined_beyond["short"] > MARGIN, joined   # the sizes can tell
    assert beyond["long"] - beyond["short"] < MARGIN, got


def test_link_statistics_peak_is_flat_in_run_length(hovers):
    """Grouped a few links at a time (chunks of 65,536 rows), the link statistics of a flight four times
    longer take the same peak; grouped at once, it grows with the flow."""
    chunked = {k: _flow_rise(d, "links")["rise"] for k, (d, _) in hovers.items()}
    whole = {k: _flow_rise(d, "links-whole")["rise"] for k, (d, _) in hovers.items()}
    assert whole["long"] - whole["short"] > 3 * MARGIN, whole
    assert chunked["long"] - chunked["short"] < MARGIN, chunked
