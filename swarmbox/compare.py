"""``python -m swarmbox.compare BASELINE CURRENT``: regression gate over two summary tables.

Exit status: 0 no regression, 1 a metric is worse beyond tolerance (or missing), 2 bad input.
"""

import sys

from swarmbox.analysis.cli import compare_main

if __name__ == "__main__":
    sys.exit(compare_main())
