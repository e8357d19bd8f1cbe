"""The message flow equals a plain pandas computation, row for row, on runs with loss and latency and
on messy hand-made logs.

``reference_flow`` is the pandas merge the analyzer used before the matching moved to arrays, with the
time rule written out per send: a receive (or drop) belongs to a send of its (msg_id, dst) only from
``SLACK_S`` before the send until ``SLACK_S`` before the next later send with the same key, and at
most ``max_latency_s`` after it.
"""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from swarmbox.analysis import flow, network
from swarmbox.analysis.load import NET, load_run
from swarmbox.analysis.unify import T, unify

_LAT = "latency_ms"
KEY = ["msg_id", "dst"]


def _in_window(sends: pd.DataFrame, events: pd.DataFrame, max_latency_s: float) -> pd.DataFrame:
    """Every (send, event) pair of the same key where the event is in the send's window (a send with no
    time: every event of its key), with the send's row number ``row``."""
    def later(t: pd.Series) -> list[float]:
        return [min((u for u in t if u > x), default=np.inf) for x in t]
    nxt = sends.groupby(KEY)["t_send"].transform(later) if len(sends) else sends["t_send"]
    pairs = sends.assign(row=np.arange(len(sends)), nxt=nxt.to_numpy()).merge(events, on=KEY)
    slack = flow.SLACK_S
    inside = ((pairs["t_e"] >= pairs["t_send"] - slack) & (pairs["t_e"] < pairs["nxt"] - slack)
              & (pairs["t_e"] - pairs["t_send"] <= max_latency_s))
    return pairs[inside | pairs["t_send"].isna()]


def reference_flow(messages: pd.DataFrame, tick_s: float = 0.0,
                   max_latency_s: float = np.inf) -> pd.DataFrame:
    sends = messages[messages["kind"] == "send"]
    out = pd.DataFrame({
        "msg_id": sends["msg_id"].astype("int64"), "type": sends["type"].astype("str"),
        "src": sends["src"].astype("int64"), "dst": sends["dst"].astype("int64"),
        "nbytes": sends["nbytes"].astype("float64"), "t_send": sends[T],
    })
    recvs = messages[(messages["kind"] == "recv") & messages[T].notna()]
    recvs = pd.DataFrame({"msg_id": recvs["msg_id"].astype("int64"), "dst": recvs["node"].astype("int64"),
                          "t_e": recvs[T]})
    got = _in_window(out, recvs, max_latency_s).groupby("row")["t_e"].min()
    drops = messages[messages["kind"] == "drop"]
    drops = pd.DataFrame({"msg_id": drops["msg_id"].astype("int64"), "dst": drops["dst"].astype("int64"),
                          "drop_reason": drops["reason"].astype("str"), "t_e": drops[T],
                          "logged": np.arange(len(drops))})
    dropped = _in_window(out, drops, max_latency_s).sort_values(["t_e", "logged"]).groupby("row").first()
    rows = pd.RangeIndex(len(out))
    out["t_recv"] = got.reindex(rows).to_numpy()
    reason = dropped["drop_reason"].reindex(rows).to_numpy()
    out["drop_reason"] = pd.Series(reason, index=out.index, dtype="str")
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


