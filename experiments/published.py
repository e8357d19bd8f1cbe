"""Published tables are data: check (or rewrite) every table of numbers in the documentation.

    python -m experiments.published --check    # exit 1 naming every stale or unmarked table
    python -m experiments.published --write    # rewrite every marked block from its data file

Documents: ``README.md``, ``docs/*.md`` and ``experiments/*/README.md``. A table of results sits
between two markers naming the committed file it is generated from::

    <!-- generated: experiments/rq4_delivery/results/rq4_table.md -->
    | algo | ... |
    <!-- /generated -->

A ``.md`` source is copied verbatim; a ``.csv`` source is rendered as a markdown table with its cells
as written in the file (the experiment's own script formats the numbers once, when it writes the
CSV). The block must equal its source exactly, character for character.

Every other markdown table with a digit in a body cell must say, on the line right above it, why
it is not generated:

- ``<!-- not results: <what it is> -->``: parameters, definitions, exit codes, examples;
- ``<!-- measured: <where and under what load> -->``: machine figures (wall time, CPU, memory,
  real-time flights) that no rerun reproduces exactly, so there is nothing to check them against;
- ``<!-- pending data: <why> -->``: results still typed by hand; ``--check`` lists them, so the debt
  stays visible until a script writes their data file.

A number-bearing table with none of these fails the check: a result typed into a document by hand
goes stale the first time the code under it moves.
"""

from __future__ import annotations

import argparse
import csv
import io
import re
import sys
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
BEGIN = re.compile(r"^\s*<!-- generated: (?P<source>\S+) -->\s*$")
END = re.compile(r"^\s*<!-- /generated -->\s*$")
#: Markers of a number-bearing table that is not generated, each with its reason after the colon.
EXEMPT = re.compile(r"^\s*<!-- (?P<kind>not results|measured|pending data): \S.* -->\s*$")
SEPARATOR = re.compile(r"^\s*\|(\s*:?-+:?\s*\|)+\s*$")
CODE_SPAN = re.compile(r"`[^`]*`")


class PublishedError(ValueError):
    """A marker that cannot be honoured (unclosed block, missing source): bad input, exit 2."""


@dataclass(frozen=True)
class Problem:
    """One disagreement between a document and its data, or one unmarked table of numbers."""

    doc: str
    line: int
    message: str

    def __str__(self) -> str:
        return f"{self.doc}:{self.line}: {self.message}"


@dataclass(frozen=True)
class Block:
    """A generated block: its source file and the 0-based line range of its body (end exclusive)."""

    source: str
    begin: int
    end: int


def documents(root: Path = ROOT) -> list[Path]:
    """Every document whose tables are checked, in a stable order."""
    docs = [root / "README.md", *sorted((root / "docs").glob("*.md")),
            *sorted((root / "experiments").glob("*/README.md"))]
    return [d for d in docs if d.is_file()]


def render(source: Path) -> str:
    """The markdown a block generated from ``source`` must hold (no trailing newline)."""
    if not source.is_file():
        raise PublishedError(f"{source}: data file of a generated block not found")
    if source.suffix == ".md":
        return source.read_text(encoding="utf-8").rstrip("\n")
    if source.suffix == ".csv":
        rows = list(csv.reader(io.StringIO(source.read_text(encoding="utf-8"))))
        if not rows:
            raise PublishedError(f"{source}: empty CSV")
        lines = ["| " + " | ".join(rows[0]) + " |", "|" + "---|" * len(rows[0])]
        lines += ["| " + " | ".join(cells) + " |" for cells in rows[1:]]
        return "\n".join(lines)
    raise PublishedError(f"{source}: a generated block's source must be .md or .csv")


def blocks(lines: list[str], doc: str) -> list[Block]:
    """The generated blocks of a document; an unclosed or nested block is bad input."""
    out, open_at, source = [], None, ""
    for i, line in enumerate(lines):
        if m := BEGIN.match(line):
            if open_at is not None:
                raise PublishedError(f"{doc}:{i + 1}: generated block opened inside another")
            open_at, source = i, m["source"]
        elif END.match(line):
            if open_at is None:
                raise PublishedError(f"{doc}:{i + 1}: '<!-- /generated -->' without an opening marker")
            out.append(Block(source, open_at + 1, i))
            open_at = None
    if open_at is not None:
        raise PublishedError(f"{doc}:{open_at + 1}: generated block never closed")
    return out


