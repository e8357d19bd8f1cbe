"""Writing tables: CSV (full precision, for machines) and Markdown (rounded, for people)."""

from __future__ import annotations

import math
from pathlib import Path

import pandas as pd


def format_value(value: object, digits: int = 4) -> str:
    if isinstance(value, bool):
        return str(value)
    if isinstance(value, float | int) and not isinstance(value, bool):
        if isinstance(value, float) and math.isnan(value):
            return ""
        if isinstance(value, float) and math.isinf(value):
            return "inf" if value > 0 else "-inf"
        if isinstance(value, int):
            return str(value)
        return f"{value:.{digits}g}"
    if value is None or value is pd.NA:
        return ""
    return str(value)


def to_markdown(frame: pd.DataFrame, digits: int = 4, index: bool = False) -> str:
    """A GitHub-flavoured Markdown table of ``frame`` (numbers to ``digits`` significant digits)."""
    if index:
        frame = frame.reset_index()
    header = [str(c) for c in frame.columns]
    rows = [[format_value(v.item() if hasattr(v, "item") else v, digits) for v in row]
            for row in frame.itertuples(index=False)]
    lines = ["| " + " | ".join(header) + " |", "|" + "|".join("---" for _ in header) + "|"]
    lines += ["| " + " | ".join(cell.replace("|", "\\|") for cell in row) + " |" for row in rows]
    return "\n".join(lines) + "\n"


def write_table(frame: pd.DataFrame, directory: Path, name: str, markdown: bool = True) -> list[Path]:
    """Write ``<name>.csv`` (and ``<name>.md``) in ``directory``; returns the written paths."""
    directory.mkdir(parents=True, exist_ok=True)
    csv_path = directory / f"{name}.csv"
    frame.to_csv(csv_path, index=False)
    written = [csv_path]
    if markdown:
        md_path = directory / f"{name}.md"
        md_path.write_text(to_markdown(frame))
        written.append(md_path)
    return written
