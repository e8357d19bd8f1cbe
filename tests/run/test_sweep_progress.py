"""The sweep's progress lines without a terminal: one per change, none for the state at the start
(a sweep refused at its start prints its one error line and nothing else)."""

from __future__ import annotations

import io
import json
import time

from swarmbox.run.progress import SweepMonitor


def wait_for(pred, timeout_s: float = 5.0) -> bool:
    end = time.monotonic() + timeout_s
    while time.monotonic() < end:
        if pred():
            return True
        time.sleep(0.02)
    return False


def test_no_line_until_a_run_finishes_then_one_per_change(tmp_path):
    (tmp_path / "0_earlier").mkdir()
    (tmp_path / "0_earlier" / "run.json").write_text(json.dumps({"status": "ok"}))   # a resumed sweep's
    out = io.StringIO()
    mon = SweepMonitor(tmp_path, total=3, interval_s=0.02, stream=out)
    mon.start()
    try:
        time.sleep(0.3)   # fifteen polls
        assert out.getvalue() == ""
        (tmp_path / "1_new").mkdir()
        (tmp_path / "1_new" / "run.json").write_text(json.dumps({"status": "failed"}))
        assert wait_for(lambda: "runs done" in out.getvalue())
        assert out.getvalue().count("\n") == 1
        assert "1/2 runs done, 1 failed, 1 skipped (finished before)" in out.getvalue()
    finally:
        mon.stop()
    assert out.getvalue().count("\n") == 2   # the final line
