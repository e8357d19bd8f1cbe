"""SwarmBox's Hydra sweeper (``hydra/sweeper=swarmbox``, the default of ``swarmbox/conf/config.yaml``).

Hydra loads sweepers only from the ``hydra_plugins`` namespace, hence this small package beside
``swarmbox``; the logic lives in ``swarmbox.run.sweeper``.
"""
