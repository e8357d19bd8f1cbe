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

