"""Broadcast ``send`` rows back to one row per destination, for readers of the ``messages`` table.

Since schema version 2 a Heartbeat published to several subscribers is logged by its sender as one
``send`` row with ``dst`` = :data:`~swarmbox.core.messages.BROADCAST` and the destination ids in
``reason`` (comma-separated): at 200 drones that is one row per tick instead of 200. Version 1 wrote
one ``send`` row per destination. :func:`expand_broadcasts` turns the version-2 form into the
version-1 form — each broadcast row becomes one row per destination, in place, with ``reason``
empty — so every reader sees the same rows from either version.
"""

from __future__ import annotations

import numpy as np
import pyarrow as pa
import pyarrow.compute as pc

from swarmbox.core.messages import BROADCAST

__all__ = ["BROADCAST", "expand_broadcasts"]


def expand_broadcasts(table: pa.Table) -> pa.Table:
    """``table`` (a messages table with at least ``kind``, ``dst`` and ``reason``) with every broadcast
    ``send`` row replaced by one row per destination; other rows and the row order are kept."""
    if not len(table) or "dst" not in table.column_names:
        return table
    dst = table.column("dst").to_numpy(zero_copy_only=False)
    where = np.flatnonzero(dst == BROADCAST)
    if not len(where):
        return table
    texts = table.column("reason").take(pa.array(where))
    flat = pc.list_flatten(pc.split_pattern(texts, ","))
    flat = flat.combine_chunks() if isinstance(flat, pa.ChunkedArray) else flat
    ids = flat.filter(pc.not_equal(flat, ""))   # a broadcast to nobody ("") expands to no row
    chars = pc.utf8_length(texts).to_numpy(zero_copy_only=False)
    commas = pc.count_substring(texts, ",").to_numpy(zero_copy_only=False)
    counts = np.ones(len(table), dtype=np.int64)
    counts[where] = np.where(chars > 0, commas + 1, 0)
    take = np.repeat(np.arange(len(table)), counts)
    # blank the destination lists before copying rows: a 1,000-drone broadcast copied 1,000 times with
    # its 4 KB list would overflow a string column's 2 GB capacity, and the copies drop it anyway
    i_reason = table.column_names.index("reason")
    in_list = np.zeros(len(table), dtype=bool)
    in_list[where] = True
    field = table.schema.field(i_reason)
    table = table.set_column(i_reason, field, pc.if_else(pa.array(in_list), pa.scalar("", field.type),
                                                         table.column(i_reason)))
    out = table.take(pa.array(take))
    new_dst = np.repeat(dst, counts)
    firsts = (np.cumsum(counts) - counts)[where]   # where each broadcast's copies start in ``out``
    n_b = counts[where]
    spans = np.repeat(firsts, n_b) + np.arange(int(n_b.sum())) - np.repeat(np.cumsum(n_b) - n_b, n_b)
    new_dst[spans] = pc.cast(ids, pa.int64()).to_numpy(zero_copy_only=False)
    i_dst = out.column_names.index("dst")
    return out.set_column(i_dst, out.schema.field(i_dst),
                          pa.array(new_dst.astype(out.schema.field(i_dst).type.to_pandas_dtype())))
