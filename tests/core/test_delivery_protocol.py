"""Reliable task delivery, unit by unit and as a property (Hypothesis) over a simulated channel:
whatever is lost, delayed, reordered or cut off, the receiver hands each command to its algorithm at
most once, in send order, never before its stage; everything not abandoned by the sender arrives.
With restarts (tests/core/test_delivery_restarts.py): never acknowledged unless delivered."""

from hypothesis import given, settings
from hypothesis import strategies as st

from swarmbox.core.delivery import DELIVERED, HELD, NEW, SKIPPED, STALE, Outbox, Window
from swarmbox.core.messages import TaskCommand

RETRY, MAX_RETRIES = 8, 40


def cmd(seq, floor=0, stage=2, src=-1, reliable=True, inc=0):
    return TaskCommand(seq, 0.0, src, 0, seq, reliable, seq, None, None, "", stage, floor, inc)


def test_duplicates_are_suppressed_and_gaps_hold_later_commands():
    w = Window(give_up_ticks=1000)
    assert w.accept(cmd(2), 0) is NEW and w.release(-1, 2, 0) == []   # 1 missing: 2 is held
    assert w.accept(cmd(2), 1) is HELD                                # a re-sent copy: not acked yet
    assert w.accept(cmd(1), 2) is NEW
    assert [c.seq for c in w.release(-1, 2, 2)] == [1, 2]
    assert w.accept(cmd(1), 3) is DELIVERED and w.accept(cmd(2), 3) is DELIVERED   # acked again
    assert w.notes == []


def test_floor_jump_keeps_held_commands_numbered_below_the_new_floor():
    """1 is missing, 2 and 3 are held; a copy of 5 says the sender's floor is now 4 (1 was given up,
    2 and 3 were abandoned or acknowledged elsewhere). 2 and 3 are here: they must be delivered, and
    only 1 is skipped."""
    w = Window(give_up_ticks=1000)
    for seq in (2, 3):
        assert w.accept(cmd(seq, floor=1), 0) is NEW
    assert w.release(-1, 2, 0) == []
    assert w.accept(cmd(5, floor=4), 1) is NEW
    assert [c.seq for c in w.release(-1, 2, 1)] == [2, 3]           # 5 waits for 4, still in flight
    assert [(n.first, n.last, n.reason) for n in w.notes] == [(1, 1, "the sender gave it up")]
    assert w.accept(cmd(4, floor=4), 2) is NEW
    assert [c.seq for c in w.release(-1, 2, 2)] == [4, 5]


def test_give_up_timer_runs_from_the_oldest_held_arrival():
    """3 arrives at tick 0 and 5 at tick 90, with 1, 2 and 4 missing: 3 has waited longer than the
    sender's whole retry schedule at tick 101 (counted from 3's arrival, not from 5's)."""
    w = Window(give_up_ticks=100)
    w.accept(cmd(3, floor=1), 0)
    w.accept(cmd(5, floor=1), 90)
    assert w.release(-1, 2, 100) == []
    assert [c.seq for c in w.release(-1, 2, 101)] == [3]             # 4's gap: open since tick 90 only
    assert [(n.first, n.last) for n in w.notes] == [(1, 2)]
    assert w.release(-1, 2, 190) == []
    assert [c.seq for c in w.release(-1, 2, 191)] == [5]
    assert [(n.first, n.last) for n in w.notes] == [(1, 2), (4, 4)]


def test_a_late_copy_of_a_skipped_number_is_never_taken_for_delivered():
    w = Window(give_up_ticks=100)
    w.accept(cmd(2, floor=1), 0)
    assert [c.seq for c in w.release(-1, 2, 101)] == [2]              # 1 skipped by the timer
    w.notes.clear()
    assert w.accept(cmd(1, floor=1), 102) is SKIPPED                  # must not be acknowledged
    assert [(n.first, n.reason) for n in w.notes] == [(1, "late copy of a skipped task")]
    assert w.accept(cmd(2, floor=1), 103) is DELIVERED


def test_a_new_incarnation_resets_the_senders_window_and_old_copies_are_refused():
    w = Window(give_up_ticks=1000)
    for seq in (1, 2, 4):
        w.accept(cmd(seq, floor=1, inc=0), 0)
    assert [c.seq for c in w.release(-1, 2, 0)] == [1, 2]               # 4 held, 3 missing
    assert w.accept(cmd(1, floor=1, inc=1), 5) is NEW                 # the sender restarted: from 1
    assert [c.seq for c in w.release(-1, 2, 5)] == [1]
    assert [(n.incarnation, n.first, n.reason) for n in w.notes] == [(0, 4, "the sender restarted")]
    assert w.accept(cmd(3, floor=1, inc=0), 6) is STALE               # the old process's straggler
    assert w.accept(cmd(2, floor=1, inc=1), 6) is NEW
    assert [c.seq for c in w.release(-1, 2, 6)] == [2]


def test_outbox_ignores_acks_of_an_earlier_incarnation_and_forget_returns_the_dropped():
    out = Outbox(retry_ticks=RETRY, max_retries=5, incarnation=3)
    for _ in range(3):
        seq, floor = out.number(0, True)
        out.track(cmd(seq, floor, inc=3)._replace(dst=0), 0)
    assert not out.acked(0, 1, incarnation=2) and 1 in out.pending[0]   # an ack of the old process
    assert out.acked(0, 1, incarnation=3) and 1 not in out.pending[0]
    assert out.forget(0) == [(2, 0), (3, 0)] and not out.busy


