"""A hover run of N drones and its analysis, each in a fresh process: wall time and peak memory.

``python -m swarmbox.bench.endtoend N [--hover-s S] [--keep DIR]`` prints one JSON line: the run's
simulated time and real-time factor, then for each step (``run``: ``python -m swarmbox.bench.hover``;
``analyze``: ``python -m swarmbox.analyze``) its wall time and peak resident memory (from ``wait4``,
so the figure is the child's own). ``--hover-s 50`` gives about 60 simulated seconds.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path


def timed(cmd: list[str]) -> tuple[float, float, str]:
    """(wall s, peak RSS MB, stdout) of one child process; raises when it fails."""
    with tempfile.TemporaryFile("w+") as out, tempfile.TemporaryFile("w+") as err:
        start = time.perf_counter()
        proc = subprocess.Popen(cmd, stdout=out, stderr=err, text=True)
        _, status, usage = os.wait4(proc.pid, 0)   # this child's own rusage (peak RSS in KiB)
        wall = time.perf_counter() - start
        code = os.waitstatus_to_exitcode(status)
        out.seek(0)
        err.seek(0)
        if code != 0:
            raise RuntimeError(f"{' '.join(cmd)} failed (exit {code}): {err.read().strip()[-800:]}")
        return wall, usage.ru_maxrss / 1024, out.read()


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m swarmbox.bench.endtoend", description=__doc__.splitlines()[0])
    p.add_argument("n", type=int, help="number of drones")
    p.add_argument("--hover-s", type=float, default=50.0, help="time at altitude, s (50: ~60 s simulated)")
    p.add_argument("--keep", type=Path, help="keep the run directory here")
    args = p.parse_args(argv)
    tmp = Path(tempfile.mkdtemp(prefix="swarmbox-e2e-"))
    run_dir = args.keep or tmp / "run"
    try:
        run_wall, run_rss, out = timed([sys.executable, "-m", "swarmbox.bench.hover", str(args.n),
                                        "--hover-s", str(args.hover_s), "--out", str(run_dir)])
        run = json.loads(out.strip().splitlines()[-1])
        an_wall, an_rss, _ = timed([sys.executable, "-m", "swarmbox.analyze", str(run_dir)])
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    print(json.dumps({"n": args.n, "sim_s": run["sim_s"], "rtf": run["rtf"], "status": run["status"],
                      "run_wall_s": round(run_wall, 2), "run_peak_mb": round(run_rss),
                      "analyze_wall_s": round(an_wall, 2), "analyze_peak_mb": round(an_rss),
                      "total_wall_s": round(run_wall + an_wall, 2), "load1": round(os.getloadavg()[0], 2)}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
