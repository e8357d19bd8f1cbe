"""Clock steps: a drone's clock jumping mid-mission is unified in pieces, reported, and its latencies stay
true; a linear drift is still one line."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from swarmbox.analysis import network
from swarmbox.analysis.load import load_run
from swarmbox.analysis.unify import ClockOptions, T, unify
from tests.conftest import run_config

FLIGHT = ("algo=hover", "mission=hover", "algo.params.hover_s=12", "network.latency_ms=1",
          "network.jitter_ms=1")
STEP = ("fault=clock_skew", "fault.onset_s=6", "fault.targets=[2]", "fault.drift_ppm=0")


def true_latencies(run, offsets: tuple[float, ...]) -> pd.DataFrame:
    """Latency of every message with each row put on the true clock: in the simulator a row's local
    time is its tick's time plus its clock's offset, so of the offsets drone 2 had, the true one is the
    one that puts the row within a tick of its tick's time (the others are seconds away)."""
    msgs = run.tables["messages"].copy()
    tick_time = msgs["tick"].to_numpy(dtype="float64") * run.manifest["tick_s"]
    t = msgs["t_s"].to_numpy(dtype="float64")
    cand = np.stack([t - o for o in offsets])
    best = np.take_along_axis(cand, np.abs(cand - tick_time).argmin(axis=0)[None], axis=0)[0]
    msgs[T] = np.where(msgs["node"].to_numpy() == 2, best, t)
    return network.message_flow(msgs, run.manifest["tick_s"])


def _flown(tmp_path, *extra: str):
    manifest = run_config(tmp_path / "run", (*FLIGHT, *extra))
    assert manifest["status"] == "ok", manifest["reason"]
    return load_run(tmp_path / "run")


@pytest.mark.parametrize(("offset_s", "duration"), [(-5.0, None), (5.0, None), (-5.0, 4.0)])
def test_a_clock_step_is_reported_and_latencies_stay_true(tmp_path, offset_s, duration):
    extra = (f"fault.offset_s={offset_s}", f"fault.duration_s={'null' if duration is None else duration}")
    run = _flown(tmp_path, *STEP, *extra)
    truth_run = load_run(tmp_path / "run")
    clocks = unify(run)
    lives = clocks[clocks["node"] == 2].set_index("life")
    jumps = [offset_s] if duration is None else [offset_s, -offset_s]   # the fault's end resynchronises
    assert list(lives.index) == list(range(len(jumps) + 1))
    assert lives["step_s"].iloc[1:].to_numpy() == pytest.approx(jumps, abs=1e-3)
    assert lives["from_u"].iloc[1] == pytest.approx(6.0, abs=0.05)
    assert sum("node 2: clock step" in p for p in run.problems) == len(jumps)
    assert len(clocks[clocks["node"] != 2]) == len(run.nodes) - 1   # the others: one clock each

    got = network.message_flow(run.tables["messages"], run.manifest["tick_s"])
    want = true_latencies(truth_run, (0.0, offset_s))
    keys = ["msg_id", "src", "dst"]
    both = got.merge(want, on=keys, suffixes=("", "_true"))
    two = both[(both["src"] == 2) | (both["dst"] == 2)]
    assert len(two) > 500 and len(both) == len(got)
    assert two["delivered"].equals(two["delivered_true"])
    lat = two[two["delivered"]]
    assert (lat["latency_ms"] >= 0).all()
    assert np.abs(lat["latency_ms"] - lat["latency_ms_true"]).max() < 1.0


def test_without_step_detection_the_jump_is_fitted_as_one_line(tmp_path):
    """The failure the detection removes: one line through a 5 s jump skews every latency of the node."""
    run = _flown(tmp_path, *STEP, "fault.offset_s=-5")
    clocks = unify(run, ClockOptions(step_min_s=0))
    assert (clocks["node"] == 2).sum() == 1 and abs(clocks.set_index("node").loc[2, "drift_ppm"]) > 1e4
    lat = network.message_flow(run.tables["messages"])
    assert (lat["latency_ms"].abs() > 100).any()   # skewed by seconds


def test_a_linear_drift_is_still_one_line(tmp_path):
    run = _flown(tmp_path, "run.clocks={drone_2: {offset_s: 0.5, drift_ppm: 1000}}")
    clocks = unify(run).set_index("node")
    assert (clocks["life"] == 0).all() and not any("clock step" in p for p in run.problems)
    assert clocks.loc[2, "offset_s"] == pytest.approx(0.5, abs=1e-3)
    assert clocks.loc[2, "drift_ppm"] == pytest.approx(1000, rel=0.01)


def test_a_stall_against_the_ticks_alone_is_not_a_step(tmp_path):
    """A real-time node that falls 0.2 s behind its ticks moves its local time against its tick count,
    not its clock against the others': the messages do not confirm a step, and none is reported."""
    run = _flown(tmp_path)
    state = run.tables["state"]
    late = (state["node"] == 2) & (state["tick"] >= 400)
    state.loc[late, "tick"] -= 8   # 8 ticks of 25 ms: the residual local - tick time jumps by 0.2 s
    clocks = unify(run)
    assert (clocks["life"] == 0).all() and not any("clock step" in p for p in run.problems)
    assert abs(clocks.set_index("node").loc[2, "offset_s"]) < 1e-3
