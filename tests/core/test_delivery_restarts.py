"""Reliable delivery across restarts (Hypothesis): a chain ground -> leader -> follower over a lossy,
reordering channel, each node's process killed and started again at random instants with the next
incarnation and empty memory (outbox, window), exactly as a node process restarted by hand.

What must hold whatever the schedule:

* an acknowledgement that the sender takes (its incarnation, a number in flight) is for a command
  the receiver had delivered before sending it — never acknowledged-but-undelivered;
* no receiver process delivers a command twice, and each delivers one sender incarnation's commands
  in number order;
* every command a surviving sender process sent after the last restart of its receiver is delivered
  exactly once, or logged undelivered (sender: retries exhausted / receiver lost; receiver: skipped).
"""

from __future__ import annotations

from dataclasses import dataclass, field

from hypothesis import given, settings
from hypothesis import strategies as st

from swarmbox.core.delivery import DELIVERED, NEW, Outbox, Window
from swarmbox.core.messages import TaskCommand

RETRY, MAX_RETRIES, LOST_TICKS, TICKS = 8, 40, 20, 2600
GROUND, LEADER, FOLLOWER = -1, 0, 1
SUPERIOR = {LEADER: GROUND, FOLLOWER: LEADER}


@dataclass
class Proc:
    """One process of a node: what a restart loses."""

    node: int
    incarnation: int
    outbox: Outbox
    window: Window
    delivered: list = field(default_factory=list)     # (src, incarnation, seq), in delivery order


@dataclass
class World:
    drop: list
    delay: list
    k: int = 0
    channel: list = field(default_factory=list)       # (arrival tick, order, dst, kind, payload)
    procs: dict = field(default_factory=dict)         # node -> its live Proc (absent: down)
    history: list = field(default_factory=list)       # every Proc that ever ran
    sent: dict = field(default_factory=dict)          # (src, inc, dst, seq) -> send tick
    taken_acks: list = field(default_factory=list)    # (key, tick) acks the sender took
    delivered_at: dict = field(default_factory=dict)  # key -> first delivery tick
    undelivered: set = field(default_factory=set)     # keys a sender or receiver logged

    def transmit(self, tick: int, dst: int, kind: str, payload) -> None:
        self.k += 1
        if not self.drop[self.k % len(self.drop)]:
            self.channel.append((tick + 1 + self.delay[self.k % len(self.delay)], self.k, dst, kind, payload))


def boot(world: World, node: int, incarnation: int) -> None:
    p = Proc(node, incarnation, Outbox(RETRY, MAX_RETRIES, incarnation), Window(RETRY * (MAX_RETRIES + 2)))
    world.procs[node] = p
    world.history.append(p)


def deliver(world: World, p: Proc, cmds: list, tick: int) -> None:
    for c in cmds:
        key = (c.src, c.incarnation, p.node, c.seq)
        p.delivered.append(key)
        world.delivered_at.setdefault(key, tick)
        world.transmit(tick, c.src, "ack", (p.node, c.seq, c.incarnation))   # only once delivered


def note_skips(world: World, p: Proc) -> None:
    for n in p.window.notes:
        world.undelivered.update((n.src, n.incarnation, p.node, s) for s in range(n.first, n.last + 1))
    p.window.notes.clear()


def receive(world: World, p: Proc, kind: str, payload, tick: int) -> None:
    if kind == "cmd":
        verdict = p.window.accept(payload, tick)
        if verdict is NEW:
            deliver(world, p, p.window.release(payload.src, 2, tick), tick)
        elif verdict is DELIVERED:
            world.transmit(tick, payload.src, "ack", (p.node, payload.seq, payload.incarnation))
    else:
        receiver, seq, inc = payload
        if seq in p.outbox.pending.get(receiver, {}) and p.outbox.acked(receiver, seq, inc):
            world.taken_acks.append(((p.node, inc, receiver, seq), tick))
    note_skips(world, p)


