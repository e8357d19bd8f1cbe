"""Task codes above one byte on real runs: delivered intact, sized as on the wire; bad ones refused."""

import json

from tests.conftest import table

ALGO = ["algo=hover", "mission=hover"]
WIDE = "+algo.ground._target_=tests.net.wide_codes.WideCodeGround"
NEG = "+algo.ground._target_=tests.net.wide_codes.NegativeCodeGround"


def test_task_code_1000_is_delivered_and_logged_with_its_wire_size(run):
    manifest, d = run(*ALGO, WIDE, "seed=2")
    assert manifest["status"] == "ok", manifest["reason"]
    msgs = table(d, "ground", "messages")
    tasks = msgs[(msgs["type"] == "task") & (msgs["kind"] == "send")]
    assert len(tasks) >= 8
    # 1000 and 1001 take a two-byte varint: one byte more than a code below 128 would
    base = 21 + 4 + 1 + 12 + 4 + 2 + 1 + 4 + 4  # header, seq, reliable, wp, yaw, len, stage, floor, inc.
    assert set(tasks["nbytes"]) == {base + 2 + 1}            # + varint + data "0"/"1"
    for i in range(4):
        got = table(d, f"drone_{i}", "messages")
        assert ((got["type"] == "task") & (got["kind"] == "recv")).sum() >= 2


def test_negative_task_code_fails_the_run_naming_the_range(run):
    manifest, _ = run(*ALGO, NEG, "seed=2")
    assert manifest["status"] != "ok"
    assert "task code must be an integer in 0..4294967295, got -5" in json.dumps(manifest)
