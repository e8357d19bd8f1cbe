"""Latency, loss, bytes/s and connectivity against hand-computed values.

Default scenario: 4 drones, ground Heartbeat to each drone and one Report per drone per tick,
1-tick (25 ms) delay. EXECUTION runs from tick 80 to tick 680 (2.0 s to 17.0 s), so 601 messages per
link are sent in it.
"""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from swarmbox.analysis import network
from swarmbox.analysis.load import load_run
from swarmbox.analysis.report import analyze_run
from swarmbox.analysis.unify import unify

PER_LINK = 601          # ticks 80..680
LOST_1 = 150            # Reports of drone 1 at ticks t in [80, 680] with (t + 1) % 4 == 0


@pytest.fixture
def lossy(make_run):
    return analyze_run(make_run(drop_every={1: 4}, extra_delay_ticks={3: 2}))


def test_link_loss_and_latency(lossy):
    links = lossy.links.set_index(["src", "dst"])
    assert links.loc[(1, -1), "sent"] == PER_LINK
    assert links.loc[(1, -1), "lost"] == LOST_1
    assert links.loc[(1, -1), "loss_ratio"] == pytest.approx(LOST_1 / PER_LINK)
    assert links.loc[(-1, 1), "loss_ratio"] == 0.0
    assert links.loc[(0, -1), "latency_ms_mean"] == pytest.approx(25.0)
    assert links.loc[(-1, 3), "latency_ms_p95"] == pytest.approx(75.0)
    assert links.loc[(3, -1), "latency_ms_max"] == pytest.approx(75.0)
    assert links.loc[(0, -1), "bytes_per_s"] == pytest.approx(PER_LINK * 100 / 15.0)


def test_agent_and_run_level_network(lossy):
    drones = lossy.drones.set_index("drone")
    assert drones.loc[1, "loss_ratio"] == pytest.approx(LOST_1 / (2 * PER_LINK))
    assert drones.loc[3, "latency_ms_mean"] == pytest.approx(75.0)
    assert drones.loc[0, "tx_bytes_per_s"] == pytest.approx(PER_LINK * 100 / 15.0)
    assert drones.loc[0, "rx_bytes_per_s"] == pytest.approx(PER_LINK * 50 / 15.0)
    s = lossy.scalars
    assert s["loss_ratio"] == pytest.approx(LOST_1 / (8 * PER_LINK))
    delivered_25 = 5 * PER_LINK + (PER_LINK - LOST_1)
    expected = (25 * delivered_25 + 75 * 2 * PER_LINK) / (delivered_25 + 2 * PER_LINK)
    assert s["latency_ms_mean"] == pytest.approx(expected)
    assert s["latency_ms_max"] == pytest.approx(75.0)
    assert s["tx_bytes_per_s_mean"] == pytest.approx(PER_LINK * 100 / 15.0)   # drones only: all equal


def test_in_flight_messages_are_not_lost(lossy):
    flow = lossy.flow
    assert flow["lost"].sum() == flow["drop_reason"].notna().sum()   # only the dropped ones
    # in flight: the 8 messages of the last tick (but drone 1's dropped Report), and the messages of
    # the two ticks before on drone 3's 75 ms links
    assert (~flow["counted"]).sum() == (8 - 1) + 2 * 2


def test_last_tick_of_a_zero_latency_link_is_in_flight():
    """Arrival time = send time, but the receive is logged one tick later: a send in the last tick
    is in flight, not lost."""
    rows = [("send", 1, 0, 0.0, 0.0), ("recv", 1, 1, 0.0, 0.0), ("send", 2, 0, 1.0, 1.0)]
    msgs = pd.DataFrame([{"kind": k, "msg_id": m, "node": n, "t_u": t, "t_sent_s": ts, "type": "report",
                          "src": 0, "dst": 1, "nbytes": 10, "reason": ""} for k, m, n, t, ts in rows])
    assert not network.message_flow(msgs, tick_s=0.025)["lost"].any()
    assert network.message_flow(msgs, tick_s=0.0)["lost"].tolist() == [False, True]


def test_latency_uses_the_unified_clock(make_run):
    run = load_run(make_run(clocks={"drone_2": (0.5, 100.0)}))
    unify(run)
    flow = network.message_flow(run.tables["messages"])
    lat = flow.loc[flow["delivered"] & ((flow["src"] == 2) | (flow["dst"] == 2)), "latency_ms"]
    assert np.abs(lat - 25.0).max() < 0.01


@pytest.mark.parametrize(("edges", "expected"), [
    ({(0, 1), (1, 2)}, 1.0),              # path of three nodes
    ({(0, 1), (1, 2), (0, 2)}, 3.0),      # triangle
    ({(0, 1)}, 0.0),                      # node 2 isolated
])
def test_algebraic_connectivity(edges, expected):
    assert network.algebraic_connectivity([0, 1, 2], edges) == pytest.approx(expected)


def test_star_connectivity_timeline(lossy):
    conn = lossy.connectivity
    assert conn["connectivity"].iloc[1:-1].to_numpy() == pytest.approx(1.0)   # star K(1,4)
    assert lossy.scalars["connectivity_min"] == pytest.approx(1.0)
