"""SwarmBox's tuning sweeper (``hydra/sweeper=tune``): an Optuna study over algorithm parameters.

Hydra loads sweepers only from the ``hydra_plugins`` namespace, hence this small package beside
``swarmbox``; the logic lives in ``swarmbox.tune``.
"""
