"""Rows to Arrow columns, without pandas (an agent process must not load it).

Nodes buffer the rare tables' rows as plain tuples; the recorder turns a chunk of them into one Arrow
record batch per table. The conversion runs once per chunk of many nodes' rows (not once per node), so
its fixed costs do not grow with the swarm. (The frequent tables are packed instead:
:mod:`swarmbox.record.packed`.)
"""

from __future__ import annotations

from collections.abc import Sequence
from functools import cache
from operator import itemgetter

import numpy as np
import pyarrow as pa

from swarmbox.record.schema import SCHEMA_VERSION, TABLES

_TYPES = {"float64": pa.float64(), "int64": pa.int64(), "int32": pa.int32(), "int16": pa.int16(),
          "int8": pa.int8(), "bool": pa.bool_(), "string": pa.string()}
NUMPY = {pa.float64(): np.float64, pa.int64(): np.int64, pa.int32(): np.int32, pa.int16(): np.int16,
          pa.int8(): np.int8}
#: The column the spill files add to every table: which node wrote the row.
NODE = pa.field("node", pa.int16())


@cache
def arrow_schema(table: str) -> pa.Schema:
    """The declared schema of one per-node table, with units and docs as field metadata."""
    cols = TABLES[table]
    fields = [pa.field(c.name, _TYPES[c.dtype], metadata={"unit": c.unit, "doc": c.doc}) for c in cols]
    return pa.schema(fields, metadata={"swarmbox.schema": SCHEMA_VERSION, "swarmbox.table": table})


@cache
def spill_schema(table: str) -> pa.Schema:
    """A table's schema plus the writing node, for the run-wide spill file."""
    return arrow_schema(table).append(NODE)


@cache
def text_columns(table: str) -> list[str]:
    """The table's text columns: the only ones worth dictionary-encoding in Parquet. Numbers rarely
    repeat (times, positions), and trying a dictionary on them first doubles the cost of a write."""
    return [c.name for c in TABLES[table] if c.dtype == "string"]


def column(values: Sequence, typ: pa.DataType) -> pa.Array:
    """One Arrow column built from raw buffers (``pa.array`` on Python objects would import pandas)."""
    n = len(values)
    if typ == pa.string():
        return strings(values)
    if typ == pa.bool_():
        bits = np.packbits(np.asarray(values, dtype=bool), bitorder="little")
        return pa.Array.from_buffers(typ, n, [None, pa.py_buffer(bits)])
    return pa.Array.from_buffers(typ, n, [None, pa.py_buffer(np.asarray(values, dtype=NUMPY[typ]))])


def strings(values: Sequence[str]) -> pa.Array:
    n = len(values)
    if type(values) is list and n and values.count(values[0]) == n and n * len(values[0].encode()) < 2**31:
        return repeated(values[0], n)   # one value throughout (a setpoint's kind, "ok", ""): no scan
    joined = "".join(values)
    data = joined.encode()
    offsets = np.zeros(n + 1, dtype=np.int64)
    if len(data) == len(joined):   # ASCII (the usual case): character lengths are byte lengths
        np.cumsum(np.fromiter(map(len, values), dtype=np.int64, count=n), out=offsets[1:])
    else:
        np.cumsum(np.fromiter((len(v.encode()) for v in values), dtype=np.int64, count=n), out=offsets[1:])
    if offsets[-1] < 2**31:
        return pa.Array.from_buffers(pa.string(), n, [None, pa.py_buffer(offsets.astype(np.int32)),
                                                      pa.py_buffer(data)])
    big = pa.Array.from_buffers(pa.large_string(), n, [None, pa.py_buffer(offsets), pa.py_buffer(data)])
    return big.cast(pa.string())


def repeated(value: str, n: int) -> pa.Array:
    """``n`` copies of ``value`` as a string column (int32 offsets: fewer than 2**31 bytes in all)."""
    data = value.encode()
    offsets = np.arange(n + 1, dtype=np.int32) * np.int32(len(data))
    return pa.Array.from_buffers(pa.string(), n, [None, pa.py_buffer(offsets), pa.py_buffer(data * n)])


def _field(rows: Sequence[tuple], index: int, typ: pa.DataType) -> pa.Array:
    """Column ``index`` of ``rows``: numbers straight into numpy (``zip(*rows)`` would build a tuple
    per column first and costs twice as much)."""
    n = len(rows)
    if typ in NUMPY:
        values = np.fromiter(map(itemgetter(index), rows), dtype=NUMPY[typ], count=n)
        return pa.Array.from_buffers(typ, n, [None, pa.py_buffer(values)])
    return column(list(map(itemgetter(index), rows)), typ)


def batch(table: str, rows: Sequence[tuple], node: np.ndarray | None = None) -> pa.RecordBatch:
    """A record batch of ``rows`` (schema column order); with ``node``, in the spill schema."""
    schema = arrow_schema(table) if node is None else spill_schema(table)
    arrays = [_field(rows, i, f.type) for i, f in enumerate(schema) if i < len(TABLES[table])]
    if node is not None:
        arrays.append(numbers(node, NODE.type))
    return pa.RecordBatch.from_arrays(arrays, schema=schema)


def numbers(values: np.ndarray, typ: pa.DataType) -> pa.Array:
    """A numeric Arrow column over a numpy array's buffer (``pa.array(ndarray)`` imports pandas)."""
    data = np.ascontiguousarray(values, NUMPY[typ])
    return pa.Array.from_buffers(typ, len(data), [None, pa.py_buffer(data)])
