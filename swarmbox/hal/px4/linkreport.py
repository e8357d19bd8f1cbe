"""What a vehicle's link saw, as events: garbage, other system ids, impostors, bad signatures, stats.

Each new kind of trouble is reported once, when first seen (counts since the last report for garbage
and signatures); ``link/stats`` every ``stats_every_s``.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from swarmbox.hal.mavlink.link import Address, VehicleLink

Emit = Callable[[str, str, dict[str, Any]], None]


def _addr(a: Address | None) -> str | None:
    return None if a is None else f"{a[0]}:{a[1]}"


class LinkReport:
    """Called about once a second with the vehicle's time; emits ``link/*`` events for what is new."""

    def __init__(self, link: VehicleLink, emit: Emit, stats_every_s: float) -> None:
        self._link, self._emit, self._every_s = link, emit, stats_every_s
        self._bad_seen, self._sig_seen, self._stats_s = (0, 0), 0, 0.0
        self._foreign_seen: set[int] = set()
        self._conflicts_seen: set[Address] = set()

    def __call__(self, now_s: float, connected: bool) -> None:
        link, emit = self._link, self._emit
        dec, st = link.decoder, link.stats
        bad = (dec.garbage_bytes, dec.bad_packets)
        if bad != self._bad_seen:
            emit("link", "garbage", {"garbage_bytes": bad[0] - self._bad_seen[0],
                                     "bad_packets": bad[1] - self._bad_seen[1]})
            self._bad_seen = bad
        for sysid in st.foreign.keys() - self._foreign_seen:   # before connecting: the wrong id
            self._foreign_seen.add(sysid)
            emit("link", "foreign_system" if connected else "wrong_system_id",
                 {"system_id": sysid, "packets": st.foreign[sysid], "expected": link.system_id})
        for addr in st.conflicts.keys() - self._conflicts_seen:
            self._conflicts_seen.add(addr)
            emit("link", "conflict", {"system_id": link.system_id, "address": _addr(addr),
                                      "bound": _addr(link.bound), "packets": st.conflicts[addr],
                                      "action": "dropped"})
        if dec.signature_rejected != self._sig_seen:
            emit("link", "signature_rejected", {"packets": dec.signature_rejected - self._sig_seen})
            self._sig_seen = dec.signature_rejected
        if connected and now_s - self._stats_s >= self._every_s:
            self._stats_s = now_s
            emit("link", "stats", st.as_dict(dec))
