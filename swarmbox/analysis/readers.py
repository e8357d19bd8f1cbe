"""Reading one node's table file: whole, or a Parquet batch at a time, conformed to the schema."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.compute as pc
import pyarrow.parquet as pq

from swarmbox.record.broadcast import expand_broadcasts
from swarmbox.record.schema import READABLE_VERSIONS, SCHEMA_VERSION, TABLES

_ARROW = {"float64": pa.float64(), "int64": pa.int64(), "int32": pa.int32(), "int16": pa.int16(),
          "int8": pa.int8(), "bool": pa.bool_(), "string": pa.string()}
#: Of those, the ones read straight as Parquet's dictionaries: no string is made per row, and the
#: broadcast expansion copies indices. Not ``reason``: a sender's broadcast rows hold their destination
#: lists there (4 KB each at 1,000 drones), and Arrow decodes a dictionary to text by reserving the
#: dictionary's mean length for every row: the ground's 20 s of a 1,000-drone hover took 1.5 GB for
#: 3 MB of text, growing with the run. Read as text it costs its own bytes; it becomes a dictionary in
#: :func:`_to_frame`.
_READ_AS_DICTIONARY: dict[str, tuple[str, ...]] = {"messages": ("kind", "type")}

def read_arrow(path: Path, table: str, node: int, problems: list[str],
               columns: tuple[str, ...] | None = None) -> pa.Table | None:
    """One node's table as Arrow in the schema's column order (only ``columns`` if given), plus ``node``.

    Missing columns are filled with nulls and named in ``problems``; a file that cannot be read gives
    None and a problem line; an absent file gives None alone.
    """
    opened = _open(path, table, problems, columns)
    if opened is None:
        return None
    pf, names, wanted, notes = opened
    try:
        data = pf.read(columns=names)
    except Exception as exc:  # noqa: BLE001 - pyarrow raises many types for a corrupt file
        problems.append(f"{path.parent.name}/{path.name}: unreadable ({type(exc).__name__}: {exc})")
        return None
    problems.extend(notes)
    return _conformed(data, table, wanted, node)


def read_batches(path: Path, table: str, node: int, problems: list[str],
                 columns: tuple[str, ...] | None = None, batch_rows: int = 1 << 16) -> Iterator[pa.Table]:
    """:func:`read_arrow` of one file a Parquet batch at a time (a broadcast row is expanded within its
    batch); nothing when the file is absent or unreadable (then a problem line)."""
    opened = _open(path, table, problems, columns)
    if opened is None:
        return
    pf, names, wanted, notes = opened
    problems.extend(notes)
    for batch in pf.iter_batches(batch_size=batch_rows, columns=names):
        yield _conformed(pa.Table.from_batches([batch]), table, wanted, node)


def check_file(path: Path, table: str, problems: list[str],
               columns: tuple[str, ...] | None = None) -> bool | None:
    """Whether a table's file opens (its footer read, the problems :func:`read_arrow` would name noted);
    None when it is absent."""
    opened = _open(path, table, problems, columns)
    if opened is None:
        return False if path.exists() else None
    problems.extend(opened[3])
    return True


def _open(path: Path, table: str, problems: list[str],
          columns: tuple[str, ...] | None) -> tuple[pq.ParquetFile, list[str], list, list[str]] | None:
    """The open file, the columns to read from it, the schema's wanted columns and the notes on it: a
    schema version the analyzer does not read, every wanted column the file lacks (filled with nulls)."""
    where = f"{path.parent.name}/{path.name}"
    try:
        pf = pq.ParquetFile(path, read_dictionary=_READ_AS_DICTIONARY.get(table, ()))
        schema = pf.schema_arrow
    except FileNotFoundError:
        return None
    except Exception as exc:  # noqa: BLE001 - pyarrow raises many types for a corrupt file
        problems.append(f"{where}: unreadable ({type(exc).__name__}: {exc})")
        return None
    present = set(schema.names)
    wanted = [c for c in TABLES[table] if columns is None or c.name in columns]
    names = [c.name for c in wanted if c.name in present]
    if table == "messages":   # broadcast rows expand to one per destination (see below)
        names += [c for c in ("dst", "reason") if c in present and c not in names]
    notes = []
    version = (schema.metadata or {}).get(b"swarmbox.schema", SCHEMA_VERSION.encode()).decode()
    if version not in READABLE_VERSIONS:
        notes.append(f"{where}: schema version {version}, analyzer reads {', '.join(READABLE_VERSIONS)}")
    notes += [f"{where}: column {c.name!r} missing (filled with NA)" for c in wanted if c.name not in present]
    return pf, names, wanted, notes


def _conformed(data: pa.Table, table: str, wanted: list, node: int) -> pa.Table:
    """Rows read from one node's file in the schema's types (text of :data:`_READ_AS_DICTIONARY` as
    dictionaries), absent columns as nulls, plus ``node``."""
    if table == "messages":   # version 2's one row per broadcast, as version 1's one per destination
        data = expand_broadcasts(data)
    as_dictionary = _READ_AS_DICTIONARY.get(table, ())
    arrays, fields = [], []
    for col in wanted:
        typ = _ARROW[col.dtype]
        if col.name in as_dictionary:
            typ = pa.dictionary(pa.int32(), typ)
        if col.name in data.column_names:
            column = data.column(col.name)
            if column.type != typ and pa.types.is_dictionary(typ):   # not text in the file: as before
                column = pc.dictionary_encode(column.cast(typ.value_type))
            arrays.append(column.cast(typ))
        else:
            arrays.append(pa.nulls(len(data), typ))
        fields.append(pa.field(col.name, typ))
    arrays.append(pa.array(np.full(len(data), node, dtype=np.int16)))
    fields.append(pa.field("node", pa.int16()))
    return pa.Table.from_arrays(arrays, schema=pa.schema(fields))
