"""Draws the dashboard's lines in place on a terminal, rewriting only the lines that changed.

rich's ``Live`` re-lays out and re-emits the whole screen every frame (wrapping, measuring, cropping
every segment): about 1 ms of CPU for four drones, which on a real-time run is a large share of an
otherwise idle ground process. The dashboard's lines are already fixed-width text, so this writer
only needs rich for what it does well — turning a style name into the terminal's escape codes for
its colour system — and keeps the previous frame to skip every line that did not change (the header
clock always does; a hovering drone's row often does not). Less CPU, and fewer bytes over SSH.

A line is a tuple of ``(text, style)`` spans. Lines are cropped to the terminal's width so that none
wraps, which keeps the cursor arithmetic exact. On a stream that is not a terminal nothing is drawn
until :meth:`Screen.close`, which prints the last frame once, plain.
"""

from __future__ import annotations

from typing import TextIO

from rich.console import COLOR_SYSTEMS, Console
from rich.style import Style

Span = tuple[str, str]
Line = tuple[Span, ...]

_ERASE_LINE = "\x1b[K"
_ERASE_BELOW = "\x1b[J"


def plain(line: Line) -> str:
    return "".join(text for text, _ in line)


class Screen:
    """The dashboard's region of the terminal: the last frame drawn, and how to update it."""

    def __init__(self, console: Console) -> None:
        self.console = console
        self.live = console.is_terminal
        self._file: TextIO = console.file
        system = console.color_system
        self._colours = None if console.no_color or system is None else COLOR_SYSTEMS[system]
        self._shown: list[Line] = []       # what the terminal holds now, top to bottom
        self._last: list[Line] = []        # the latest frame handed in (drawn or not)
        self.lines_written = 0

    def width(self) -> int:
        return max(20, self.console.size.width)

    def height(self) -> int:
        return max(5, self.console.size.height)

    def draw(self, lines: list[Line]) -> bool:
        """Show ``lines``; returns False when nothing had to be written (the same frame again)."""
        self._last = lines
        if not self.live or lines == self._shown:
            return False
        width = self.width() - 1
        lines = lines[: self.height() - 1]
        shown, out = self._shown, []
        if len(shown) > 1:
            out.append(f"\x1b[{len(shown) - 1}A")   # up to the region's first line
        for i, line in enumerate(lines):
            if i:
                out.append("\n")
            if i < len(shown) and shown[i] == line:
                continue
            out.append("\r" + self._ansi(line, width) + _ERASE_LINE)
            self.lines_written += 1
        if len(lines) < len(shown):   # the frame got shorter: clear what was below it, come back
            out.append(f"\n\r{_ERASE_BELOW}\x1b[1A")
        self._file.write("".join(out))
        self._file.flush()
        self._shown = list(lines)
        return True

    def close(self) -> None:
        """Leave the last frame on screen (on a plain stream: print it once) and move below it."""
        if self.live:
            self.draw(self._last)
            if self._shown:
                self._file.write("\n")
        else:
            width = self.width()
            self._file.write("".join(_crop(plain(line), width) + "\n" for line in self._last))
        self._file.flush()

    def _ansi(self, line: Line, width: int) -> str:
        out, room = [], width
        for text, style in line:
            if room <= 0:
                break
            if len(text) > room:
                text = text[: room - 1] + "…"
            room -= len(text)
            if style and self._colours is not None:
                text = Style.parse(style).render(text, color_system=self._colours)
            out.append(text)
        return "".join(out)


def _crop(text: str, width: int) -> str:
    return text if len(text) <= width else text[: width - 1] + "…"
