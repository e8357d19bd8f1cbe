"""Read a run directory into tidy frames, one per table, holding every node's rows.

A run directory (see :mod:`swarmbox.record.schema`) is ``run.json`` + ``config.yaml`` +
``logs/<node>/<table>.parquet``. Each loaded table gets a ``node`` column (ground -1, net -2, drone i
= i) and keeps every schema column; a missing or unreadable file becomes an empty table plus a line in
``RunData.problems`` rather than an exception. Only a missing or unreadable ``run.json`` is fatal
(:class:`RunLoadError`): without it the directory is not a run.

A run is *incomplete* (``RunData.incomplete``, with the reasons in ``problems``) when any expected
table is unreadable, a table the metrics need is missing, or a ``.partial`` file shows that writing
never finished; the analyzer refuses such a run unless told otherwise, and a sweep lists it as
skipped. :func:`find_unfinished` finds the directories of runs that never wrote ``run.json``.
"""

from __future__ import annotations

import json
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pandas as pd
import pyarrow.parquet as pq
import yaml

from swarmbox.record.schema import SCHEMA_VERSION, TABLES

GROUND = -1
NET = -2

#: Tables each kind of node is expected to write.
EXPECTED: dict[str, tuple[str, ...]] = {
    "ground": ("messages", "stages", "events"),
    "drone": ("state", "messages", "stages", "events", "setpoints"),
    "net": ("messages",),
}
#: Tables the metrics cannot do without; a run missing one of them is skipped in a sweep.
REQUIRED: dict[str, tuple[str, ...]] = {"ground": ("stages",), "drone": ("state",)}

_PANDAS_DTYPE = {
    "float64": "float64", "int64": "int64", "int32": "int32", "int16": "int16", "int8": "int8",
    "bool": "bool", "string": "str",
}
_DRONE = re.compile(r"drone_(\d+)")


class RunLoadError(RuntimeError):
    """The directory is not a readable run (no or invalid ``run.json``)."""


@dataclass
class RunData:
    """Everything read from one run directory."""

    path: Path
    manifest: dict[str, Any]
    config: dict[str, Any]
    tables: dict[str, pd.DataFrame]
    nodes: list[int]
    problems: list[str] = field(default_factory=list)
    #: True when a table the metrics need is missing or unreadable.
    incomplete: bool = False

    @property
    def drones(self) -> list[int]:
        return sorted(n for n in self.nodes if n >= 0)

    @property
    def status(self) -> str:
        return str(self.manifest.get("status", "unknown"))


def node_id(name: str) -> int | None:
    """Node id of a log directory name, or None when it is not a node directory."""
    if name == "ground":
        return GROUND
    if name == "net":
        return NET
    match = _DRONE.fullmatch(name)
    return int(match.group(1)) if match else None


def node_kind(node: int) -> str:
    return "ground" if node == GROUND else "net" if node == NET else "drone"


def empty_table(table: str) -> pd.DataFrame:
    """A zero-row frame with the schema's columns and dtypes, plus ``node``."""
    cols = {c.name: pd.Series(dtype=_PANDAS_DTYPE[c.dtype]) for c in TABLES[table]}
    frame = pd.DataFrame(cols)
    frame["node"] = pd.Series(dtype="int16")
    return frame


def read_manifest(run_dir: Path) -> dict[str, Any]:
    path = run_dir / "run.json"
    try:
        manifest = json.loads(path.read_text())
    except FileNotFoundError as exc:
        raise RunLoadError(f"{run_dir}: no run.json") from exc
    except (OSError, ValueError) as exc:
        raise RunLoadError(f"{path}: unreadable ({exc})") from exc
    if not isinstance(manifest, dict):
        raise RunLoadError(f"{path}: not a JSON object")
    return manifest


def read_config(run_dir: Path, problems: list[str]) -> dict[str, Any]:
    path = run_dir / "config.yaml"
    try:
        config = yaml.safe_load(path.read_text())
    except FileNotFoundError:
        problems.append("config.yaml missing")
        return {}
    except (OSError, yaml.YAMLError) as exc:
        problems.append(f"config.yaml unreadable: {exc}")
        return {}
    return config if isinstance(config, dict) else {}


