"""Hydra callbacks: a closing summary of every sweep (and a non-zero exit if a run failed)."""

from __future__ import annotations

import json
import sys
from collections import Counter
from pathlib import Path
from typing import Any

from hydra.experimental.callback import Callback
from omegaconf import DictConfig


class SweepSummary(Callback):
    """After a multirun: count statuses from each run's ``run.json``; exit 1 if any run failed.

    The other runs of the sweep always run to the end; only the process exit code reports failures.
    """

    def on_multirun_end(self, config: DictConfig, **kwargs: Any) -> None:
        root = Path(config.hydra.sweep.dir)
        manifests = []
        for path in sorted(root.glob("*/run.json")):
            try:
                manifests.append((path.parent, json.loads(path.read_text())))
            except (OSError, ValueError) as exc:
                print(f"unreadable {path}: {exc}", file=sys.stderr)
        counts = Counter(m.get("status", "?") for _, m in manifests)
        summary = ", ".join(f"{n} {s}" for s, n in sorted(counts.items()))
        print(f"sweep {root}: {len(manifests)} runs ({summary})", flush=True)
        failed = [(d, m) for d, m in manifests if m.get("status") == "failed"]
        for d, m in failed:
            print(f"  failed: {d}: {m.get('reason')}", file=sys.stderr)
        if failed:
            sys.exit(1)


class AnalyzeSweep(Callback):
    """After a multirun: tables and figures for the whole sweep (``swarmbox.analysis``).

    The analysis library is imported only here, at the end of a sweep, so runs themselves never
    load pandas or matplotlib. Switch it off with ``~hydra.callbacks.analyze`` on the command line.
    """

    def __init__(self, group_by: list[str] | tuple[str, ...] = ("algo",), figures: bool = True) -> None:
        self.group_by, self.figures = tuple(group_by), figures

    def on_multirun_end(self, config: DictConfig, **kwargs: Any) -> None:
        from swarmbox.analysis.callback import AnalyzeSweepCallback

        AnalyzeSweepCallback(group_by=self.group_by, figures=self.figures).on_multirun_end(config, **kwargs)
