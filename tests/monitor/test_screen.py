"""The line writer: rewrites only changed lines, crops to the terminal, draws nothing when nothing
changed, and prints the last frame once on a stream that is not a terminal."""

from __future__ import annotations

import io

from rich.console import Console

from swarmbox.monitor.screen import Screen


def _console(terminal: bool) -> tuple[Console, io.StringIO]:
    out = io.StringIO()
    return Console(file=out, force_terminal=terminal, width=30, height=10, color_system="standard"), out


def _frame(t: float, alt: float) -> list:
    return [((f"t {t:.1f} s", "bold"),), (("drone 0 ", ""), ("alive", "green"), (f" {alt:.1f} m", "")),
            (("drone 1 alive 5.0 m", ""),)]


def test_only_changed_lines_are_rewritten():
    console, out = _console(True)
    screen = Screen(console)
    assert screen.draw(_frame(1.0, 5.0)) and screen.lines_written == 3
    first = out.getvalue()
    assert "\x1b[1mt 1.0 s\x1b[0m" in first and "\x1b[32malive\x1b[0m" in first   # rich's styles
    out.truncate(0), out.seek(0)
    assert screen.draw(_frame(1.5, 5.0)) and screen.lines_written == 4   # only the clock line
    second = out.getvalue()
    assert second.startswith("\x1b[2A") and "t 1.5 s" in second and "drone" not in second
    out.truncate(0), out.seek(0)
    assert not screen.draw(_frame(1.5, 5.0)) and out.getvalue() == ""    # the same frame: nothing
    screen.draw([((f"{'x' * 50}", ""),)])                                  # shorter, and too wide
    third = out.getvalue()
    assert "x" * 28 + "…" in third and "x" * 30 not in third and "\x1b[J" in third


def test_a_plain_stream_gets_the_last_frame_once():
    console, out = _console(False)
    screen = Screen(console)
    assert not screen.draw(_frame(1.0, 5.0)) and not screen.draw(_frame(2.0, 6.0))
    assert out.getvalue() == ""
    screen.close()
    assert out.getvalue() == "t 2.0 s\ndrone 0 alive 6.0 m\ndrone 1 alive 5.0 m\n"
