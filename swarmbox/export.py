"""``python -m swarmbox.export RUN``: a run as MCAP (Foxglove, PlotJuggler) or Rerun recording."""

import sys

from swarmbox.analysis.export import export_main

if __name__ == "__main__":
    sys.exit(export_main())
