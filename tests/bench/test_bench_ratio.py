"""``python -m swarmbox.bench``: the interleaved ratio table runs the algorithm and core it is given."""

import json
import subprocess
import sys
from pathlib import Path

FLOOR = Path(__file__).resolve().parents[2].parent / "shared" / "bench" / "floor.py"


def test_the_ratio_table_measures_the_batch_algorithm_on_the_fleet_core(tmp_path):
    out = tmp_path / "bench.json"
    done = subprocess.run([sys.executable, "-m", "swarmbox.bench", "--sizes", "2", "--rounds", "1", "--floor",
                           str(FLOOR), "--floor-s", "0.5", "--hover-s", "0.5", "--core", "fleet", "--algo",
                           "hover_batch", "--json", str(out)], capture_output=True, text=True, check=False)
    assert done.returncode == 0, done.stderr[-2000:]
    rows = json.loads(out.read_text())["measurements"]
    box = [r for r in rows if r["system"] == "swarmbox"]
    assert [(r["algo"], r["core"], r["status"], r["n"]) for r in box] == [("hover_batch", "fleet", "ok", 2)]
    assert "| 2 |" in done.stdout
