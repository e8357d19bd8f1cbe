"""Finding run directories (finished or not) under a folder."""

from __future__ import annotations

from pathlib import Path


def find_unfinished(root: str | Path) -> list[Path]:
    """Directories at or below ``root`` that hold a run's files (config.yaml or logs/) but no run.json:
    runs that were killed, or still run."""
    root = Path(root)
    marks = [*root.rglob("config.yaml"), *(p for p in root.rglob("logs") if p.is_dir())]
    dirs = {p.parent for p in marks}
    return sorted(d for d in dirs if not (d / "run.json").is_file())


def find_runs(root: str | Path) -> list[Path]:
    """Every run directory (one holding ``run.json``) at or below ``root``, sorted by path."""
    root = Path(root)
    if (root / "run.json").is_file():
        return [root]
    return sorted(p.parent for p in root.rglob("run.json") if p.is_file())
