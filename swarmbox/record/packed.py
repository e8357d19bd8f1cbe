"""Packed rows (:mod:`swarmbox.core.rows`) to Arrow: a hand-over's bytes read as one numpy structured
array, numbers as views of it, text codes looked up in C.

A packed table is checked against the log schema on import: same columns in the same order, numbers
of the same width, a text code wherever the schema declares text.
"""

from __future__ import annotations

import numpy as np
import pyarrow as pa
import pyarrow.compute as pc

from swarmbox.core.rows import FIELDS, TEXTS
from swarmbox.record.columns import NUMPY, arrow_schema, numbers, repeated, strings

#: the packed tables, each with its numpy record layout (little-endian, unpadded, as ``struct``)
_STRUCT_TO_NUMPY = {"d": "<f8", "q": "<i8", "i": "<i4", "h": "<i2", "b": "i1", "T": "<i4"}
DTYPES: dict[str, np.dtype] = {
    table: np.dtype([(name, _STRUCT_TO_NUMPY[code]) for name, code in fields])
    for table, fields in FIELDS.items()}
PACKED = frozenset(DTYPES)


def _check(table: str) -> None:
    schema, dtype = arrow_schema(table), DTYPES[table]
    if schema.names != list(dtype.names):
        raise TypeError(f"packed {table} rows have columns {dtype.names}, the schema {schema.names}")
    for field, (_, code) in zip(schema, FIELDS[table], strict=True):
        text = field.type == pa.string()
        if text != (code == "T") or not text and dtype[field.name] != np.dtype(NUMPY[field.type]):
            raise TypeError(f"packed {table}.{field.name} is {code!r}, the schema wants {field.type}")


for _table in DTYPES:
    _check(_table)


def row_size(table: str) -> int:
    return DTYPES[table].itemsize


def packed_batch(table: str, data: bytes | bytearray | memoryview) -> pa.RecordBatch:
    """The rows in ``data`` (whole packed rows of ``table``, concatenated) as a record batch."""
    rows = np.frombuffer(data, dtype=DTYPES[table])
    schema = arrow_schema(table)
    texts: pa.Array | None = None
    arrays = []
    for field in schema:
        col = rows[field.name]
        if field.type != pa.string():
            arrays.append(numbers(col, field.type))
            continue
        first = int(col[0]) if len(col) else 0
        if not len(col) or (col == first).all():   # one text throughout (a kind, "ok", ""): no lookup
            arrays.append(repeated(TEXTS.texts[first] if len(col) else "", len(col)))
            continue
        if texts is None:
            texts = strings(TEXTS.snapshot())
        arrays.append(pc.take(texts, numbers(col, pa.int32())))
    return pa.RecordBatch.from_arrays(arrays, schema=schema)
