"""Resuming a sweep: ``run.resume=true`` skips the runs that already finished.

A run directory that holds a finished run (``run.json`` with status ``ok`` or ``aborted``) is left
alone and the job reports its recorded status, so re-running an interrupted study with the same
``hydra.sweep.dir`` flies only the rest. A directory whose run failed or was cut short is flown
again; its earlier ``run.json``, ``config.yaml`` and ``logs/`` are kept beside it with a
``.failed-<k>`` suffix, never deleted.
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any

from swarmbox.run.record import redact_overrides

FINISHED = ("ok", "aborted")
_KEPT = ("run.json", "config.yaml", "logs")


class ResumeMismatchError(RuntimeError):
    """The finished run in the directory was made with other overrides than this job's."""


def finished_run(run_dir: Path, overrides: list[str]) -> dict[str, Any] | None:
    """The manifest of the finished run in ``run_dir`` (or None: the job must fly).

    Raises :class:`ResumeMismatchError` when that run was made with other overrides, which happens
    when the sweep's parameters changed between the two invocations.
    """
    path = run_dir / "run.json"
    if not path.is_file():
        return None
    try:
        manifest = json.loads(path.read_text())
    except (OSError, ValueError):
        manifest = {"status": "unreadable"}
    if manifest.get("status") in FINISHED:
        recorded = _job_overrides(manifest.get("overrides") or [])
        wanted = _job_overrides(redact_overrides(overrides))   # recorded ones hide key values
        if recorded != wanted:
            raise ResumeMismatchError(
                f"{run_dir} holds a finished run made with overrides {recorded}, not {wanted}; "
                "resume the same sweep (same parameters and hydra.sweep.dir) or use a new directory")
        return manifest
    _set_aside(run_dir)
    return None


def _job_overrides(overrides: list[str]) -> list[str]:
    """The overrides that make a run what it is (``run.resume`` and ``run.progress`` do not)."""
    return sorted(o for o in overrides if not o.lstrip("+~").startswith(("run.resume=", "run.progress=")))


def _set_aside(run_dir: Path) -> None:
    """Rename a failed run's files to ``<name>.failed-<k>`` (k = first free number)."""
    k = 1
    while any((run_dir / _aside(name, k)).exists() for name in _KEPT):
        k += 1
    for name in _KEPT:
        if (run_dir / name).exists():
            os.replace(run_dir / name, run_dir / _aside(name, k))


def _aside(name: str, k: int) -> str:
    stem, dot, ext = name.partition(".")
    return f"{stem}.failed-{k}{dot}{ext}"