def test_a_task_waits_for_its_stage():
    w = Window(give_up_ticks=1000)
    w.accept(cmd(1, stage=3), 0)
    assert w.release(-1, 2, 0) == [] and w.holding() == [-1]
    assert [c.seq for c in w.release(-1, 3, 1)] == [1]


def test_an_abandoned_gap_is_skipped_by_floor_or_by_time():
    w = Window(give_up_ticks=100)
    w.accept(cmd(3, floor=1), 0)
    assert w.release(-1, 2, 0) == []
    w.accept(cmd(4, floor=3), 1)                                    # the sender gave up 1 and 2
    assert [c.seq for c in w.release(-1, 2, 1)] == [3, 4]
    w2 = Window(give_up_ticks=100)
    w2.accept(cmd(2, floor=1), 0)                                   # nothing else will come
    assert w2.release(-1, 2, 100) == []
    assert [c.seq for c in w2.release(-1, 2, 101)] == [2]


def test_outbox_retries_on_schedule_and_gives_up_after_max_retries():
    out = Outbox(retry_ticks=RETRY, max_retries=2)
    seq, floor = out.number(0, True)
    assert (seq, floor) == (1, 1)
    out.track(cmd(1), tick=0)
    assert out.due(RETRY - 1) == ([], [])
    assert [c.seq for c in out.due(RETRY)[0]] == [1]
    assert [c.seq for c in out.due(2 * RETRY)[0]] == [1]
    assert out.due(3 * RETRY) == ([], [(0, 1, 2)])                  # abandoned after 2 retries
    assert out.number(0, True) == (2, 2) and out.number(0, False) == (1, 0)   # streams count apart


def _simulate(n, send_ticks, drop, delay, cut, stage_lag):
    """Sender -> channel -> receiver (and acks back) for up to 3000 ticks; returns what happened."""
    out, win = Outbox(RETRY, MAX_RETRIES), Window(RETRY * (MAX_RETRIES + 2))
    channel: list[tuple[int, str, object]] = []     # (arrival tick, kind, payload)
    k = 0
    delivered, abandoned = [], []
    sent_at: dict[int, int] = {}

    def transmit(tick, kind, payload):
        nonlocal k
        k += 1
        lost = drop[k % len(drop)] or any(a <= tick < b for a, b in cut)
        if not lost:
            channel.append((tick + 1 + delay[k % len(delay)], kind, payload))

    for tick in range(3000):
        sender_stage = 2 + sum(tick >= t for t in (send_ticks[len(send_ticks) // 2],))
        receiver_stage = 2 + sum(tick >= t + stage_lag for t in (send_ticks[len(send_ticks) // 2],))
        def hand_over(cmds, tick=tick, receiver_stage=receiver_stage):
            for c in cmds:
                delivered.append((c, receiver_stage))
                transmit(tick, "ack", c.seq)         # acknowledged once delivered, never before

        for _, kind, payload in sorted(c for c in channel if c[0] == tick):
            if kind == "cmd":
                verdict = win.accept(payload, tick)
                if verdict is NEW:
                    hand_over(win.release(-1, receiver_stage, tick))
                elif verdict is DELIVERED:
                    transmit(tick, "ack", payload.seq)
            else:
                out.acked(0, payload)
        channel[:] = [c for c in channel if c[0] > tick]
        for src in win.holding():
            hand_over(win.release(src, receiver_stage, tick))
        for i, t in enumerate(send_ticks[:n]):
            if t == tick:
                seq, floor = out.number(0, True)
                c = TaskCommand(seq, 0.0, -1, 0, seq, True, i, None, None, "", sender_stage, floor)
                sent_at[seq] = tick
                out.track(c, tick)
                transmit(tick, "cmd", c)
        resend, gone = out.due(tick)
        abandoned += [seq for _, seq, _ in gone]
        for c in resend:
            transmit(tick, "cmd", c._replace(floor=out.floor(0, c.seq)))
    return delivered, abandoned, sent_at


@settings(max_examples=60, deadline=None)
@given(n=st.integers(1, 40),
       gaps=st.lists(st.integers(0, 6), min_size=40, max_size=40),
       drop=st.lists(st.booleans(), min_size=1, max_size=50).filter(lambda d: not all(d)),
       delay=st.lists(st.integers(0, 30), min_size=1, max_size=30),
       cut=st.lists(st.tuples(st.integers(0, 600), st.integers(1, 500)), max_size=2),
       stage_lag=st.integers(0, 40))
def test_in_order_exactly_once_under_any_loss_delay_and_partition(n, gaps, drop, delay, cut, stage_lag):
    send_ticks = [sum(gaps[:i + 1]) for i in range(40)]
    windows = [(a, a + d) for a, d in cut]
    delivered, abandoned, sent_at = _simulate(n, send_ticks, drop, delay, windows, stage_lag)
    seqs = [c.seq for c, _ in delivered]
    assert seqs == sorted(set(seqs)), f"out of order or duplicated: {seqs}"
    assert all(c.stage <= stage for c, stage in delivered), "a task arrived before its stage"
    assert set(sent_at) - set(abandoned) <= set(seqs), "a command neither delivered nor abandoned"
