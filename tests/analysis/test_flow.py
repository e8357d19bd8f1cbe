"""The Arrow message flow equals the former pandas merge, row for row, on runs with loss and latency.

``reference_flow`` is the pandas implementation the analyzer used before the matching moved to Arrow,
kept here verbatim as the oracle.
"""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from swarmbox.analysis import flow, network
from swarmbox.analysis.load import NET, load_run
from swarmbox.analysis.unify import T, unify

_LAT = "latency_ms"


def reference_flow(messages: pd.DataFrame, tick_s: float = 0.0) -> pd.DataFrame:
    sends = messages[messages["kind"] == "send"]
    out = pd.DataFrame({
        "msg_id": sends["msg_id"].astype("int64"), "type": sends["type"].astype("str"),
        "src": sends["src"].astype("int64"), "dst": sends["dst"].astype("int64"),
        "nbytes": sends["nbytes"].astype("float64"), "t_send": sends[T],
    })
    recvs = messages[messages["kind"] == "recv"]
    recvs = pd.DataFrame({"msg_id": recvs["msg_id"].astype("int64"), "dst": recvs["node"].astype("int64"),
                          "t_recv": recvs[T]})
    recvs = recvs.sort_values("t_recv").drop_duplicates(["msg_id", "dst"])
    drops = messages[messages["kind"] == "drop"]
    drops = pd.DataFrame({"msg_id": drops["msg_id"].astype("int64"), "dst": drops["dst"].astype("int64"),
                          "drop_reason": drops["reason"].astype("str")}).drop_duplicates(["msg_id", "dst"])
    out = out.merge(recvs, on=["msg_id", "dst"], how="left").merge(drops, on=["msg_id", "dst"], how="left")
    out[_LAT] = (out["t_recv"] - out["t_send"]) * 1e3
    out["delivered"] = out["t_recv"].notna()
    logged = set(messages.loc[messages["node"] != NET, "node"].astype("int64").unique())
    t_end = float(messages[T].max()) if len(messages) else np.nan
    max_lat = out.groupby(["src", "dst"])[_LAT].transform("max").fillna(0.0) / 1e3
    late = out["t_send"] > t_end - max_lat - (tick_s if np.isfinite(tick_s) else 0.0)
    in_flight = ~out["delivered"] & out["drop_reason"].isna() & late
    out["counted"] = out["dst"].isin(logged) & ~in_flight
    out["lost"] = out["counted"] & ~out["delivered"]
    return out.sort_values(["t_send", "msg_id", "dst"]).reset_index(drop=True)


def _same(messages: pd.DataFrame, tick_s: float) -> pd.DataFrame:
    new = flow.message_flow(messages, tick_s)
    pd.testing.assert_frame_equal(new, reference_flow(messages, tick_s), check_exact=True)
    return new


def test_synthetic_loss_latency_and_clock_offset(make_run):
    run = load_run(make_run(drop_every={1: 4, 2: 7}, extra_delay_ticks={3: 2},
                            clocks={"drone_2": (0.5, 100.0)}))
    unify(run)
    got = _same(run.tables["messages"], 0.025)
    assert got["lost"].sum() > 100 and (got[_LAT] > 50).sum() > 100   # the case is not trivial
    assert (~got["counted"]).sum() > 0                                  # in-flight messages at the end


def test_real_run_on_a_lossy_network(formation_run):
    run = load_run(formation_run)
    unify(run)
    got = _same(run.tables["messages"], float(run.manifest["tick_s"]))
    assert got["lost"].any() and got["delivered"].mean() > 0.9
    assert got["drop_reason"].notna().any()


def test_duplicates_missing_times_and_unlogged_destinations():
    """A re-delivered copy, a receive without a time, a destination with no log and a repeated drop."""
    rows = [("send", 1, 0, 1, 0.0), ("recv", 1, 1, 1, 0.02), ("recv", 1, 1, 1, 0.01),
            ("send", 2, 0, 1, 0.1), ("recv", 2, 1, 1, np.nan), ("send", 3, 0, 5, 0.2),
            ("send", 4, 1, 0, 0.3), ("drop", 4, NET, 0, 0.3), ("drop", 4, NET, 0, 0.3),
            ("send", 5, 1, 0, 0.3), ("recv", 5, 0, 0, 0.35)]
    msgs = pd.DataFrame([{"kind": k, "msg_id": m, "node": n, "dst": d, T: t, "type": "report", "src": 1 - d,
                          "nbytes": 10, "reason": "loss" if k == "drop" else ""}
                         for k, m, n, d, t in rows])
    msgs["node"] = msgs["node"].astype("int16")
    got = _same(msgs, 0.025)
    assert got.set_index("msg_id").loc[1, _LAT] == pytest.approx(10.0)
    assert _same(msgs.iloc[:0], 0.025).empty


def test_network_module_uses_the_arrow_flow(make_run):
    run = load_run(make_run(drop_every={1: 4}))
    unify(run)
    pd.testing.assert_frame_equal(network.message_flow(run.tables["messages"], 0.025),
                                  reference_flow(run.tables["messages"], 0.025))




WINDOWS = [(2.0, 17.0), (-1.0, 99.0), (5.0, 4.0), (2.0125, 2.0125), (30.0, 40.0)]


@pytest.mark.parametrize(("t0", "t1"), WINDOWS)
def test_between_is_the_send_time_window(make_run, t0, t1):
    run = load_run(make_run(drop_every={1: 4}, extra_delay_ticks={3: 2}))
    unify(run)
    got = flow.message_flow(run.tables["messages"], 0.025)
    got.loc[got.index[-3:], "t_send"] = np.nan    # unknown send times sort last and are never inside
    expected = got[(got["t_send"] >= t0) & (got["t_send"] <= t1)]
    pd.testing.assert_frame_equal(network.between(got, t0, t1), expected)
    shuffled = got.sample(frac=1.0, random_state=0)   # not sorted: filtered, same rows
    pd.testing.assert_frame_equal(network.between(shuffled, t0, t1),
                                  shuffled[(shuffled["t_send"] >= t0) & (shuffled["t_send"] <= t1)])
