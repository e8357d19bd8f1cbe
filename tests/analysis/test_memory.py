"""What the analyzer holds in memory on a large run, and that holding less changes no number: the
destination lists of broadcast rows decoded at their own size, a large run's reads from a pool that
gives memory back (then the default pool restored), the same tables whichever way a run is read, and
the diagnosis reusing the run's message flow."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from swarmbox.analysis import diagnosis as dg
from swarmbox.analysis import load, network, sampling
from swarmbox.analysis.load import load_run
from swarmbox.analysis.report import ANALYZED_COLUMNS, analyze_run
from swarmbox.analysis.unify import unify
from swarmbox.record.broadcast import BROADCAST
from swarmbox.record.schema import TABLES
from tests.conftest import ROOT

_DRONES = 1000
_ROWS = 20_000
_BROADCASTS = 50


def _ground_messages(path: Path) -> None:
    """A ground's messages file as a 1,000-drone run writes it: a few broadcast rows listing every drone
    in ``reason`` (4.9 kB each), and many receive rows with an empty reason."""
    every = ",".join(str(i) for i in range(_DRONES))
    broadcast = np.zeros(_ROWS, dtype=bool)
    broadcast[:: _ROWS // _BROADCASTS] = True
    columns = {c.name: np.zeros(_ROWS, dtype=c.dtype) for c in TABLES["messages"]
               if c.dtype not in ("string", "bool")}
    columns["t_s"] = np.arange(_ROWS) * 0.025
    columns["msg_id"] = np.arange(_ROWS)
    columns["dst"] = np.where(broadcast, BROADCAST, -1).astype("int16")
    columns["kind"] = np.where(broadcast, "send", "recv")
    columns["type"] = np.where(broadcast, "heartbeat", "report")
    columns["reason"] = np.where(broadcast, every, "")
    table = pa.table({c.name: columns[c.name] for c in TABLES["messages"]})
    pq.write_table(table.replace_schema_metadata({"swarmbox.schema": "2"}), path)


_PEAK = """
import json, sys
from pathlib import Path
import pyarrow as pa
from swarmbox.analysis.load import read_arrow
data = read_arrow(Path(sys.argv[1]), "messages", -1, [])
print(json.dumps({"rows": data.num_rows, "peak": pa.default_memory_pool().max_memory()}))
"""


def test_broadcast_destination_lists_are_decoded_at_their_own_size(tmp_path):
    """Decoding ``reason`` from Parquet's dictionary reserved the dictionary's mean length for every row
    (20,000 rows x ~2.4 kB: ~50 MB for 0.25 MB of text; at 1,000 drones, 1.5 GB per 20 s of flight).
    A fresh process, so that Arrow's peak is this read's alone."""
    path = tmp_path / "messages.parquet"
    _ground_messages(path)
    out = subprocess.run([sys.executable, "-c", _PEAK, str(path)], capture_output=True, text=True,
                         cwd=ROOT, check=True)
    got = json.loads(out.stdout)
    assert got["rows"] == _ROWS - _BROADCASTS + _BROADCASTS * _DRONES   # every broadcast expanded
    assert got["peak"] < 16e6, got   # the expanded table is ~3 MB; the old decoding ~50 MB


@pytest.mark.parametrize(("threshold", "large"), [(0, True), (1 << 40, False)])
def test_a_large_run_is_read_from_a_pool_that_returns_memory(formation_run, monkeypatch, threshold, large):
    """Above ``_POOL_BYTES`` the reads allocate from jemalloc (or the system allocator) instead of the
    default pool, which kept 1.4 GB of freed read buffers after an 80 s 1,000-drone run; the default pool
    is back afterwards. A small run stays on the default pool (a sweep worker reuses its few MB)."""
    default = pa.default_memory_pool().backend_name
    seen: list[str] = []
    read = load.read_arrow

    def recording(*args, **kwargs):
        seen.append(pa.default_memory_pool().backend_name)
        return read(*args, **kwargs)

    monkeypatch.setattr(load, "_POOL_BYTES", threshold)
    monkeypatch.setattr(load, "read_arrow", recording)
    load_run(formation_run, ANALYZED_COLUMNS)
    assert set(seen) == ({_returning_backend()} if large else {default})
    assert pa.default_memory_pool().backend_name == default


def _returning_backend() -> str:
    try:
        return pa.jemalloc_memory_pool().backend_name
    except NotImplementedError:   # pyarrow built without jemalloc
        return "system"


def _tables(analysis) -> dict[str, pd.DataFrame]:
    return {"drones": analysis.drones, "links": analysis.links, "agents": analysis.agents,
            "clocks": analysis.clocks, "timeline": analysis.timeline, "swarm": analysis.swarm,
            "connectivity": analysis.connectivity, "anomalies": analysis.flags, "finding": analysis.finding,
            "alarms": analysis.alarms, "markers": analysis.markers, "flow": analysis.flow}


def test_large_and_small_read_paths_give_the_same_analysis(formation_run, monkeypatch):
    """The same run read file by file on the default pool, and table by table by the thread pool on the
    returning pool: every table and scalar of its analysis identical, bit for bit."""
    small = analyze_run(load_run(formation_run, ANALYZED_COLUMNS))
    monkeypatch.setattr(load, "_POOL_BYTES", 0)
    large = analyze_run(load_run(formation_run, ANALYZED_COLUMNS))
    assert small.problems == large.problems
    np.testing.assert_equal(small.scalars, large.scalars)
    for name, frame in _tables(small).items():
        pd.testing.assert_frame_equal(frame, _tables(large)[name], check_exact=True, obj=name)
    assert len(small.flow) and len(small.timeline) and len(small.swarm)


def test_the_finding_from_the_run_flow_equals_its_own_matching(formation_run):
    """The diagnosis series given the flow the run analysis already matched are those it matches itself."""
    run = load_run(formation_run, ANALYZED_COLUMNS)
    unify(run)
    flow = network.message_flow(run.tables["messages"], sampling.tick_s(run), sampling.max_latency_s(run))
    own, given = dg.drone_series(run), dg.drone_series(run, flow=flow)
    assert own.values.keys() == given.values.keys()
    for metric, values in own.values.items():
        np.testing.assert_array_equal(values, given.values[metric], err_msg=metric)
    assert np.isfinite(own.values["latency_ms"]).any() and np.isfinite(own.values["loss_ratio"]).any()


@pytest.mark.parametrize("keep", ["agents", "where", "both"])
def test_touching_filtered_equals_the_doubled_flow_filtered(formation_run, keep):
    """The drones' and the delivered rows taken while doubling the flow are the rows, in the order, that
    filtering the whole doubled flow gives (what the timeline and the diagnosis used to make)."""
    run = load_run(formation_run, ANALYZED_COLUMNS)
    unify(run)
    flow = network.message_flow(run.tables["messages"], sampling.tick_s(run), sampling.max_latency_s(run))
    columns = ["t_send", "latency_ms", "delivered", "lost"]
    drones = run.drones[1:]   # not every drone: the filter must drop some agents' rows
    where = flow["delivered"].to_numpy(dtype=bool)
    agents = drones if keep != "where" else None
    mask = where if keep != "agents" else None
    whole = network.touching(flow, columns)
    expected = whole[(whole["agent"].isin(drones) if agents else True) & (
        np.concatenate([where, where]) if mask is not None else True)].reset_index(drop=True)
    got = network.touching(flow, columns, agents, mask)
    assert 0 < len(got) < len(whole)
    pd.testing.assert_frame_equal(got, expected, check_exact=True)
