"""The ``swarmbox`` console command: ``swarmbox run|analyze|compare ...``.

A thin dispatcher over the ``python -m`` entry points, so both spellings take the same arguments::

    swarmbox run algo=hover seed=3            # = python -m swarmbox.run algo=hover seed=3
    swarmbox run -m 'seed=range(20)'          # a sweep (Hydra multirun)
    swarmbox analyze results/runs/<run>       # = python -m swarmbox.analyze ...
    swarmbox compare base.csv current.csv     # = python -m swarmbox.compare ...

Each subcommand imports only what it needs: ``swarmbox run`` never loads the analysis stack.
"""

from __future__ import annotations

import os
import sys

USAGE = """usage: swarmbox {run,analyze,compare} [ARGS...]

  run      fly a mission or a sweep (Hydra overrides; --help lists the config groups)
  analyze  analyze a run or a sweep directory (tables and figures)
  compare  regression gate over two summary tables (exit 1 on regression)

'swarmbox COMMAND --help' shows the options of one command."""


def _run(argv: list[str]) -> int:
    from swarmbox.run.__main__ import main as run_main

    sys.argv = ["swarmbox run", *argv]   # Hydra reads its arguments from sys.argv
    # As with `python -m`, the current directory is importable: a user project's algorithms
    # (_target_: my_lab.flock.FlockDrone) load from where the command runs.
    if os.getcwd() not in sys.path:
        sys.path.insert(0, os.getcwd())
    run_main()
    return 0


def _analyze(argv: list[str]) -> int:
    from swarmbox.analysis.cli import analyze_main

    return analyze_main(argv)


def _compare(argv: list[str]) -> int:
    from swarmbox.analysis.cli import compare_main

    return compare_main(argv)


COMMANDS = {"run": _run, "analyze": _analyze, "compare": _compare}


def main(argv: list[str] | None = None) -> int:
    args = sys.argv[1:] if argv is None else list(argv)
    if not args or args[0] in ("-h", "--help"):
        print(USAGE)
        return 0 if args else 2
    command = COMMANDS.get(args[0])
    if command is None:
        print(f"swarmbox: unknown command {args[0]!r}\n\n{USAGE}", file=sys.stderr)
        return 2
    return command(args[1:])


if __name__ == "__main__":
    sys.exit(main())
