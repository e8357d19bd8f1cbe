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
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.compute as pc
import yaml

from swarmbox.analysis.arrowpool import arrow_pool as _arrow_pool
from swarmbox.analysis.arrowpool import disk_bytes as _disk_bytes
from swarmbox.analysis.readers import check_file, read_arrow, read_batches
from swarmbox.analysis.rundirs import find_runs, find_unfinished
from swarmbox.record.schema import TABLES

__all__ = ["EXPECTED", "GROUND", "NET", "REQUIRED", "RunData", "RunLoadError", "check_file", "empty_table",
           "find_runs", "find_unfinished", "load_run", "node_id", "node_kind", "read_arrow", "read_batches",
           "read_config", "read_manifest", "read_table"]

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
_DTYPES = {t: {c.name: c.dtype for c in cols} for t, cols in TABLES.items()}
_READERS = 4
#: Runs whose files total less than this are read one file after another: the pool's hand-offs cost more
#: CPU than they save in time on a few MB (a 5-drone run, 6 MB in 29 files: ~7 % less CPU to load).
_POOL_BYTES = 32 * 2**20
#: Text columns read as pandas categoricals: few distinct values in the largest table.
CATEGORICAL: dict[str, tuple[str, ...]] = {"messages": ("kind", "type", "reason")}
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
    #: Tables left in their files (each here an empty frame): the analysis reads them window by window.
    streamed: tuple[str, ...] = ()
    #: The projection the tables were read with (``load_run``'s ``columns``).
    columns: dict[str, tuple[str, ...]] | None = None

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


#: libyaml's safe loader when PyYAML was built with it: ~10x faster on a run's config (a sweep reads
#: hundreds); the same documents as yaml.safe_load
_YAML_LOADER = getattr(yaml, "CSafeLoader", yaml.SafeLoader)


def read_config(run_dir: Path, problems: list[str]) -> dict[str, Any]:
    path = run_dir / "config.yaml"
    try:
        config = yaml.load(path.read_text(), Loader=_YAML_LOADER)  # noqa: S506 - a safe loader
    except FileNotFoundError:
        problems.append("config.yaml missing")
        return {}
    except (OSError, yaml.YAMLError) as exc:
        problems.append(f"config.yaml unreadable: {exc}")
        return {}
    return config if isinstance(config, dict) else {}


def read_table(path: Path, table: str, node: int, problems: list[str]) -> pd.DataFrame | None:
    """One node's table conformed to the schema, or None (with a problem line) when unreadable."""
    data = read_arrow(path, table, node, problems)
    return None if data is None else _to_frame(table, [data])


def _to_frame(table: str, parts: list[pa.Table]) -> pd.DataFrame:
    """Concatenate Arrow parts and conform their columns once, as pandas.

    The text columns of :data:`CATEGORICAL` tables become pandas categoricals (Arrow dictionaries):
    a handful of distinct words over millions of rows, one byte a row instead of a string each. The
    categories are in order of first appearance, however the files' dictionaries were ordered.
    """
    data = pa.concat_tables(parts)
    parts.clear()   # the caller's list: let the per-node tables go as soon as they are joined
    for name in CATEGORICAL.get(table, ()):
        if name in data.column_names:
            i = data.column_names.index(name)
            column = data.column(name)
            if not pa.types.is_dictionary(column.type) or column.null_count:
                column = pc.fill_null(column.cast(pa.string()), "").dictionary_encode()
            data = data.set_column(i, name, column)
    # self_destruct frees each Arrow column once converted: peak memory ~1x the frame, not 2x
    frame = data.to_pandas(self_destruct=True, split_blocks=True)
    del data
    for name, dtype in frame.dtypes.items():
        target = _PANDAS_DTYPE[_DTYPES[table][name]] if name != "node" else None
        if target is None or (target != "str" and dtype == np.dtype(target)):
            continue   # numbers arrive as the schema's type unless they hold nulls: nothing to do
        column = frame[name]
        conformed = _conform(column, target)
        if conformed is not column:   # setting back a column that needed nothing would copy it
            frame[name] = conformed
    return frame


def _first_seen(series: pd.Series) -> pd.Series:
    """A categorical with its categories in order of first appearance, the unused ones dropped."""
    codes = series.cat.codes.to_numpy()
    if len(codes) and codes[0] == 0 and codes.min() == 0:   # no NaN (-1): maybe in order already
        top = np.maximum.accumulate(codes)   # a new code first appears where this running max steps up
        if top[-1] == len(series.cat.categories) - 1 and (np.diff(top) <= 1).all():
            return series   # steps of one up to the last category: in order, every one used
    seen = pd.unique(codes)
    remap = np.zeros(len(series.cat.categories), dtype=codes.dtype)
    remap[seen] = np.arange(len(seen))
    return pd.Series(pd.Categorical.from_codes(remap[codes], series.cat.categories[seen]),
                     index=series.index, name=series.name)


def _conform(series: pd.Series, target: str) -> pd.Series:
    """``series`` as the pandas dtype ``target``: text without nulls, integers as floats when some are
    missing."""
    if isinstance(series.dtype, pd.CategoricalDtype):
        return _first_seen(series)   # text as a dictionary, nulls already filled with ""
    missing = series.isna()
    if target == "str":
        if series.dtype == "str" and not missing.any():
            return series   # already text, as Arrow strings arrive: no copy of millions of values
        return series.astype("str").where(~missing, "")
    if target.startswith("int") and missing.any():
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


