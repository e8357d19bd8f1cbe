"""Packed log rows: the tick loop's ``messages`` and ``setpoints`` rows as fixed-size binary records.

These two tables take several rows per drone and tick. A row is written as one ``Struct.pack`` call
appended to the node's ``bytearray`` (both run in C, and cost what building a tuple and appending it
to a list did); the recorder then reads a hand-over as one numpy structured array
(:mod:`swarmbox.record.packed`), so the row's numbers never become Python objects again. Turning
millions of row tuples back into columns, cold in the cache, was the log writer's whole cost.

Text columns are written as codes of :data:`TEXTS`, a process-wide, bounded table that only grows: the
vocabularies (``send``, ``report``, ``ok``, ...) have fixed codes below, free text (a drop reason, a
broadcast's destination list, a safety monitor's reason) takes a code on first use. The field order
and names are the log schema's (``swarmbox.record.schema``), which checks them on import.
"""

from __future__ import annotations

import struct
import threading


class TextTable:
    """Text <-> small integer code. Codes are never reused or removed, so a code read at any time
    decodes with the table as it is later.

    The table holds at most ``limit`` texts: it lives as long as its process (a sweep worker runs
    many jobs), and free text that embeds numbers would otherwise grow it without end. Past the
    limit every new text is logged as :attr:`OVERFLOW` and counted in :attr:`overflowed` (the run
    reports the count in ``run.json`` ``problems``); texts already in the table keep their codes.
    """

    LIMIT = 1 << 16
    OVERFLOW = "(text not logged: the text table is full)"

    def __init__(self, limit: int = LIMIT) -> None:
        self.limit = max(2, int(limit))
        self.texts: list[str] = []
        self._codes: dict[str, int] = {}
        self._lock = threading.Lock()   # a transport may log from its own thread
        self.overflowed = 0             # texts refused a code
        self._overflow: int | None = None

    def code(self, text: str) -> int:
        code = self._codes.get(text)
        if code is None:
            with self._lock:
                code = self._codes.get(text)
                if code is None:
                    code = self._add(str(text))
        return code

    def _add(self, text: str) -> int:
        if len(self.texts) >= self.limit - (self._overflow is None):
            self.overflowed += 1
            if self._overflow is None:   # the last free code: the marker
                self._overflow = len(self.texts)
                self.texts.append(self.OVERFLOW)
            return self._overflow
        code = len(self.texts)
        self.texts.append(text)
        self._codes[text] = code
        return code

    def snapshot(self) -> list[str]:
        """Every text so far, by code."""
        return self.texts[:]


#: The process's text table (codes are internal to a process: the recorder decodes before writing).
TEXTS = TextTable()
NO_TEXT = TEXTS.code("")
SEND, RECV, DROP = TEXTS.code("send"), TEXTS.code("recv"), TEXTS.code("drop")

#: (name, struct code) per column, in the schema's order; ``T``: a text column, written as its
#: :data:`TEXTS` code (an ``i``).
MESSAGE_FIELDS = (("t_s", "d"), ("tick", "q"), ("kind", "T"), ("msg_id", "q"), ("type", "T"),
                  ("src", "h"), ("dst", "h"), ("nbytes", "i"), ("t_sent_s", "d"), ("reason", "T"))
SETPOINT_FIELDS = (("t_s", "d"), ("tick", "q"), ("kind", "T"), ("n", "d"), ("e", "d"), ("d", "d"),
                   ("yaw_rad", "d"), ("verdict", "T"), ("reason", "T"))
#: table -> its columns, for the packed tables
FIELDS = {"messages": MESSAGE_FIELDS, "setpoints": SETPOINT_FIELDS}


def row_struct(fields: tuple[tuple[str, str], ...]) -> struct.Struct:
    """Little-endian, unpadded: the layout numpy reads with the same field list."""
    return struct.Struct("<" + "".join("i" if code == "T" else code for _, code in fields))


STRUCTS = {table: row_struct(fields) for table, fields in FIELDS.items()}
#: ``pack_message(t_s, tick, kind, msg_id, type, src, dst, nbytes, t_sent_s, reason)`` -> one row
pack_message = STRUCTS["messages"].pack
#: ``pack_setpoint(t_s, tick, kind, n, e, d, yaw_rad, verdict, reason)`` -> one row
pack_setpoint = STRUCTS["setpoints"].pack


def unpack_row(table: str, row: bytes) -> tuple:
    """One packed row back as the row tuple, texts as text (for tests and inspection)."""
    values = STRUCTS[table].unpack(row)
    return tuple(TEXTS.texts[v] if code == "T" else v
                 for v, (_, code) in zip(values, FIELDS[table], strict=True))


def unpacking(rows: list, table: str = "messages"):
    """A log that keeps each packed row of ``table`` as its row tuple in ``rows`` (tests, inspection)."""
    return lambda row: rows.append(unpack_row(table, row))
