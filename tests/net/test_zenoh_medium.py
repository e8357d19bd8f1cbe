"""Two nodes over real Zenoh sessions on 127.0.0.1: delivery, logging, link faults, rejected frames."""

from __future__ import annotations

import time

import numpy as np
import pytest
import zenoh

from swarmbox.core.clock import NodeClock, TimeSource
from swarmbox.core.messages import Heartbeat, TaskAck, TaskCommand
from swarmbox.core.rows import unpacking
from swarmbox.net.auth import AuthSpec, Signer
from swarmbox.net.codec import encode
from swarmbox.net.medium import LinkSpec
from swarmbox.net.zenoh_medium import ZenohMedium, session_config
from swarmbox.run.processes import free_ports

KEY = b"k" * 32


def _node(node_id, locators, mission, default=LinkSpec()):
    time_src, rows = TimeSource(), []
    me = locators[node_id]
    medium = ZenohMedium(node_id, time=time_src, true_of=lambda w: w - 0.0, auth=AuthSpec(KEY, mission),
                         listen=me, peers=[v for k, v in locators.items() if k != node_id],
                         rng=np.random.default_rng(0), default=default, subscribers={-1: [0]})
    medium.register(node_id, NodeClock(time_src), unpacking(rows))
    return medium, time_src, rows


def _pump(medium, time_src, until, timeout_s=20.0):
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        time_src.t_s = time.time()
        medium.deliver_due()
        if until():
            return True
        time.sleep(0.02)
    return False


@pytest.fixture
def pair(request):
    ports = free_ports(2)
    locators = {-1: f"tcp/127.0.0.1:{ports[0]}", 0: f"tcp/127.0.0.1:{ports[1]}"}
    mission = f"t{ports[0]}"
    default = getattr(request, "param", LinkSpec())
    ground, drone = _node(-1, locators, mission), _node(0, locators, mission, default)
    drone[0].subscribe(0, -1)
    yield ground, drone, locators, mission
    ground[0].close()
    drone[0].close()


def _heartbeat(i):
    return Heartbeat(i, float(i), -1, 1, (), (0.0, 0.0, -1.0), (0.0, 0.0, 0.0))


def test_heartbeats_and_direct_messages_arrive_logged(pair):
    (g, g_time, g_rows), (d, d_time, d_rows), _, _ = pair
    # sessions connect asynchronously: publish until the drone hears one Heartbeat
    for i in range(1, 200):
        g.publish(_heartbeat(i))
        if _pump(d, d_time, lambda: d.inbox, timeout_s=0.1):
            break
    assert d.inbox and type(d.inbox[0]) is Heartbeat
    assert [r[2] for r in g_rows if r[3] == d.inbox[0].msg_id] == ["send"]
    recv = [r for r in d_rows if r[2] == "recv"]
    assert recv and recv[0][5:8] == (-1, 0, len(encode(_heartbeat(1))) + 41)   # frame = message + envelope
    d.send(TaskAck(900, 5.0, 0, -1, 4), -1)
    assert _pump(g, g_time, lambda: g.inbox)
    assert g.inbox[-1] == TaskAck(900, 5.0, 0, -1, 4)


@pytest.mark.parametrize("pair", [LinkSpec(loss_prob=1.0)], indirect=True)
def test_link_loss_applies_at_the_receiver(pair):
    (g, _, _), (d, d_time, d_rows), _, _ = pair
    for i in range(1, 200):
        g.publish(_heartbeat(i))
        if _pump(d, d_time, lambda: any(r[2] == "drop" for r in d_rows), timeout_s=0.1):
            break
    assert not d.inbox
    assert {r[9] for r in d_rows if r[2] == "drop"} == {"loss"}


def test_intruder_frames_are_dropped_with_their_reason(pair):
    (g, _, _), (d, d_time, d_rows), locators, mission = pair
    for i in range(1, 200):                              # wait until the link is up
        g.publish(_heartbeat(i))
        if _pump(d, d_time, lambda: d.inbox, timeout_s=0.1):
            break
    d.inbox.clear()
    reject_before = len([r for r in d_rows if r[2] == "drop"])
    port = free_ports(1)[0]
    intruder = zenoh.open(session_config(f"tcp/127.0.0.1:{port}", list(locators.values())))
    try:
        key = f"swarmbox/{mission}/hb/-1"
        pub = intruder.declare_publisher(key)
        genuine = Signer(AuthSpec(KEY, mission), -1).sign(encode(_heartbeat(500)), key)
        forged = Signer(AuthSpec(b"x" * 32, mission), -1).sign(encode(_heartbeat(501)), key)
        spoofed = Signer(AuthSpec(KEY, mission), 7).sign(encode(_heartbeat(502)), key)   # 7 claims src -1
        time.sleep(1.0)
        for frame in (encode(_heartbeat(503)), forged, spoofed, genuine, genuine):
            pub.put(frame)
        want = {"unsigned", "forged", "replayed"}
        assert _pump(d, d_time, lambda: want <= {r[9] for r in d_rows[reject_before:] if r[2] == "drop"})
    finally:
        intruder.close()
    assert [m.msg_id for m in d.inbox] == [500]           # only the genuine frame, once


def test_a_task_for_one_drone_replayed_to_another_is_refused():
    """The ground's task for drone 3, captured on the wire and replayed to drone 5 within the age bound,
    must not reach drone 5 (it was signed for drone 3's key expression); nor may a frame that a key
    holder signed for drone 5's key but addressed inside to drone 3 (``misdirected``)."""
    ports = free_ports(3)
    locators = {i: f"tcp/127.0.0.1:{p}" for i, p in zip((-1, 3, 5), ports, strict=True)}
    mission = f"t{ports[0]}"
    (g, _, _), (d3, t3, _), (d5, t5, rows5) = (_node(i, locators, mission) for i in (-1, 3, 5))
    port = free_ports(1)[0]
    spy = zenoh.open(session_config(f"tcp/127.0.0.1:{port}", list(locators.values())))
    captured: list[bytes] = []
    sub = spy.declare_subscriber(f"swarmbox/{mission}/to/3",
                                 lambda sample: captured.append(bytes(sample.payload.to_bytes())))
    to_5 = spy.declare_publisher(f"swarmbox/{mission}/to/5")
    try:
        task = TaskCommand(77, 1.0, -1, 3, 1, True, 4, (1.0, 2.0, -3.0), None, "go", 2, 1, 0)
        for _ in range(200):                                   # until the sessions are connected
            g.send(task, 3)
            if _pump(d3, t3, lambda: d3.inbox and captured, timeout_s=0.1):
                break
        assert d3.inbox[-1] == task and captured
        to_5.put(captured[-1])                                # the genuine frame, replayed to drone 5
        insider = Signer(AuthSpec(KEY, mission), -1).sign(encode(task._replace(msg_id=78)),
                                                          f"swarmbox/{mission}/to/5")
        to_5.put(insider)                                     # signed for drone 5, addressed to drone 3
        assert _pump(d5, t5, lambda: len([r for r in rows5 if r[2] == "drop"]) >= 2)
    finally:
        sub.undeclare()
        spy.close()
        for m in (g, d3, d5):
            m.close()
    assert d5.inbox == []
    assert sorted(r[9] for r in rows5 if r[2] == "drop") == ["forged", "misdirected"]