def load_run(run_dir: str | Path, columns: dict[str, tuple[str, ...]] | None = None,
             streamed: tuple[str, ...] = ()) -> RunData:
    """Read a run directory. Raises :class:`RunLoadError` only when ``run.json`` is unusable.

    ``streamed``: tables not read here but left to the analysis to read window by window (only
    ``messages``); their files are opened, so that a damaged one is named as when it is read.

    ``columns`` projects tables (table -> the columns to read; ``node`` always comes along): Parquet
    is columnar, so what is not asked for is never read, which bounds memory on large runs. Files are
    read by a small thread pool (a small run's one after another) and each table is converted to pandas
    once, not once per node.
    """
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
    jobs = [(nid, ndir, t) for nid, ndir in dirs.items() for t in TABLES]
    notes: list[list[str]] = [[] for _ in jobs]   # per file, merged in order: deterministic output
    found = [False] * len(jobs)
    threaded = _disk_bytes(ndir / f"{table}.parquet" for _, ndir, table in jobs) >= _POOL_BYTES
    with _arrow_pool(threaded):
        # one table at a time, its Arrow parts freed once it is a frame: the read and the conversion
        # then hold two copies of one table at most, not of the whole run
        tables = {t: _read_table(t, [i for i, job in enumerate(jobs) if job[2] == t], jobs, notes, found,
                                 (columns or {}).get(t), threaded) for t in TABLES if t not in streamed}
    for i, (_, ndir, table) in enumerate(jobs):
        if table in streamed:
            path, wanted = ndir / f"{table}.parquet", (columns or {}).get(table)
            found[i] = check_file(path, table, notes[i], wanted) is True
    tables |= {t: _concat(t, [], (columns or {}).get(t)) for t in streamed}
    for (nid, ndir, table), data, note in zip(jobs, found, notes, strict=True):
        problems.extend(note)
        if data:
            continue
        if (ndir / f"{table}.parquet").exists():
            incomplete = True    # unreadable (truncated, corrupt): the record is damaged
        elif table in EXPECTED[node_kind(nid)]:
            if not any(p.startswith(f"{ndir.name}/{table}") for p in problems):
                problems.append(f"{ndir.name}/{table}.parquet missing")
            incomplete |= table in REQUIRED.get(node_kind(nid), ())
    if GROUND not in dirs:
        incomplete = True
        problems.append("no ground logs")
    for partial in sorted((run_dir / "logs").rglob("*.partial")):
        incomplete = True
        problems.append(f"{partial.relative_to(run_dir)}: writing never finished")
    if "events" not in (columns or {}) and any((run_dir / "logs").glob("drone_*/ulog.json")):
        from swarmbox.analysis.ulog import add_estimator_events  # PX4 runs: EKF2's markers as events
        tables["events"] = add_estimator_events(run_dir, tables["events"], tables.get("state"))
    tables = {t: tables[t] for t in TABLES}   # in the schema's order, streamed or not
    return RunData(run_dir, manifest, config, tables, sorted(dirs), problems, incomplete, tuple(streamed),
                   columns)


def read_streamed(run: RunData, table: str) -> None:
    """Read a table ``run`` left in its files into ``run.tables``, whole, as :func:`load_run` would have
    (its files' problems were named when it was loaded)."""
    dirs = _node_dirs(run.path, [])
    jobs = [(nid, ndir, table) for nid, ndir in dirs.items()]
    notes: list[list[str]] = [[] for _ in jobs]
    threaded = _disk_bytes(ndir / f"{table}.parquet" for _, ndir, _ in jobs) >= _POOL_BYTES
    with _arrow_pool(threaded):
        run.tables[table] = _read_table(table, list(range(len(jobs))), jobs, notes, [False] * len(jobs),
                                        (run.columns or {}).get(table), threaded)
    run.streamed = tuple(t for t in run.streamed if t != table)

def _read_table(table: str, indices: list[int], jobs: list[tuple[int, Path, str]], notes: list[list[str]],
                found: list[bool], columns: tuple[str, ...] | None, threaded: bool) -> pd.DataFrame:
    """Every node's file of ``table`` (the ``jobs`` at ``indices``) as one frame; marks in ``found``
    which files gave data and puts each file's problems in its ``notes``."""

    def read(i: int) -> pa.Table | None:
        nid, ndir, _ = jobs[i]
        return read_arrow(ndir / f"{table}.parquet", table, nid, notes[i], columns)

    if threaded:
        with ThreadPoolExecutor(max_workers=_READERS) as pool:   # pyarrow reads without the GIL
            results = list(pool.map(read, indices))
    else:
        results = [read(i) for i in indices]
    for i, data in zip(indices, results, strict=True):
        found[i] = data is not None
    return _concat(table, [data for data in results if data is not None], columns)


def _concat(table: str, parts: list[pa.Table], columns: tuple[str, ...] | None = None) -> pd.DataFrame:
    parts[:] = [p for p in parts if len(p)]
    if not parts:
        frame = empty_table(table)
        return frame if columns is None else frame[[c for c in frame.columns if c in columns or c == "node"]]
    return _to_frame(table, parts)
