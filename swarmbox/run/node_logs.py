"""The logs of a node whose process was restarted: earlier segments first, then the new process's rows.

A node process writes its tables once, at its end (``logs/<node>/<table>.parquet``). When the node
is started again in a run already under way (a rejoin after a crash or a stop), whatever an earlier
process of that node wrote is moved to ``nodes/<node>.segments/<k>/`` before the new process
builds its recorder, and appended in front of the new rows when it closes, so the node's tables
hold every segment in time order and nothing written before is replaced. A process killed with
SIGKILL writes no tables at all (its rows were in memory), so a rejoin after ``kill -9`` has one
segment, that of the restarted process; one stopped by SIGTERM or SIGINT leaves its own.
"""

from __future__ import annotations

import os
import shutil
from pathlib import Path

import pyarrow as pa
import pyarrow.parquet as pq


def set_aside(run_dir: Path, name: str) -> list[Path]:
    """Move ``logs/<name>/`` (if any) to the next ``nodes/<name>.segments/<k>/``; all segments, in order."""
    seg_root = run_dir / "nodes" / f"{name}.segments"
    logs = run_dir / "logs" / name
    if logs.is_dir() and any(logs.glob("*.parquet")):
        seg_root.mkdir(parents=True, exist_ok=True)
        os.replace(logs, seg_root / str(len(list(seg_root.iterdir()))))
    if not seg_root.is_dir():
        return []
    segs = (p for p in seg_root.iterdir() if p.is_dir() and p.name.isdigit())
    return sorted(segs, key=lambda p: int(p.name))


def append_segments(run_dir: Path, name: str, segments: list[Path]) -> None:
    """Put the rows of ``segments`` in front of this process's rows in every table of ``logs/<name>/``."""
    if not segments:
        return
    logs = run_dir / "logs" / name
    tables = {p.name for seg in [*segments, logs] for p in seg.glob("*.parquet")}
    for file in sorted(tables):
        parts = [pq.read_table(seg / file) for seg in segments if (seg / file).exists()]
        if (logs / file).exists():
            parts.append(pq.read_table(logs / file))
        merged = pa.concat_tables(parts, promote_options="default")
        tmp = logs / f".{file}.tmp"
        logs.mkdir(parents=True, exist_ok=True)
        pq.write_table(merged, tmp)
        os.replace(tmp, logs / file)
    for seg in segments:             # every row is in logs/<name>/ now; a later restart sets that aside
        shutil.rmtree(seg, ignore_errors=True)
