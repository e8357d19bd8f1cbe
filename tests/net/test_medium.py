import numpy as np
import pytest

from swarmbox.core.clock import ClockSpec, NodeClock, TimeSource
from swarmbox.core.messages import TaskAck
from swarmbox.core.rows import unpacking
from swarmbox.net.medium import LinkSpec, SimMedium

TICK = 0.025


class Net:
    """Two nodes (ground -1 and drone 0) on a medium, with their logs."""

    def __init__(self, seed=1, default=LinkSpec(), links=None, drone_clock=ClockSpec()):
        self.time = TimeSource()
        self.drops = []
        self.medium = SimMedium(self.time, np.random.default_rng(seed), default, links, unpacking(self.drops))
        self.logs = {-1: [], 0: []}
        self.inbox = {
            -1: self.medium.register(-1, NodeClock(self.time), unpacking(self.logs[-1])),
            0: self.medium.register(0, NodeClock(self.time, drone_clock), unpacking(self.logs[0])),
        }
        self.seq = 0

    def send(self, src=-1, dst=0):
        self.seq += 1
        self.medium.send(TaskAck(self.seq, self.time.t_s, src, dst, self.seq), dst)

    def tick(self):
        self.time.tick += 1
        self.time.t_s = self.time.tick * TICK
        self.medium.deliver_due()


def test_ideal_link_delivers_next_tick_with_zero_latency():
    net = Net()
    net.send()
    net.medium.deliver_due()          # same tick: not yet
    assert net.inbox[0] == []
    net.tick()
    assert len(net.inbox[0]) == 1
    send, recv = net.logs[-1][0], net.logs[0][0]
    assert send[2] == "send" and recv[2] == "recv" and recv[0] - send[0] == 0.0


def test_latency_below_one_tick_is_stamped_at_arrival():
    net = Net(default=LinkSpec(latency_s=0.020))
    net.tick()
    net.send()
    net.tick()
    recv = net.logs[0][0]
    assert recv[0] - recv[8] == pytest.approx(0.020, abs=1e-9)


def test_latency_longer_than_a_tick_waits_for_arrival():
    net = Net(default=LinkSpec(latency_s=0.060))
    net.send()
    delivered_at = None
    for _ in range(5):
        net.tick()
        if net.inbox[0] and delivered_at is None:
            delivered_at = net.time.t_s
    assert delivered_at == pytest.approx(0.075)   # first tick at or after 0.060


def test_receiver_clock_offset_appears_in_recv_rows():
    net = Net(drone_clock=ClockSpec(offset_s=1.5))
    net.send()
    net.tick()
    assert net.logs[0][0][0] - net.logs[-1][0][0] == pytest.approx(1.5)


def test_bernoulli_loss_ratio_and_replay():
    def dropped(seed):
        net = Net(seed=seed, default=LinkSpec(loss_prob=0.3))
        for _ in range(20_000):
            net.send()
        return [row[3] for row in net.drops]

    a, b, c = dropped(7), dropped(7), dropped(8)
    assert len(a) / 20_000 == pytest.approx(0.3, abs=0.02)
    assert a == b and a != c


def test_per_link_override_only_affects_that_link():
    net = Net(links={(0, -1): LinkSpec(loss_prob=1.0)})
    net.send(-1, 0)
    net.send(0, -1)
    assert [(r[5], r[6]) for r in net.drops] == [(0, -1)]


def test_disconnected_node_neither_sends_nor_receives():
    net = Net()
    net.medium.disconnect(0)
    net.send(0, -1)
    net.send(-1, 0)
    net.tick()
    assert net.logs[0] == [] and [r[9] for r in net.drops] == ["unreachable"]


def test_invalid_link_spec_is_refused():
    with pytest.raises(ValueError, match="loss_prob"):
        LinkSpec(loss_prob=1.5)
    with pytest.raises(ValueError, match="latency"):
        LinkSpec(latency_s=-0.1)