def read_table(path: Path, table: str, node: int, problems: list[str]) -> pd.DataFrame | None:
    """One node's table conformed to the schema, or None (with a problem line) when unreadable."""
    where = f"{path.parent.name}/{path.name}"
    try:
        pf = pq.ParquetFile(path)
        frame = pf.read().to_pandas()
    except FileNotFoundError:
        return None
    except Exception as exc:  # noqa: BLE001 - pyarrow raises many types for a corrupt file
        problems.append(f"{where}: unreadable ({type(exc).__name__}: {exc})")
        return None
    meta = pf.schema_arrow.metadata or {}
    version = meta.get(b"swarmbox.schema", SCHEMA_VERSION.encode()).decode()
    if version != SCHEMA_VERSION:
        problems.append(f"{where}: schema version {version}, analyzer reads {SCHEMA_VERSION}")
    for col in TABLES[table]:
        if col.name not in frame.columns:
            problems.append(f"{where}: column {col.name!r} missing (filled with NA)")
            frame[col.name] = pd.Series(pd.NA, index=frame.index, dtype="object")
        frame[col.name] = _conform(frame[col.name], col.dtype)
    frame["node"] = pd.Series(node, index=frame.index, dtype="int16")
    return frame[[c.name for c in TABLES[table]] + ["node"]]


def _conform(series: pd.Series, dtype: str) -> pd.Series:
    target = _PANDAS_DTYPE[dtype]
    if target == "str":
        return series.astype("str").where(series.notna(), "")
    if target.startswith("int") and series.isna().any():
        return series.astype("float64")
    if target == "bool":
        return series.fillna(False).astype("bool")
    return series.astype(target)


def _node_dirs(run_dir: Path, problems: list[str]) -> dict[int, Path]:
    logs = run_dir / "logs"
    if not logs.is_dir():
        problems.append("logs/ missing")
        return {}
    dirs: dict[int, Path] = {}
    for child in sorted(logs.iterdir()):
        nid = node_id(child.name) if child.is_dir() else None
        if nid is None:
            problems.append(f"logs/{child.name}: not a node directory, ignored")
        else:
            dirs[nid] = child
    return dirs


def load_run(run_dir: str | Path) -> RunData:
    """Read a run directory. Raises :class:`RunLoadError` only when ``run.json`` is unusable."""
    run_dir = Path(run_dir)
    manifest = read_manifest(run_dir)
    problems: list[str] = []
    config = read_config(run_dir, problems)
    dirs = _node_dirs(run_dir, problems)
    incomplete = False
    for name in manifest.get("nodes", []):
        nid = node_id(str(name))
        if nid is not None and nid not in dirs:
            problems.append(f"node {name} listed in run.json has no logs")
            incomplete |= bool(REQUIRED.get(node_kind(nid)))
    parts: dict[str, list[pd.DataFrame]] = {t: [] for t in TABLES}
    for nid, ndir in dirs.items():
        kind = node_kind(nid)
        for table in TABLES:
            path = ndir / f"{table}.parquet"
            frame = read_table(path, table, nid, problems)
            if frame is not None:
                parts[table].append(frame)
            elif path.exists():
                incomplete = True    # unreadable (truncated, corrupt): the record is damaged
            elif table in EXPECTED[kind]:
                if not any(p.startswith(f"{ndir.name}/{table}") for p in problems):
                    problems.append(f"{ndir.name}/{table}.parquet missing")
                incomplete |= table in REQUIRED.get(kind, ())
    if GROUND not in dirs:
        incomplete = True
        problems.append("no ground logs")
    for partial in sorted((run_dir / "logs").rglob("*.partial")):
        incomplete = True
        problems.append(f"{partial.relative_to(run_dir)}: writing never finished")
    tables = {t: _concat(t, frames) for t, frames in parts.items()}
    return RunData(run_dir, manifest, config, tables, sorted(dirs), problems, incomplete)


def _concat(table: str, frames: list[pd.DataFrame]) -> pd.DataFrame:
    frames = [f for f in frames if len(f)]
    if not frames:
        return empty_table(table)
    return pd.concat(frames, ignore_index=True)


def find_unfinished(root: str | Path) -> list[Path]:
    """Directories at or below ``root`` that hold a run's files (config.yaml or logs/) but no run.json:
    runs that were killed, or still run."""
    root = Path(root)
    marks = [*root.rglob("config.yaml"), *(p for p in root.rglob("logs") if p.is_dir())]
    dirs = {p.parent for p in marks}
    return sorted(d for d in dirs if not (d / "run.json").is_file())


def find_runs(root: str | Path) -> list[Path]:
    """Every run directory (one holding ``run.json``) at or below ``root``, sorted by path."""
    root = Path(root)
    if (root / "run.json").is_file():
        return [root]
    return sorted(p.parent for p in root.rglob("run.json") if p.is_file())