def tables(lines: list[str]) -> Iterator[tuple[int, int]]:
    """(first line, end line exclusive) of every markdown table: a row line followed by a separator."""
    i = 0
    while i < len(lines) - 1:
        if lines[i].lstrip().startswith("|") and SEPARATOR.match(lines[i + 1]):
            j = i + 2
            while j < len(lines) and lines[j].lstrip().startswith("|"):
                j += 1
            yield i, j
            i = j
        else:
            i += 1


def has_numbers(rows: list[str]) -> bool:
    """True when a body cell holds a digit outside code spans (names like `rq4_ci` are not numbers)."""
    return any(re.search(r"\d", CODE_SPAN.sub("", row)) for row in rows)


def exemption(lines: list[str], first: int) -> str | None:
    """The kind of exemption marker on the nearest non-blank line above the table, if any."""
    k = first - 1
    while k >= 0 and not lines[k].strip():
        k -= 1
    m = EXEMPT.match(lines[k]) if k >= 0 else None
    return m["kind"] if m else None


def check_document(path: Path, root: Path = ROOT, *, pending: list[Problem] | None = None) -> list[Problem]:
    """Stale generated blocks and unmarked tables of numbers in one document; tables marked
    ``pending data`` are appended to ``pending`` when it is given."""
    doc = str(path.relative_to(root))
    lines = path.read_text(encoding="utf-8").splitlines()
    found = blocks(lines, doc)
    problems = []
    for b in found:
        want = render(root / b.source)
        indent = re.match(r"\s*", lines[b.begin - 1])[0]
        if "\n".join(line[len(indent):] for line in lines[b.begin:b.end]) != want:
            problems.append(Problem(doc, b.begin, f"stale: differs from {b.source} "
                                    "(python -m experiments.published --write)"))
    inside = {i for b in found for i in range(b.begin, b.end)}
    for first, end in tables(lines):
        kind = exemption(lines, first)
        if kind == "pending data" and pending is not None:
            pending.append(Problem(doc, first + 1, "results typed by hand (pending data)"))
        if first in inside or kind or not has_numbers(lines[first + 2:end]):
            continue
        problems.append(Problem(doc, first + 1, "table of numbers neither generated from data "
                                "('<!-- generated: FILE -->') nor marked '<!-- not results: why -->'"))
    return problems


def write_document(path: Path, root: Path = ROOT) -> bool:
    """Rewrite every generated block of ``path`` from its source (indented as its marker); True if
    the file changed. The rewrite goes to a sibling file first, then replaces the document."""
    text = path.read_text(encoding="utf-8")
    lines = text.splitlines()
    for b in reversed(blocks(lines, str(path.relative_to(root)))):
        indent = re.match(r"\s*", lines[b.begin - 1])[0]
        body = [indent + line if line else line for line in render(root / b.source).split("\n")]
        lines[b.begin:b.end] = body
    new = "\n".join(lines) + ("\n" if text.endswith("\n") else "")
    if new == text:
        return False
    tmp = path.with_name(path.name + ".partial")
    tmp.write_text(new, encoding="utf-8")
    tmp.replace(path)
    return True


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m experiments.published",
                                     description=__doc__.split("\n")[0])
    mode = parser.add_mutually_exclusive_group(required=True)
    mode.add_argument("--check", action="store_true", help="exit 1 if a document disagrees with its data")
    mode.add_argument("--write", action="store_true", help="rewrite every generated block from its data")
    args = parser.parse_args(argv)
    try:
        docs = documents()
        for path in docs:       # every marker and source valid before any document is rewritten
            check_document(path)
        if args.write:
            for path in docs:
                if write_document(path):
                    print(f"rewrote {path.relative_to(ROOT)}")
        pending: list[Problem] = []
        problems = [p for path in docs for p in check_document(path, pending=pending)]
    except PublishedError as exc:
        print(f"published: {exc}", file=sys.stderr)
        return 2
    for p in pending:
        print(p, file=sys.stderr)
    for p in problems:
        print(p)
    return 1 if problems else 0


if __name__ == "__main__":
    sys.exit(main())
