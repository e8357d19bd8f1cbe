"""The analyzer's window: a run analysed in many small windows gives the tables of one window over the
whole run, on a real run whose faults put messages in flight across window edges (a 600 ms link on
drone 1), a clock step (drone 2), a node removed (drone 3, its messages lost) and alarms that persist
across the diagnosis' chunk edges; and the edges themselves (a boundary at a send or receive time, a
message in flight longer than a window, empty windows, one tick)."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from swarmbox.analysis import diagnosis as dg
from swarmbox.analysis import flow as fl
from swarmbox.analysis import metrics, network, sampling, windows
from swarmbox.analysis.load import load_run
from swarmbox.analysis.report import ANALYZED_COLUMNS, analyze_run
from swarmbox.analysis.unify import T, unify
from tests.analysis.test_memory import _tables
from tests.conftest import run_config

FAULTY = ("algo=hover", "mission=hover", "algo.params.hover_s=10", "network=wifi",
          "fault=[clock_skew,crash,latency]", "fault.clock_skew.targets=[2]", "fault.clock_skew.onset_s=5",
          "fault.crash.targets=[3]", "fault.crash.onset_s=7", "fault.latency.targets=[1]",
          "fault.latency.onset_s=4", "fault.latency.latency_ms=600")
#: The same faults without the clock step: the messages stay in their files and are matched window by
#: window (a clock step has the analyzer read the whole table: the lives are told apart in each log).
PLAIN = (*(o for o in FAULTY if "clock_skew" not in o), "fault=[crash,latency]",
         "run.clocks={drone_2: {offset_s: 0.5, drift_ppm: 100}}")
SMALL_S = 0.1   # four grid points of 25 ms: the 600 ms messages cross six windows


@pytest.fixture(scope="module")
def faulty_run(tmp_path_factory):
    run_dir = tmp_path_factory.mktemp("window") / "faulty"
    manifest = run_config(run_dir, FAULTY)
    assert manifest["status"] == "ok", manifest["reason"]
    return run_dir


@pytest.fixture(scope="module")
def plain_run(tmp_path_factory):
    run_dir = tmp_path_factory.mktemp("window") / "plain"
    manifest = run_config(run_dir, PLAIN)
    assert manifest["status"] == "ok", manifest["reason"]
    return run_dir


def _analysis(run_dir, monkeypatch, window: str, streamed: tuple[str, ...] = ()):
    monkeypatch.setenv(windows.ENV, window)
    return analyze_run(load_run(run_dir, ANALYZED_COLUMNS, streamed=streamed))


def _equal(one, other) -> None:
    assert one.problems == other.problems
    np.testing.assert_equal(one.scalars, other.scalars)
    for name, frame in _tables(one).items():
        pd.testing.assert_frame_equal(frame, _tables(other)[name], check_exact=True, obj=name)


def test_many_windows_give_the_tables_of_one(faulty_run, monkeypatch):
    one = _analysis(faulty_run, monkeypatch, "inf")
    many = _analysis(faulty_run, monkeypatch, str(SMALL_S))
    _equal(one, many)
    # the faults did what the windows must survive
    assert (one.clocks["life"] > 0).any()                                   # a clock step
    assert one.flow["lost"].any() and (one.flow["latency_ms"] > 5 * SMALL_S * 1e3).any()
    grid = float(one.finding["grid_s"].iloc[0])
    assert ((one.alarms["end_u"] - one.alarms[T]) > SMALL_S + grid).any()    # an alarm across chunks
    assert one.finding["detected"].iloc[0]


@pytest.mark.parametrize("window", ["inf", str(SMALL_S), "3"])
def test_messages_streamed_from_their_files_give_the_tables_of_the_loaded_run(plain_run, monkeypatch, window):
    """The messages left in their files (clocks from batches, the flow matched per window from scratch
    partitions): every table, scalar and problem as when the table is loaded, the flow row for row."""
    loaded = _analysis(plain_run, monkeypatch, "inf")
    streamed = _analysis(plain_run, monkeypatch, window, ("messages",))
    assert streamed.run.streamed == ("messages",) and streamed.run.tables["messages"].empty
    _equal(loaded, streamed)
    assert loaded.flow["lost"].any() and (loaded.flow["latency_ms"] > 500).any()
    assert (loaded.clocks["offset_s"] - loaded.clocks["true_offset_s"]).abs().max() < 1e-3


def test_a_clock_step_has_the_streamed_messages_read_whole(faulty_run, monkeypatch):
    loaded = _analysis(faulty_run, monkeypatch, "inf")
    streamed = _analysis(faulty_run, monkeypatch, str(SMALL_S), ("messages",))
    assert streamed.run.streamed == () and len(streamed.run.tables["messages"])
    _equal(loaded, streamed)


@pytest.mark.filterwarnings("ignore:invalid value encountered in cast:RuntimeWarning")   # the NaN send time
def test_a_message_row_with_no_time_has_the_messages_read_whole(plain_run, tmp_path, monkeypatch):
    """A row whose time is unknown cannot be put in a window (such a send takes its key's first receive
    anywhere in the run): the streamed run reads its messages whole and gives the loaded run's tables."""
    import shutil

    import pyarrow as pa
    import pyarrow.parquet as pq

    damaged = tmp_path / "damaged"
    shutil.copytree(plain_run, damaged)
    path = damaged / "logs" / "drone_0" / "messages.parquet"
    table = pq.read_table(path)
    t_s = table.column("t_s").to_numpy(zero_copy_only=False).copy()
    sends = np.flatnonzero(pd.Series(table.column("kind").to_pylist()) == "send")
    mask = np.zeros(len(t_s), dtype=bool)
    mask[sends[len(sends) // 2]] = True   # a send in mid-flight loses its time
    column = pa.array(t_s, mask=mask)
    pq.write_table(table.set_column(table.schema.get_field_index("t_s"), "t_s", column), path)
    loaded = _analysis(damaged, monkeypatch, "inf")
    streamed = _analysis(damaged, monkeypatch, str(SMALL_S), ("messages",))
    assert streamed.run.streamed == () and loaded.flow["t_send"].isna().sum() == 1
    _equal(loaded, streamed)


@pytest.mark.parametrize(("window", "batch_rows", "touch_rows"),
                         [("inf", 1 << 16, 1 << 21), (str(SMALL_S), 1 << 16, 1 << 21), ("3", 97, 500)])
def test_the_cli_writes_the_tables_of_the_loaded_run(plain_run, tmp_path, monkeypatch, window, batch_rows,
                                                     touch_rows):
    """``swarmbox analyze`` streams the messages and reads the state without the columns no table uses:
    its files, byte for byte, are those of the run loaded whole (every column, the messages matched at
    once, the links and agents grouped at once) and written the same way; in one window, in windows of
    100 ms, and in 3 s windows read in batches of 97 rows with links and agents a few at a time."""
    from swarmbox.analysis.cli import analyze_main
    from swarmbox.analysis.outputs import write_run

    monkeypatch.setenv(windows.ENV, "inf")
    write_run(analyze_run(load_run(plain_run)), tmp_path / "ref", with_figures=False)
    monkeypatch.setenv(windows.ENV, window)
    monkeypatch.setattr(windows, "BATCH_ROWS", batch_rows)
    monkeypatch.setattr(windows, "TOUCH_ROWS", touch_rows)
    assert analyze_main([str(plain_run), "--no-figures", "--out", str(tmp_path / "cli")]) == 0
    names = sorted(p.name for p in (tmp_path / "ref" / "tables").iterdir())
    assert names == sorted(p.name for p in (tmp_path / "cli" / "tables").iterdir()) and "links.csv" in names
    for name in names:
        cli, ref = (tmp_path / kind / "tables" / name for kind in ("cli", "ref"))
        assert cli.read_bytes() == ref.read_bytes(), name


def test_per_agent_metrics_a_few_agents_at_a_time(plain_run, monkeypatch):
    """The links', agents', the timeline's and the diagnosis' latency and loss grouped over chunks of agents
    (at most 500 rows of the doubled flow each: chunks of two or three agents here, each averaged as
    pandas averages the whole) equal those grouped at once."""
    whole = _analysis(plain_run, monkeypatch, "inf")
    monkeypatch.setattr(windows, "TOUCH_ROWS", 500)
    chunks = network.agent_chunks(whole.flow)
    assert len(chunks) > 1 and all(len(c) >= 2 for c in chunks)
    for chunk in chunks:   # no chunk falls back to the whole: its delivered rows are not in key order
        both = network.touching(whole.flow, ["delivered"], chunk)
        assert not network.sorted_keys(both["agent"].to_numpy()[both["delivered"].to_numpy()])
    links = network._link_chunks(whole.flow["src"].to_numpy(), whole.flow["dst"].to_numpy(), 500)
    assert len(links) > 1 and sorted(np.concatenate(links)) == list(range(len(whole.flow)))   # each row once
    for rows in links:   # the links' chunks: two links at least, never in key order
        mine = whole.flow.iloc[rows]
        mine = mine[mine["delivered"]]
        assert len(mine.groupby(["src", "dst"])) >= 2
        assert not network.sorted_keys(mine["src"].to_numpy(), mine["dst"].to_numpy())
    drones = network.agent_chunks(whole.flow, whole.run.drones)   # the timeline's and the diagnosis'
    assert len(drones) > 1
    for chunk in drones:
        got = network.touching(whole.flow, ["t_recv"], chunk, whole.flow["delivered"].to_numpy(dtype=bool))
        assert not network.sorted_keys(dg.nearest_tick(got["t_recv"], 0.025), got["agent"].to_numpy())
    _equal(whole, _analysis(plain_run, monkeypatch, "inf"))


@pytest.mark.parametrize("block", [1, 7, 256])
def test_swarm_order_by_blocks_of_ticks(plain_run, block):
    run = _unified(plain_run)
    whole = metrics.order_by_tick(run.tables["state"], run.drones, block=10**9)
    got = metrics.order_by_tick(run.tables["state"], run.drones, block=block)
    pd.testing.assert_series_equal(whole, got, check_exact=True)
    assert whole.notna().sum() > 100


def test_sorted_keys():
    assert network.sorted_keys(np.array([1, 1, 2]), np.array([5, 6, 0]))
    assert not network.sorted_keys(np.array([1, 1, 2]), np.array([6, 5, 0]))
    assert not network.sorted_keys(np.array([2, 1]))
    assert network.sorted_keys(np.array([3]))


@pytest.mark.parametrize("block", [1, 2, 5, 64])
def test_sorted_keys_block_by_block(block):
    """The marked rows' order told a block at a time, as of the marked rows taken whole; an unmarked row
    out of order (3 before 2) does not count, a marked one across a block edge does."""
    rng = np.random.default_rng(7)
    a, b = np.array([1, 3, 1, 1, 2, 2, 2, 4]), np.array([0, 0, 1, 2, 0, 5, 7, 1])
    marked = np.array([True, False, True, True, True, True, True, True])
    assert network.sorted_where(marked, a, b, block=block)
    assert not network.sorted_where(np.ones(len(a), dtype=bool), a, b, block=block)
    for _ in range(200):
        where = rng.random(len(a)) < 0.6
        expected = network.sorted_keys(a[where], b[where])
        assert network.sorted_where(where, a, b, block=block) == expected
        x = rng.integers(0, 3, 9)
        assert network.sorted_where(where[:8], x[:8], block=block) == network.sorted_keys(x[:8][where[:8]])


def _unified(run_dir):
    run = load_run(run_dir, ANALYZED_COLUMNS)
    unify(run)
    return run


def _flows(msgs, run, widths) -> list[pd.DataFrame]:
    tick, bound = sampling.tick_s(run), sampling.max_latency_s(run)
    return [fl.message_flow(msgs, tick, bound, window_s=w) for w in widths]


def _same(flows: list[pd.DataFrame]) -> None:
    for other in flows[1:]:
        pd.testing.assert_frame_equal(flows[0], other, check_exact=True)


def test_a_window_edge_at_a_send_or_a_receive_loses_no_match(faulty_run):
    """Window boundaries placed exactly on a send time and on a receive time (w * width == t): the
    message on the edge is matched as over the whole run."""
    run = _unified(faulty_run)
    whole = _flows(run.tables["messages"], run, [np.inf])[0]
    slow = whole[whole["latency_ms"] > 500].iloc[len(whole) // 1000]
    for t in (slow["t_send"], slow["t_recv"]):
        width = t / 3   # the third edge is the send (or receive) time itself
        assert 3 * width == t or (np.floor(t / width) == 3 and 3 * width == pytest.approx(t))
        got = _flows(run.tables["messages"], run, [width])[0]
        pd.testing.assert_frame_equal(whole, got, check_exact=True)
    assert slow["delivered"]


def test_messages_in_flight_longer_than_a_window_and_empty_windows(faulty_run):
    """A width of 5 ms: every 600 ms message is in flight for 120 windows, and four windows in five hold
    no send (sends come on 25 ms ticks)."""
    run = _unified(faulty_run)
    msgs = run.tables["messages"]
    whole, narrow = _flows(msgs, run, [np.inf, 0.005])
    _same([whole, narrow])
    sent = whole["t_send"].to_numpy()
    bins = np.unique(np.floor(sent[np.isfinite(sent)] / 0.005))
    assert len(bins) < 0.5 * (bins[-1] - bins[0])   # most windows are empty
    assert (whole["latency_ms"] > 100 * 5).sum() > 10


def test_one_tick(faulty_run):
    """The message rows of a single tick, and a diagnosis series one grid point long."""
    run = load_run(faulty_run)   # every column: the tick of each message row
    unify(run)
    msgs = run.tables["messages"]
    tick = int(msgs["tick"].median())
    one = msgs[msgs["tick"] == tick].reset_index(drop=True)
    flows = _flows(one, run, [np.inf, 0.001, 0.025])
    _same(flows)
    # sent in the run's only tick, received in none: in flight at its end unless the network dropped it
    only = flows[0]
    assert len(only) and not only["delivered"].any()
    assert only["counted"].any() and (only["lost"] == only["counted"]).all()
    assert only["drop_reason"][only["counted"]].notna().all()
    series = dg.drone_series(run)
    single = dg.Series(series.ticks[:1], series.drones, {k: v[:1] for k, v in series.values.items()},
                       series.step_s)
    pd.testing.assert_frame_equal(dg.scan(single, chunk=1), dg.scan(single, chunk=10), check_exact=True)


@pytest.mark.parametrize("chunk", [1, 2, 3, 4, 5, 7, 64])
def test_the_scan_in_chunks_carries_persistence_across_edges(faulty_run, chunk):
    """Alarms (their start, value, score and end) of the scan in chunks of ``chunk`` grid points equal
    those of one chunk; persistence is 4 points, so runs of flags cross chunk edges and some reach
    their persistence in a later chunk than they began."""
    run = _unified(faulty_run)
    opts = dg.DiagnosisOptions()
    series = dg.drone_series(run, opts)
    whole = dg.scan(series, opts, chunk=len(series.ticks))
    assert opts.persist_points(series.step_s) == 4 and len(whole) >= 2
    got = dg.scan(series, opts, chunk=chunk)
    pd.testing.assert_frame_equal(whole, got, check_exact=True)


def test_a_bad_window_is_refused(monkeypatch):
    for bad in ("0", "-1", "nan", "ten"):
        monkeypatch.setenv(windows.ENV, bad)
        with pytest.raises(ValueError, match=windows.ENV):
            windows.window_s()
    monkeypatch.setenv(windows.ENV, "inf")
    assert windows.window_s() == np.inf
    monkeypatch.delenv(windows.ENV)
    assert windows.window_s() == windows.DEFAULT_WINDOW_S
