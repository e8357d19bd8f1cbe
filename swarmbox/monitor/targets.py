"""Where ``run.rerun`` streams to (its own module: the package and the Rerun stream both use it)."""

from __future__ import annotations

from pathlib import Path

VIEWER_SCHEMES = ("rerun://", "rerun+http://", "rerun+https://")


def rerun_target(value: str, run_dir: Path) -> str:
    """Where ``run.rerun`` streams to: a viewer's URL as given; a relative ``.rrd`` path inside the
    run directory (like everything else a run writes), an absolute one as given."""
    if value.startswith(VIEWER_SCHEMES):
        return value
    path = Path(value).expanduser()
    return str(path if path.is_absolute() else run_dir / path)
