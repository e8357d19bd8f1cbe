"""``swarmbox.load(path)``: a run's or a whole sweep's logs as tidy pandas DataFrames.

One frame per log table (``state``, ``messages``, ``stages``, ``events``, ``setpoints``) holding
every node of every run, each row labelled with the ``run`` it came from (its path relative to
``path``), the run's ``algo``, ``mission`` and ``seed``, and the ``node`` that wrote it (``ground``,
``drone_<i>``, ``net``; ``node_id`` is -1, i, -2). Plus ``runs``: one row per run with its status,
choices and times from ``run.json``. Times are each node's own clock, as logged; the analyzer's
unified timeline is :func:`swarmbox.analysis.unify.unify`.
"""

from __future__ import annotations

from collections.abc import Iterable
from pathlib import Path

import pandas as pd

from swarmbox.analysis.load import _node_dirs, empty_table, find_runs, read_manifest, read_table
from swarmbox.record.schema import TABLES, node_name

LABELS = ("run", "algo", "mission", "seed", "node")


class Logs(dict):
    """``{table: DataFrame}``; also ``logs.state``, ``logs.events``, ... and ``logs.runs``."""

    def __getattr__(self, name: str) -> pd.DataFrame:
        try:
            return self[name]
        except KeyError:
            raise AttributeError(name) from None

    def __repr__(self) -> str:
        sizes = ", ".join(f"{k}: {len(v)} rows" for k, v in self.items())
        return f"Logs({sizes})"


def load(path: str | Path, tables: Iterable[str] | None = None) -> Logs:
    """Read every run at or below ``path`` (a run directory or a sweep directory).

    ``tables`` picks a subset of the log tables (default: all). Raises FileNotFoundError when no
    run directory (one holding ``run.json``) is found.
    """
    root = Path(path)
    names = list(TABLES) if tables is None else list(tables)
    unknown = [t for t in names if t not in TABLES]
    if unknown:
        raise ValueError(f"unknown table(s) {unknown}; the logs have {sorted(TABLES)}")
    run_dirs = find_runs(root)
    if not run_dirs:
        raise FileNotFoundError(f"no run directory (with run.json) at or below {root}")
    parts: dict[str, list[pd.DataFrame]] = {t: [] for t in names}
    runs = []
    for run_dir in run_dirs:
        manifest = read_manifest(run_dir)
        choices = manifest.get("choices") or {}
        label = {"run": str(run_dir.relative_to(root)) if run_dir != root else run_dir.name,
                 "algo": choices.get("algo"), "mission": choices.get("mission"), "seed": manifest.get("seed")}
        runs.append({**label, "status": manifest.get("status"), "reason": manifest.get("reason"),
                     **{k: v for k, v in choices.items() if k not in label},
                     **{k: manifest.get(k) for k in ("n_drones", "sim_time_s", "wall_time_s")}})
        problems: list[str] = []
        for nid, node_dir in _node_dirs(run_dir, problems).items():
            for table in names:
                frame = read_table(node_dir / f"{table}.parquet", table, nid, problems)
                if frame is not None and len(frame):
                    parts[table].append(_label(frame, label, nid))
    out = Logs()
    for table in names:
        frames = parts[table]
        out[table] = _categories(pd.concat(frames, ignore_index=True) if frames
                                 else _label(empty_table(table), {k: None for k in LABELS[:-1]}, None))
    out["runs"] = pd.DataFrame(runs)
    return out


def _label(frame: pd.DataFrame, label: dict, nid: int | None) -> pd.DataFrame:
    frame = frame.rename(columns={"node": "node_id"})
    for i, (key, value) in enumerate([*label.items(), ("node", None if nid is None else node_name(nid))]):
        frame.insert(i, key, pd.Series([value] * len(frame), index=frame.index,
                                       dtype="Int64" if key == "seed" else "object"))
    return frame


def _categories(frame: pd.DataFrame) -> pd.DataFrame:
    """Repeated labels as categoricals: a 180-run sweep's labels cost a few bytes per row."""
    for key in ("run", "algo", "mission", "node"):
        frame[key] = frame[key].astype("category")
    return frame
