"""The hook watchdog: a guarded hook past the limit is stopped and named; nothing else is touched."""

from __future__ import annotations

import time

import pytest

from swarmbox.core.stages import Stage
from swarmbox.run.watchdog import HookTimeout, HookWatchdog


class Algo:
    def __init__(self, pause_s: float) -> None:
        self.pause_s = pause_s

    def run_stage(self, stage, ctx):
        time.sleep(self.pause_s)
        return True, None

    def enter_stage(self, stage, ctx):
        while True:   # a busy loop, not a sleep: the signal still gets in
            pass

    def on_task(self, ctx, task):
        deadline = time.monotonic() + self.pause_s
        while time.monotonic() < deadline:
            try:
                time.sleep(0.01)
            except Exception:   # swallowing errors does not swallow the timeout
                pass


@pytest.fixture
def dog():
    d = HookWatchdog(0.3)
    yield d
    d.stop()


def test_a_hook_past_the_limit_is_stopped_and_named(dog):
    algo = Algo(30.0)
    dog.guard(algo, "drone 2")
    assert dog.start()
    start = time.monotonic()
    with pytest.raises(HookTimeout, match=r"^drone 2: exec_loop/exec_complete did not return within 0\.3 s"):
        algo.run_stage(Stage.EXECUTION, None)
    # stopped after the limit, long before the hook's own 30 s end (any margin for a loaded machine)
    assert 0.3 <= time.monotonic() - start < 20.0


@pytest.mark.parametrize("call, named", [
    (lambda a: a.enter_stage(Stage.EXECUTION, None), "ground: execution entry did not return"),
    (lambda a: a.on_task(None, None), "ground: on_task did not return"),
])
def test_every_dispatch_hook_is_watched(dog, call, named):
    algo = Algo(30.0)
    dog.guard(algo, "ground")
    dog.start()
    with pytest.raises(HookTimeout, match=named):
        call(algo)


def test_many_short_calls_and_unguarded_objects_are_left_alone(dog):
    guarded, other = Algo(0.02), Algo(0.8)
    dog.guard(guarded, "drone 0")
    dog.start()
    deadline = time.monotonic() + 1.0
    while time.monotonic() < deadline:   # 1 s of hooks, each well under the limit
        guarded.run_stage(Stage.EXECUTION, None)
    assert other.run_stage(Stage.EXECUTION, None) == (True, None)   # not guarded: runs to the end
