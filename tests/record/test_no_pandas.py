"""The runner writes its logs without pandas: a simulation run never loads it (nor the plotting stack)."""

from __future__ import annotations

import json
import subprocess
import sys

from tests.conftest import ROOT


def test_a_sim_run_writes_its_logs_without_loading_pandas(tmp_path):
    # The fleet state log hands its rows over as Arrow columns; building the spill batch from them
    # must not go through pa.array(ndarray), which imports pandas on the recorder thread.
    # A small hand-over size makes the 4-drone run hand rows over during the loop, as long runs do.
    code = ("import sys, json, pathlib; from tests.conftest import run_config; "
            "from swarmbox.record.writer import Recorder; Recorder.FLUSH_ROWS = 2000; "
            f"m = run_config(pathlib.Path({str(tmp_path / 'run')!r}), ['algo=hover', 'mission=hover']); "
            "print(json.dumps({'status': m['status'], "
            "'modules': sorted({'pandas', 'matplotlib', 'seaborn', 'scipy'} & set(sys.modules))}))")
    proc = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr[-3000:]
    out = json.loads(proc.stdout.strip().splitlines()[-1])
    assert out == {"status": "ok", "modules": []}, out
    assert (tmp_path / "run" / "logs" / "drone_0" / "state.parquet").stat().st_size > 0