def simulate(sends: dict, outages: list, drop: list, delay: list) -> World:
    """``sends``: sender -> ticks it sends a command at; ``outages``: (node, down tick, up tick)."""
    world = World(drop, delay)
    for node in (GROUND, LEADER, FOLLOWER):
        boot(world, node, 0)
    boots = {GROUND: 0, LEADER: 0, FOLLOWER: 0}
    forgotten: set = set()                            # (sender inc, receiver) declared lost
    for tick in range(TICKS):
        for node, down, up in outages:
            if tick == down and node in world.procs:
                del world.procs[node]                 # kill -9: everything in memory is gone
            elif tick == up and node not in world.procs:
                boots[node] += 1
                boot(world, node, boots[node])
        arrived = sorted(c for c in world.channel if c[0] == tick)
        world.channel[:] = [c for c in world.channel if c[0] > tick]
        for _, _, dst, kind, payload in arrived:
            if dst in world.procs:                    # a message to a dead process is lost
                receive(world, world.procs[dst], kind, payload, tick)
        for p in list(world.procs.values()):
            for src in p.window.holding():
                deliver(world, p, p.window.release(src, 2, tick), tick)
            note_skips(world, p)
        for receiver, sender in SUPERIOR.items():
            p = world.procs.get(sender)
            if p is None:
                continue
            down_long = any(n == receiver and down + LOST_TICKS <= tick < up for n, down, up in outages)
            if down_long and (p.incarnation, receiver) not in forgotten:   # the superior's inferior_lost
                forgotten.add((p.incarnation, receiver))
                dropped = p.outbox.forget(receiver)
                world.undelivered.update((sender, p.incarnation, receiver, s) for s, _ in dropped)
            if not down_long:
                forgotten.discard((p.incarnation, receiver))
            if tick in sends[sender] and not down_long:   # send_task refuses a lost inferior
                seq, floor = p.outbox.number(receiver, True)
                c = TaskCommand(seq, 0.0, sender, receiver, seq, True, seq, None, None, "", 2, floor,
                                p.incarnation)
                world.sent[(sender, p.incarnation, receiver, seq)] = tick
                p.outbox.track(c, tick)
                world.transmit(tick, receiver, "cmd", c)
            resend, gone = p.outbox.due(tick)
            world.undelivered.update((sender, p.incarnation, dst, seq) for dst, seq, _ in gone)
            for c in resend:
                world.transmit(tick, c.dst, "cmd", c._replace(floor=p.outbox.floor(c.dst, c.seq)))
    return world


def last_boot_tick(outages: list, node: int) -> int:
    return max([up for n, _, up in outages if n == node], default=0)


def check(world: World, outages: list) -> None:
    for key, tick in world.taken_acks:
        assert world.delivered_at.get(key, TICKS) <= tick, f"acknowledged but never delivered: {key}"
    for p in world.history:
        assert len(p.delivered) == len(set(p.delivered)), f"node {p.node} delivered twice: {p.delivered}"
        for src_inc in {(s, i) for s, i, _, _ in p.delivered}:
            seqs = [q for s, i, _, q in p.delivered if (s, i) == src_inc]
            assert seqs == sorted(seqs), f"node {p.node}: out of order from {src_inc}: {seqs}"
    survivors = {(p.node, p.incarnation) for p in world.procs.values()}
    for key, tick in world.sent.items():
        src, inc, dst, _ = key
        if (src, inc) not in survivors or tick < last_boot_tick(outages, dst):
            continue
        times = sum(key in p.delivered for p in world.history)
        assert times == 1 or (times == 0 and key in world.undelivered), \
            f"sent after the restarts, delivered {times} times, not logged undelivered: {key}"


@settings(max_examples=50, deadline=None)
@given(sends=st.fixed_dictionaries({GROUND: st.sets(st.integers(0, 1700), max_size=40),
                                    LEADER: st.sets(st.integers(0, 1700), max_size=40)}),
       outages=st.lists(st.tuples(st.sampled_from([GROUND, LEADER, FOLLOWER]), st.integers(1, 1400),
                                  st.integers(1, 200)).map(lambda t: (t[0], t[1], t[1] + t[2])),
                        max_size=4),
       drop=st.lists(st.booleans(), min_size=1, max_size=40).filter(lambda d: not all(d)),
       delay=st.lists(st.integers(0, 25), min_size=1, max_size=20))
def test_restarts_never_leave_a_task_acknowledged_but_undelivered(sends, outages, drop, delay):
    world = simulate(sends, outages, drop, delay)
    check(world, outages)


def test_a_restarted_sender_numbering_from_one_again_is_delivered_not_taken_for_duplicates():
    """The bug this guards: the ground restarts and numbers from 1 again; without incarnations the
    leader's window took 1..3 for copies of what it had delivered, acked them and dropped them."""
    sends = {GROUND: {10, 11, 12, 600, 601, 602}, LEADER: set()}
    world = simulate(sends, [(GROUND, 300, 320)], drop=[False], delay=[0])
    leader = [p for p in world.history if p.node == LEADER][0]
    assert leader.delivered == [(GROUND, 0, LEADER, s) for s in (1, 2, 3)] + \
        [(GROUND, 1, LEADER, s) for s in (1, 2, 3)]
    check(world, [(GROUND, 300, 320)])


def test_a_restarted_receiver_gets_what_its_earlier_process_held_unacknowledged():
    """The follower holds 2 (1 is lost once) and dies before 1's re-sent copy arrives; nothing was
    acknowledged, so the leader re-sends both and the new process delivers 1 and 2 once each."""
    drop = [False, True] + [False] * 400                 # transmission 1 (the first copy of 1) is lost
    sends = {GROUND: set(), LEADER: {1, 2}}
    world = simulate(sends, [(FOLLOWER, 4, 6)], drop=drop, delay=[0])   # 2 arrives (held) at tick 3
    follower = [p for p in world.history if p.node == FOLLOWER]
    assert [p.delivered for p in follower] == [[], [(LEADER, 0, FOLLOWER, 1), (LEADER, 0, FOLLOWER, 2)]]
    assert not world.undelivered
    check(world, [(FOLLOWER, 4, 6)])
