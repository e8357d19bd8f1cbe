"""Long STATUSTEXT lines: MAVLink 2 carries at most 50 characters per message and splits a longer line
into chunks that share a non-zero ``id`` and count up in ``chunk_seq``; a chunk shorter than 50
characters (its text ends in a NUL) is the last. PX4 sends its failsafe and pre-arm explanations this
way, so a bridge that logged each packet would cut one sentence into several events.

``split`` is the sending side (mavsim speaks like PX4); ``TextAssembler`` the receiving side: it gives
back whole lines once every chunk up to the last has come (in any order), and a line whose last
chunk never comes (lost, or a line of exactly 50·k characters, which has no NUL to end it) once
``stale_s`` has passed without a new chunk.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

CHUNK = 50                 # STATUSTEXT's text field
WARNING = 4                # RFC-5424 severities: this or worse is logged as an event
CRITICAL = 2               # ... and this or worse may explain what the autopilot does next
ALERT_WINDOW_S = 3.0       # how long a critical line explains a mode change


def split(text: str, line_id: int) -> list[tuple[str, int, int]]:
    """``(chunk, id, chunk_seq)`` for one line: a short line is one chunk with id 0."""
    data = text.encode()
    if len(data) <= CHUNK:
        return [(text, 0, 0)]
    parts = [data[i:i + CHUNK] for i in range(0, len(data), CHUNK)]
    return [(p.decode("utf-8", "replace"), line_id, seq) for seq, p in enumerate(parts)]


@dataclass
class _Pending:
    severity: int
    since_s: float
    chunks: dict[int, str] = field(default_factory=dict)
    last_seq: int = -1         # known once the chunk ending in a NUL has come

    def text(self) -> str:
        return "".join(self.chunks[k] for k in sorted(self.chunks))


class TextAssembler:
    """Whole STATUSTEXT lines out of chunks, per sender (one assembler per vehicle)."""

    def __init__(self, stale_s: float = 1.0) -> None:
        self.stale_s = stale_s
        self._pending: dict[int, _Pending] = {}

    @property
    def waiting(self) -> bool:
        return bool(self._pending)

    def feed(self, severity: int, text: str, line_id: int, chunk_seq: int,
             now_s: float) -> list[tuple[int, str]]:
        """The lines this chunk completes (usually none or one), oldest first."""
        out = self.flush(now_s)
        if line_id == 0:
            return out + [(severity, text)]
        pending = self._pending.setdefault(line_id, _Pending(severity, now_s))
        pending.chunks[chunk_seq] = text
        pending.since_s = now_s
        if len(text.encode()) < CHUNK:
            pending.last_seq = chunk_seq
        if pending.last_seq >= 0 and len(pending.chunks) == pending.last_seq + 1:
            del self._pending[line_id]
            out.append((pending.severity, pending.text()))
        return out

    def flush(self, now_s: float, everything: bool = False) -> list[tuple[int, str]]:
        """Lines whose last chunk has not come within ``stale_s`` (all of them with ``everything``)."""
        done = [k for k, p in self._pending.items() if everything or now_s - p.since_s >= self.stale_s]
        return [(p.severity, p.text()) for p in (self._pending.pop(k) for k in done)]


class StatusTexts:
    """A vehicle's STATUSTEXT stream: whole lines at warning or worse become ``command/statustext``
    events; the latest critical line is kept to explain an autopilot's own mode change."""

    def __init__(self, emit: Callable[[str, str, dict[str, Any]], None]) -> None:
        self._emit = emit
        self._lines = TextAssembler()
        self._alert: tuple[float, str] = (float("-inf"), "")

    def on_chunk(self, severity: int, text: str, line_id: int, chunk_seq: int, now_s: float) -> None:
        self._report(self._lines.feed(severity, text, line_id, chunk_seq, now_s), now_s)

    def service(self, now_s: float) -> None:
        """Lines whose last chunk never came (call now and then)."""
        if self._lines.waiting:
            self._report(self._lines.flush(now_s), now_s)

    def recent_alert(self, now_s: float) -> str:
        """The latest critical line if it came within ``ALERT_WINDOW_S``, else ``""``."""
        at_s, text = self._alert
        return text if now_s - at_s <= ALERT_WINDOW_S else ""

    def _report(self, lines: list[tuple[int, str]], now_s: float) -> None:
        for severity, text in lines:
            if severity <= WARNING:
                self._emit("command", "statustext", {"severity": severity, "text": text})
            if severity <= CRITICAL:
                self._alert = (now_s, text.strip())
