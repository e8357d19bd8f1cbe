"""The text table is bounded: past its limit new texts share one marker code, and the run says so."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pyarrow.parquet as pq

from swarmbox.core.rows import TextTable

ROOT = Path(__file__).resolve().parents[2]


def test_past_the_limit_new_texts_share_the_marker_and_are_counted():
    table = TextTable(limit=4)
    codes = [table.code(t) for t in ("", "send", "recv")]
    assert codes == [0, 1, 2]
    late = [table.code(f"clamped to {v:.3f} m") for v in (1.0, 2.0, 3.0)]
    assert late == [3, 3, 3] and table.texts[3] == TextTable.OVERFLOW
    assert table.overflowed == 3 and len(table.texts) == 4
    assert table.code("send") == 1 and table.code("recv") == 2   # the texts it holds keep their codes


def test_a_run_past_the_limit_reports_it_and_logs_the_marker(tmp_path):
    """A run whose process has no room for new texts (the limit set to what the imports use)."""
    script = f"""
from swarmbox.core.rows import TEXTS
TEXTS.limit = len(TEXTS.texts) + 1
from pathlib import Path
from tests.conftest import run_config
run_config(Path({str(tmp_path / 'run')!r}), ["algo=hover", "mission=hover"])
"""
    proc = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=300,
                          cwd=ROOT, env=dict(os.environ, PYTHONPATH=str(ROOT)))
    assert proc.returncode == 0, proc.stderr
    manifest = json.loads((tmp_path / "run" / "run.json").read_text())
    problem = [p for p in manifest["problems"] if "text table" in p]
    assert len(problem) == 1 and f"texts logged as {TextTable.OVERFLOW!r}: the text table holds" in problem[0]
    texts = {t for node in (tmp_path / "run" / "logs").iterdir() for t in
             pq.read_table(node / "messages.parquet").column("reason").to_pylist()}
    assert TextTable.OVERFLOW in texts
