"""Reliable task delivery, unit by unit and as a property (Hypothesis) over a simulated channel:
whatever is lost, delayed, reordered or cut off, the receiver hands each command to its algorithm at
most once, in send order, never before its stage; everything not abandoned by the sender arrives."""

from hypothesis import given, settings
from hypothesis import strategies as st

from swarmbox.core.delivery import Outbox, Window
from swarmbox.core.messages import TaskCommand

RETRY, MAX_RETRIES = 8, 40


def cmd(seq, floor=0, stage=2, src=-1, reliable=True):
    return TaskCommand(seq, 0.0, src, 0, seq, reliable, seq, None, None, "", stage, floor)


def test_duplicates_are_suppressed_and_gaps_hold_later_commands():
    w = Window(give_up_ticks=1000)
    assert w.accept(cmd(2), 0) and w.release(-1, 2, 0) == []        # 1 missing: 2 is held
    assert not w.accept(cmd(2), 1)                                  # a re-sent copy of 2: duplicate
    assert w.accept(cmd(1), 2)
    assert [c.seq for c in w.release(-1, 2, 2)] == [1, 2]
    assert not w.accept(cmd(1), 3) and not w.accept(cmd(2), 3)      # late copies after delivery


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
        for _, kind, payload in sorted(c for c in channel if c[0] == tick):
            if kind == "cmd":
                transmit(tick, "ack", payload.seq)
                if win.accept(payload, tick):
                    delivered += [(c, receiver_stage) for c in win.release(-1, receiver_stage, tick)]
            else:
                out.acked(0, payload)
        channel[:] = [c for c in channel if c[0] > tick]
        for src in win.holding():
            delivered += [(c, receiver_stage) for c in win.release(src, receiver_stage, tick)]
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