def _messy_messages(seed: int, id_base: int = 1 << 40, text: str = "category") -> pd.DataFrame:
    """Sends (a few repeated, a few without a time) from 4 logged nodes and to an unlogged one, receives
    repeated with other times, late or without a time, and repeated network drops with different
    reasons; rows in no particular order."""
    rng = np.random.default_rng(seed)
    n = 400
    src = rng.integers(0, 4, n)
    dst = (src + rng.integers(1, 4, n)) % 4
    dst[rng.random(n) < 0.05] = 9                                   # a destination that logs nothing
    msg_id = id_base * (src + 1) + rng.permutation(n)
    t_send = np.round(rng.uniform(0, 10, n) / 0.025) * 0.025         # ticks: many equal send times
    t_send[rng.random(n) < 0.03] = np.nan
    sends = pd.DataFrame({"kind": "send", "msg_id": msg_id, "node": src, "src": src, "dst": dst, T: t_send})
    sends = pd.concat([sends, sends.sample(10, random_state=seed)])   # the same send logged twice
    got = sends[(rng.random(len(sends)) < 0.8) & (sends["dst"] != 9)]
    recvs = got.assign(kind="recv", node=got["dst"], **{T: got[T] + rng.uniform(0.001, 0.2, len(got))})
    again = recvs.sample(60, random_state=seed + 1)                 # re-delivered copies, earlier or later
    again = again.assign(**{T: again[T] + rng.uniform(-0.1, 0.5, len(again))})
    blind = recvs.sample(10, random_state=seed + 2).assign(**{T: np.nan})
    missed = sends[~sends.index.isin(got.index)].drop_duplicates(["msg_id", "dst"])
    drops = missed.sample(frac=0.7, random_state=seed).assign(kind="drop", node=NET, reason="loss")
    twice = drops.sample(frac=0.3, random_state=seed).assign(reason="queue")
    msgs = pd.concat([sends, recvs, again, blind, drops, twice], ignore_index=True)
    msgs = msgs.sample(frac=1.0, random_state=seed).reset_index(drop=True)
    msgs["type"] = rng.choice(["report", "heartbeat", "task"], len(msgs))
    msgs["reason"] = msgs["reason"].fillna("")
    msgs["nbytes"] = rng.integers(10, 200, len(msgs)).astype("int32")
    for col in ("node", "src", "dst"):
        msgs[col] = msgs[col].astype("int16")
    for col in ("kind", "type", "reason"):
        msgs[col] = msgs[col].astype(text)
    return msgs


@pytest.mark.parametrize("seed", range(6))
def test_messy_logs_equal_the_reference(seed):
    msgs = _messy_messages(seed)
    got = _same(msgs, 0.025)
    assert got["lost"].any() and got["drop_reason"].eq("loss").any() and got["drop_reason"].eq("queue").any()
    assert (~got["counted"]).any() and got["t_send"].isna().any()


@pytest.mark.parametrize("text", ["str", "category"])
def test_text_columns_and_far_apart_ids(text):
    """Text as plain strings or categoricals; message ids too far apart to pack with the node as they are."""
    _same(_messy_messages(7, text=text), 0.025)
    far = _same(_messy_messages(8, id_base=1 << 61), 0.0)
    assert far["msg_id"].max() > 1 << 62 and far["delivered"].any()
    _same(_messy_messages(9, id_base=-(1 << 61)), 0.0)


@pytest.mark.parametrize(("a_scale", "b_scale"), [(1, 1), (1 << 60, 1), (1, 1 << 61), (1 << 60, 1 << 61)])
def test_pair_keys_are_exact_and_ordered(a_scale, b_scale):
    """Equal keys exactly for equal pairs, ordered by (a, b), across the arrays, near int64's limits too."""
    rng = np.random.default_rng(0)
    a, b = rng.integers(-6, 6, 500) * a_scale, rng.integers(-3, 4, 500) * b_scale
    keys = np.concatenate(flow.pair_keys([(a[:200], b[:200]), (a[200:], b[200:]), (a[:0], b[:0])]))
    np.testing.assert_array_equal(np.argsort(keys, kind="stable"), np.lexsort((b, a)))
    assert len(np.unique(keys)) == len(set(zip(a.tolist(), b.tolist(), strict=True)))


def test_unknown_ids_match_nothing():
    """A row whose msg_id or destination is unknown (NaN) is never matched; its send stays, as NaN."""
    rows = [("send", 1.0, 0, 1, 0.0), ("recv", 1.0, 1, 1, 0.01), ("send", np.nan, 0, 1, 0.1),
            ("recv", np.nan, 1, 1, 0.11), ("send", 3.0, 0, np.nan, 0.2), ("recv", 3.0, 1, 1, 0.21)]
    msgs = pd.DataFrame([{"kind": k, "msg_id": m, "node": n, "dst": d, T: t, "type": "report", "src": 0,
                          "nbytes": 10, "reason": ""} for k, m, n, d, t in rows])
    msgs["node"] = msgs["node"].astype("int16")
    got = flow.message_flow(msgs, 0.0)
    assert got["msg_id"].dtype == "float64" and got["dst"].dtype == "float64"
    assert got["delivered"].tolist() == [True, False, False]
    assert got["counted"].tolist() == [True, True, False]   # no destination: nothing can be said


