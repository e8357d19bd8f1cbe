"""SwarmBox: develop, test and benchmark drone-swarm algorithms.

Write an algorithm once against :mod:`swarmbox.api`; run it on the pymunk 2.5D simulator or on PX4
over MAVLink; analyse the per-node logs with :mod:`swarmbox.analysis`.
"""

__version__ = "0.1.0"


def load(path, tables=None):
    """A run's or a sweep's logs as tidy DataFrames: ``swarmbox.load("results/sweeps/<sweep>").state``.

    Every row carries ``run``, ``algo``, ``mission``, ``seed`` and ``node``; ``.runs`` lists the runs.
    See :mod:`swarmbox.analysis.tidy`. pandas is imported only when this is called.
    """
    # Imported by name, on call: the runtime imports this package (for __version__) and must not
    # reach pandas through it (the import contracts in pyproject.toml check that statically).
    import importlib

    return importlib.import_module("swarmbox.analysis.tidy").load(path, tables)
