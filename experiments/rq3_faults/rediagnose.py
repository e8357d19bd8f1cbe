"""Diagnose every finished run below a sweep directory again (after a change to the analyzer), in
place of its ``diagnosis.parquet``; the simulations are not rerun.

    python experiments/rq3_faults/rediagnose.py results/rq3 [--jobs 1] [--only wifi]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path


def redo(run_dir: Path) -> str:
    from swarmbox.analysis.detection import default_settings, evaluate_run

    t0 = time.time()
    rows = evaluate_run(run_dir, default_settings())
    rows.to_parquet(run_dir / "diagnosis.parquet.tmp", index=False)
    (run_dir / "diagnosis.parquet.tmp").replace(run_dir / "diagnosis.parquet")
    return f"{run_dir} {time.time() - t0:.1f}s"


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("root", type=Path)
    p.add_argument("--jobs", type=int, default=1)
    p.add_argument("--only", default="", help="only runs whose path contains this text (e.g. wifi)")
    args = p.parse_args(argv)
    from joblib import Parallel, delayed

    dirs = sorted(d.parent for d in args.root.rglob("run.json") if args.only in str(d.parent))
    for line in Parallel(n_jobs=args.jobs, return_as="generator")(delayed(redo)(d) for d in dirs):
        print(line, flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
