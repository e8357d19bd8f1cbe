"""SwarmBox's Hydra launcher (``hydra/launcher=swarmbox``): the joblib launcher, minus its per-job
cost of shipping Hydra's context to the workers.

Hydra loads launchers only from the ``hydra_plugins`` namespace, hence this small package beside
``swarmbox``; the logic lives in ``swarmbox.run.launcher``.
"""