def test_network_module_uses_the_array_flow(make_run):
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


@pytest.mark.parametrize("seed", range(3))
def test_a_table_without_type_gives_the_flow_without_it(seed):
    """The scalars-only load leaves the type out; every other column is the same."""
    msgs = _messy_messages(seed)
    full = flow.message_flow(msgs, 0.025)
    got = flow.message_flow(msgs.drop(columns="type"), 0.025)
    pd.testing.assert_frame_equal(got, full.drop(columns="type"), check_exact=True)


def _two_lives() -> pd.DataFrame:
    """Drone 1 reports to the ground, ids 0..9 from 1 s; it restarts and numbers 0..9 again from 20 s.
    Every report arrives 2 ms later except id 3 of the second life; id 50, sent at 30 s, is logged as
    received 5 s later; the ground's last message at 40 s ends the run."""
    rows = []
    for life, start in enumerate((1.0, 20.0)):
        for k in range(10):
            t = start + 0.1 * k
            rows.append(("send", k, 1, -1, t))
            if (life, k) != (1, 3):
                rows.append(("recv", k, -1, -1, t + 0.002))
    rows += [("send", 50, 1, -1, 30.0), ("recv", 50, -1, -1, 35.0), ("send", 900, -1, 1, 40.0),
             ("recv", 900, 1, 1, 40.001)]
    msgs = pd.DataFrame([{"kind": k, "msg_id": m, "node": n, "dst": d, T: t, "type": "report",
                          "src": 1 if d == -1 else -1, "nbytes": 10, "reason": ""} for k, m, n, d, t in rows])
    msgs["node"] = msgs["node"].astype("int16")
    return msgs


def test_a_restarted_node_s_repeated_ids_match_by_time():
    """A receive matches only a send before it: the report lost after the restart comes out lost (the old
    key-only match gave it the first life's arrival, -18,998 ms), and no latency is negative."""
    msgs = _two_lives()
    got = flow.message_flow(msgs, 0.025, max_latency_s=2.0)
    pd.testing.assert_frame_equal(got, reference_flow(msgs, 0.025, max_latency_s=2.0), check_exact=True)
    reports = got[got["msg_id"] < 50]
    assert len(reports) == 20 and reports["counted"].all()
    lost = reports[reports["lost"]]
    assert lost[["msg_id", "t_send"]].values.tolist() == [[3, pytest.approx(20.3)]]
    delivered = reports[reports["delivered"]]
    assert len(delivered) == 19 and np.allclose(delivered[_LAT], 2.0)
    late = got.set_index("msg_id").loc[50]
    assert late["lost"] and not late["delivered"]            # 5 s: beyond the 2 s bound, not its receive
    assert flow.message_flow(msgs, 0.025).set_index("msg_id").loc[50, "delivered"]   # no bound: matched
    assert (got[_LAT].dropna() >= 0).all()


def test_a_receive_before_its_send_is_not_its_receive():
    rows = [("send", 1, 0, 1, 1.0), ("recv", 1, 1, 1, 0.5), ("send", 2, 0, 1, 1.0), ("recv", 2, 1, 1, 0.998)]
    msgs = pd.DataFrame([{"kind": k, "msg_id": m, "node": n, "dst": d, T: t, "type": "report", "src": 0,
                          "nbytes": 10, "reason": ""} for k, m, n, d, t in rows])
    msgs["node"] = msgs["node"].astype("int16")
    got = flow.message_flow(msgs, 0.0).set_index("msg_id")
    assert not got.loc[1, "delivered"]                         # half a second before: another send's
    assert got.loc[2, "delivered"] and got.loc[2, _LAT] == pytest.approx(-2.0)   # within the slack
