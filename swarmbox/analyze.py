"""``python -m swarmbox.analyze PATH``: analyze a run or a sweep directory (see docs/analysis.md)."""

import sys

from swarmbox.analysis.cli import analyze_main

if __name__ == "__main__":
    sys.exit(analyze_main())
