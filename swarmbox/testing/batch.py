"""Conformance of a batch algorithm with the per-drone algorithm it ports.

A :class:`~swarmbox.api.FleetAlgorithm` written as the array form of a
:class:`~swarmbox.api.DroneAlgorithm` should fly the same mission the same way: same setpoints,
same verdicts, same markers, same messages. :func:`check_batch_matches` flies both on the
simulation backend with the same seed and requires every log table to be equal, row for row
(floats bit for bit, NaN equal to NaN)::

    from swarmbox.testing import check_batch_matches

    def test_my_batch_port(tmp_path):
        check_batch_matches(["algo=my_algo"], ["algo=my_algo_batch"], workdir=tmp_path,
                            extra=["fault=gps_drift"], config_dir="conf")

``fleets_of_one=True`` runs the batch algorithm as ``run.runtime=processes`` does, one driver and
one instance per drone (each drone ticking on its own), in one process so that the run stays
deterministic. The usual cause of a difference is arithmetic done in another order or with another
function than the per-drone code (``math.hypot`` against numpy: see ``swarmbox.api.row_norms``).
"""

from __future__ import annotations

import copy
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from omegaconf import DictConfig, open_dict


class BatchMismatch(AssertionError):
    """The batch and the per-drone algorithm did not write the same logs; the message says where."""


@dataclass
class BatchReport:
    """Both runs: manifests (per-drone first) and run directories."""

    manifests: list[dict[str, Any]] = field(default_factory=list)
    run_dirs: list[Path] = field(default_factory=list)


def check_batch_matches(per_drone: Sequence[str], batch: Sequence[str], *, workdir: Path,
                        extra: Sequence[str] = (), seed: int = 0,
                        edit: Callable[[DictConfig], None] | None = None,
                        config_dir: str | Path | None = None, fleets_of_one: bool = False) -> BatchReport:
    """Fly ``per_drone`` and ``batch`` (Hydra overrides, each with ``extra``) and compare their logs.

    Raises :class:`BatchMismatch` listing the differing tables (or a run that failed, or configs that
    do not name a DroneAlgorithm and a FleetAlgorithm); returns both runs otherwise.
    """
    # Hydra and the batch API (numpy) load only when a check runs
    from hydra.utils import get_class

    from swarmbox.api import DroneAlgorithm, FleetAlgorithm
    from swarmbox.testing.runs import compare_logs, compose, fly, search_path_override

    common = [*extra, f"seed={seed}", "run.progress=false"]
    if config_dir is not None:
        common.append(search_path_override(config_dir))
    report = BatchReport()
    for label, overrides, base in (("per_drone", per_drone, DroneAlgorithm),
                                   ("batch", batch, FleetAlgorithm)):
        cfg, choices = compose([*overrides, *common])
        if edit is not None:
            with open_dict(cfg):
                edit(cfg)
        cls = get_class(str(cfg.algo.drone._target_))
        if not issubclass(cls, base):
            raise BatchMismatch(f"{label} run: algo.drone is {cls.__name__}, not a {base.__name__}")
        run_dir = Path(workdir) / label
        prepare = split_fleet if fleets_of_one and base is FleetAlgorithm else None
        report.manifests.append(fly(cfg, choices, run_dir, prepare))
        report.run_dirs.append(run_dir)
    a, b = report.manifests
    problems = [f"{label} run failed: {m['reason']}" for label, m in (("per_drone", a), ("batch", b))
                if m["status"] == "failed"]
    if not problems:
        if (a["status"], a["reason"]) != (b["status"], b["reason"]):
            problems.append(f"outcomes differ: {a['status']} ({a['reason']}) vs "
                            f"{b['status']} ({b['reason']})")
        problems += compare_logs(*report.run_dirs)
    if problems:
        shown = "\n  - ".join(problems)
        raise BatchMismatch(f"batch and per-drone runs differ ({len(problems)} problem(s)):\n  - {shown}")
    return report


def split_fleet(swarm: Any) -> None:
    """Make every drone of ``swarm`` a fleet of one with its own algorithm instance, ticking alone,
    as in ``run.runtime=processes`` (pass as ``prepare`` to :func:`swarmbox.testing.runs.fly`)."""
    from swarmbox.core.batch import FleetDriver

    driver = swarm.fleet_driver
    if driver is None:
        raise ValueError("split_fleet: the swarm's drones do not run a FleetAlgorithm")
    for agent in swarm.agents:   # a copy of the instance no hook has touched yet: a fresh one per drone
        agent.algorithm = FleetDriver(copy.deepcopy(driver.algorithm), [agent]).members[0]
    swarm.fleet_driver = None
