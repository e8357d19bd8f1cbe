"""Conformance suite every algorithm must pass (like PettingZoo's ``api_test`` for environments).

:func:`check_algorithm` composes a run config exactly as ``python -m swarmbox.run`` does, flies it
twice on the simulation backend under packet loss and jitter, and checks what a researcher relies
on when comparing results:

- **no hook error** — neither run failed;
- **completion** — both runs ended ``ok`` (or, with ``expect="any"``, aborted with a reason), and
  every drone ended on the ground, disarmed;
- **lifecycle order** — on every node, each stage's ``*_once`` hook ran once, before any loop hook
  of that stage, PREPARATION's hooks before EXECUTION's and never after, ``on_task`` never before
  ``prep_once``, and every hook in the stage it belongs to;
- **setpoint types** — ``exec_loop`` returned only ``Setpoint`` (position, velocity or acceleration,
  three finite floats) or None;
- **determinism** — the two runs wrote identical logs, table by table, row by row.

Every violation found is collected; :class:`ConformanceError` lists them all. Use it from pytest::

    from swarmbox.testing import check_algorithm

    def test_my_algorithm(tmp_path):
        check_algorithm(["algo=my_algo", "mission=my_mission"], workdir=tmp_path, config_dir="conf")

``config_dir`` is a folder of your own config groups (``conf/algo/my_algo.yaml`` ...), relative to the
current directory or absolute; it joins the shipped groups as ``swarmbox run --config-dir DIR`` does
(see docs/user-projects.md). ``edit(cfg)`` may shrink the mission (fewer drones, shorter phases)
before the runs. From the shell: ``swarmbox check --config-dir conf algo=my_algo``.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from omegaconf import DictConfig, open_dict

from swarmbox.api import Setpoint, SetpointKind
from swarmbox.testing.trace import HookTrace, lifecycle_problems

#: Network conditions of the suite's runs: lossy and jittery, as the contract must hold under both.
DEFAULT_NETWORK = {"loss_prob": 0.1, "jitter_ms": 20.0, "latency_ms": 5.0}


class ConformanceError(AssertionError):
    """The algorithm broke the contract; the message lists every violation found."""


@dataclass
class ConformanceReport:
    """What the suite saw: both manifests, their run directories, the hook traces."""

    manifests: list[dict[str, Any]] = field(default_factory=list)
    run_dirs: list[Path] = field(default_factory=list)
    traces: list[HookTrace] = field(default_factory=list)
    problems: list[str] = field(default_factory=list)


def check_algorithm(overrides: Sequence[str], *, workdir: Path, seed: int = 0,
                    network: dict[str, float] | None = None, expect: str = "ok",
                    edit: Callable[[DictConfig], None] | None = None,
                    config_dir: str | Path | None = None) -> ConformanceReport:
    """Fly the configured algorithm twice and check the contract; raise ConformanceError if broken.

    ``config_dir``: your own config groups, added to the shipped ones (relative paths: to the
    current directory); a directory that does not exist raises FileNotFoundError before any run.
    """
    from swarmbox.testing.runs import compose, fly, search_path_override  # Hydra loads only when used

    if expect not in ("ok", "any"):
        raise ValueError(f"expect must be 'ok' or 'any', got {expect!r}")
    net = {**DEFAULT_NETWORK, **(network or {})}
    args = [*overrides, f"seed={seed}", "run.progress=false", *(f"network.{k}={v}" for k, v in net.items())]
    if config_dir is not None:   # resolved once: the two runs compose the same groups
        args.append(search_path_override(config_dir))
    report = ConformanceReport()
    for label in ("first", "second"):
        cfg, choices = compose(args)
        if edit is not None:
            with open_dict(cfg):
                edit(cfg)
        trace = HookTrace()
        run_dir = Path(workdir) / label
        manifest = fly(cfg, choices, run_dir, trace.install)
        report.manifests.append(manifest)
        report.run_dirs.append(run_dir)
        report.traces.append(trace)
    name = report.manifests[0].get("choices", {}).get("algo", "?")
    problems = report.problems
    for label, manifest, run_dir, trace in zip(("first", "second"), report.manifests, report.run_dirs,
                                               report.traces, strict=True):
        problems += [f"{label} run: {p}" for p in _outcome_problems(manifest, run_dir, expect)]
        problems += [f"{label} run: {p}" for p in lifecycle_problems(trace)]
        problems += [f"{label} run: {p}" for p in _setpoint_problems(trace)]
    if all(m["status"] != "failed" for m in report.manifests):
        problems += _log_differences(*report.run_dirs)
    if problems:
        shown = "\n  - ".join(dict.fromkeys(problems))
        raise ConformanceError(f"algorithm '{name}' breaks the contract ({len(problems)} problem(s)):\n"
                               f"  - {shown}")
    return report


def _outcome_problems(manifest: dict[str, Any], run_dir: Path, expect: str) -> list[str]:
    from swarmbox.testing.runs import last_states

    status, reason = manifest["status"], manifest["reason"]
    if status == "failed":
        return [f"a hook raised: {reason}"]
    out = []
    if status == "aborted" and (expect == "ok" or not reason):
        out.append(f"the mission did not complete: aborted ({reason or 'no reason given'})")
    for node, (armed, landed) in last_states(run_dir).items():
        if armed or not landed:
            out.append(f"{node} ended {'armed' if armed else 'disarmed'} and "
                       f"{'on the ground' if landed else 'airborne'}")
    return out


def _setpoint_problems(trace: HookTrace) -> list[str]:
    out = []
    for node, value in trace.setpoints:
        if value is None:
            continue
        if type(value) is not Setpoint:
            out.append(f"{node}: exec_loop returned {type(value).__name__} {value!r:.60}, "
                       "expected a Setpoint (Setpoint.position/velocity/acceleration) or None")
        elif not isinstance(value.kind, SetpointKind) or len(value.ned) != 3:
            out.append(f"{node}: malformed Setpoint {value!r:.80}")
        elif not all(isinstance(x, float) and math.isfinite(x) for x in value.ned) or (
                value.yaw_rad is not None and not math.isfinite(value.yaw_rad)):
            out.append(f"{node}: non-finite or non-float Setpoint {value!r:.80}")
        else:
            continue
        if len(out) >= 3:
            break
    return out


def _log_differences(a: Path, b: Path) -> list[str]:
    from swarmbox.testing.runs import compare_logs

    return [f"not deterministic: {d}" for d in compare_logs(a, b)]


def check_main(argv: list[str] | None = None) -> int:
    """``swarmbox check [--config-dir DIR] OVERRIDES...``: the suite from the shell.

    Exit codes: 0 the algorithm conforms, 1 it breaks the contract (every violation printed),
    2 bad input (a config that does not compose, a missing directory).
    """
    import argparse
    import sys
    import tempfile

    p = argparse.ArgumentParser(prog="swarmbox check", description=(
        "Fly an algorithm twice under packet loss and jitter and check the contract every algorithm "
        "must keep (docs/user-projects.md). Example: swarmbox check --config-dir conf algo=flock"))
    p.add_argument("overrides", nargs="+", metavar="OVERRIDE",
                   help="Hydra overrides choosing the algorithm (algo=NAME) and, optionally, its mission")
    p.add_argument("--config-dir", "-cd", help="your own config groups (conf/algo/NAME.yaml ...), added "
                   "to the shipped ones; relative to the current directory")
    p.add_argument("--seed", type=int, default=0, help="root seed of both runs (0)")
    p.add_argument("--expect", choices=["ok", "any"], default="ok",
                   help="ok: the mission must complete; any: an abort with a reason passes too")
    p.add_argument("--workdir", help="keep both runs here (default: a temporary directory, removed "
                   "when the check passes)")
    args = p.parse_intermixed_args(argv)   # options before, between or after the overrides
    with tempfile.TemporaryDirectory(prefix="swarmbox-check-") as tmp:
        workdir = Path(args.workdir or tmp)
        try:
            report = check_algorithm(args.overrides, workdir=workdir, seed=args.seed, expect=args.expect,
                                     config_dir=args.config_dir)
        except ConformanceError as exc:
            print(f"FAIL  {exc}", file=sys.stderr)
            return 1
        except Exception as exc:   # noqa: BLE001 - composition and input errors: one line, exit 2
            print(f"error: {type(exc).__name__}: {_first_line(exc)}", file=sys.stderr)
            return 2
    name = report.manifests[0].get("choices", {}).get("algo", "?")
    print(f"PASS  algorithm '{name}': 2 runs {[m['status'] for m in report.manifests]}, identical logs"
          + (f"; runs in {workdir}" if args.workdir else ""))
    return 0


def _first_line(exc: BaseException) -> str:
    text = str(exc).strip() or repr(exc)
    return text.splitlines()[0]


__all__ = ["DEFAULT_NETWORK", "ConformanceError", "ConformanceReport", "check_algorithm", "check_main"]
