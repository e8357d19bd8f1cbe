"""Hydra callbacks: a closing summary of every sweep (and a non-zero exit if a run did not succeed)."""

from __future__ import annotations

import json
import sys
from collections import Counter
from pathlib import Path
from typing import Any

from hydra.experimental.callback import Callback
from omegaconf import DictConfig

from swarmbox.run import claims, interrupt, record, sweep_state
from swarmbox.run.record import RunExistsError, write_atomic


class SweepSummary(Callback):
    """After a multirun: count statuses from each run's ``run.json``, write ``sweep.json``, print it.

    The other runs of a sweep always run to the end, except after SIGINT / SIGTERM: then the run in
    progress is finished as ``interrupted`` and no further job starts. Exit code: 128+signal if
    interrupted, else 2 if a job's config was refused, else 1 if a run failed, else 0.
    """

    _claim: claims.Claim | None = None

    def on_run_start(self, config: DictConfig, **kwargs: Any) -> None:
        """Before Hydra makes the run directory: note whether it existed (a refused command never
        removes it), and refuse one that cannot be made in one line (exit 2)."""
        from hydra.core.hydra_config import HydraConfig

        HydraConfig.instance().set_config(config)   # as Hydra does next: hydra.run.dir reads it
        run_dir = Path(config.hydra.run.dir)
        claims.note_preexisting(run_dir)
        record.scrub_logging(record.secret_values(config, list(config.hydra.overrides.task)))
        try:
            run_dir.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            _refuse(f"run directory {run_dir} (hydra.run.dir) cannot be written: {exc.strerror or exc}")

    def on_multirun_start(self, config: DictConfig, **kwargs: Any) -> None:
        """Claim the sweep directory: a second sweep into it while this one runs is refused (exit 2)."""
        sweep_state.entered()   # the config composed: later exit codes are the sweep's, not bad input
        root = Path(config.hydra.sweep.dir)
        claims.note_preexisting(root, *(root.iterdir() if root.is_dir() else ()))
        try:
            self._claim = claims.Claim(root, ".sweep.claim", "sweep").acquire()
        except RunExistsError as exc:
            _refuse(f"{exc}; wait for it to finish or choose another hydra.sweep.dir")
        except OSError as exc:
            _refuse(f"sweep directory {root} (hydra.sweep.dir) cannot be written: {exc.strerror or exc}")

    def on_multirun_end(self, config: DictConfig, **kwargs: Any) -> None:
        root = Path(config.hydra.sweep.dir)
        if self._claim is not None:   # every job has ended
            self._claim.release()
        runs, unreadable = [], []
        for path in sorted(root.glob("*/run.json"), key=lambda p: (len(p.parent.name), p.parent.name)):
            try:
                runs.append((path.parent, json.loads(path.read_text())))
            except (OSError, ValueError) as exc:
                unreadable.append(f"{path}: {exc}")
        counts = Counter(m.get("status", "?") for _, m in runs)
        not_started, invalid = sweep_state.jobs_not_started(), sweep_state.jobs_invalid()
        summary = {
            "sweep_dir": str(root), "counts": dict(sorted(counts.items())),
            "runs": [{"dir": d.name, "status": m.get("status"), "reason": m.get("reason"),
                      "sim_time_s": m.get("sim_time_s"), "ticks": m.get("ticks")} for d, m in runs],
            "invalid": [{"overrides": o, "reason": r} for o, r in invalid],
            "not_started": not_started, "unreadable": unreadable,
            "interrupted_by": interrupt.signal_name() or None,
        }
        if root.is_dir():
            write_atomic(root / "sweep.json", json.dumps(summary, indent=2))
        text = ", ".join(f"{n} {s}" for s, n in sorted(counts.items()))
        extra = "".join([f"; {len(invalid)} refused" if invalid else "",
                         f"; {len(not_started)} not started ({interrupt.signal_name()})"
                         if not_started else ""])
        print(f"sweep {root}: {len(runs)} runs ({text}){extra}", flush=True)
        for d, m in runs:
            if m.get("status") in ("failed", "interrupted"):
                print(f"  {m['status']}: {d}: {m.get('reason')} (t={m.get('sim_time_s', 0):.1f} s)",
                      file=sys.stderr)
        for line in unreadable:
            print(f"  unreadable: {line}", file=sys.stderr)
        code = (interrupt.exit_code() or (2 if invalid else 0)
                or (1 if any(m.get("status") == "failed" for _, m in runs) or unreadable else 0))
        if code:
            sys.exit(code)


def _refuse(reason: str) -> None:
    """Bad input found before anything was written: one line, exit 2."""
    print(f"error: {reason} (nothing was run or written)", file=sys.stderr, flush=True)
    sys.exit(2)
