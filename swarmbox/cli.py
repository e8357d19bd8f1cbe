"""The ``swarmbox`` console command: one entry point for every tool.

A thin dispatcher over the ``python -m`` entry points, so both spellings take the same arguments::

    swarmbox run algo=hover seed=3            # = python -m swarmbox.run algo=hover seed=3
    swarmbox run -m 'seed=range(20)'          # a sweep (Hydra multirun)
    swarmbox analyze results/runs/<run>       # = python -m swarmbox.analyze ...
    swarmbox compare base.csv current.csv     # = python -m swarmbox.compare ...
    swarmbox export results/runs/<run>        # = python -m swarmbox.export ...
    swarmbox detect results/sweeps/<sweep>    # = python -m swarmbox.analysis.detection ...
    swarmbox bench --sizes 5 36               # = python -m swarmbox.bench ...
    swarmbox check --config-dir conf algo=my_algo   # the algorithm conformance suite

Each subcommand imports only what it needs: ``swarmbox run`` never loads the analysis stack, and the
analysis commands never load Hydra's runner or a simulator.
"""

from __future__ import annotations

import os
import sys
from collections.abc import Callable

#: command -> its one-line summary (``swarmbox --help``)
SUMMARIES = {
    "run": "fly a mission, or a sweep with -m (Hydra overrides; 'swarmbox run --help' lists the groups)",
    "analyze": "analyze a run or a sweep directory (tables and figures)",
    "compare": "regression gate over two summary tables (exit 1 on regression)",
    "export": "a run as MCAP (Foxglove, PlotJuggler) or a Rerun recording",
    "detect": "fault-detection benchmark over the runs of sweeps (rates, false alarms, localization)",
    "bench": "SwarmBox against the bare pymunk loop, as a ratio table",
    "check": "the algorithm conformance suite on an algorithm config (pass/fail with every violation)",
}

USAGE = "usage: swarmbox {" + ",".join(SUMMARIES) + "} [ARGS...]\n\n" + "\n".join(
    f"  {name:<8} {text}" for name, text in SUMMARIES.items()) + \
    "\n\n'swarmbox COMMAND --help' shows the options of one command."


def _project_importable() -> None:
    """As with ``python -m``, the current directory is importable: a user project's algorithms
    (``_target_: my_lab.flock.FlockDrone``) load from where the command runs."""
    if os.getcwd() not in sys.path:
        sys.path.insert(0, os.getcwd())


def _run(argv: list[str]) -> int:
    from swarmbox.run.__main__ import cli

    sys.argv = ["swarmbox run", *argv]   # Hydra reads its arguments from sys.argv
    _project_importable()
    cli()
    return 0


def _analyze(argv: list[str]) -> int:
    from swarmbox.analysis.cli import analyze_main

    return analyze_main(argv)


def _compare(argv: list[str]) -> int:
    from swarmbox.analysis.cli import compare_main

    return compare_main(argv)


def _export(argv: list[str]) -> int:
    from swarmbox.analysis.export import export_main

    return export_main(argv)


def _detect(argv: list[str]) -> int:
    from swarmbox.analysis.detection import main as detect_main

    return detect_main(argv)


def _bench(argv: list[str]) -> int:
    from swarmbox.bench.__main__ import main as bench_main

    return bench_main(argv)


def _check(argv: list[str]) -> int:
    from swarmbox.testing.algorithm_suite import check_main

    _project_importable()
    return check_main(argv)


COMMANDS: dict[str, Callable[[list[str]], int]] = {
    "run": _run, "analyze": _analyze, "compare": _compare, "export": _export, "detect": _detect,
    "bench": _bench, "check": _check}


def main(argv: list[str] | None = None) -> int:
    args = sys.argv[1:] if argv is None else list(argv)
    if args and args[0] in ("-h", "--help"):
        print(USAGE)
        return 0
    if not args:
        print(USAGE, file=sys.stderr)
        return 2
    command = COMMANDS.get(args[0])
    if command is None:
        print(f"swarmbox: unknown command {args[0]!r} (one of: {', '.join(COMMANDS)}; see swarmbox --help)",
              file=sys.stderr)
        return 2
    return command(args[1:])


if __name__ == "__main__":
    sys.exit(main())
