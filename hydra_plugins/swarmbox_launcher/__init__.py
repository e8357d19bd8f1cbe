"""SwarmBox's Hydra launcher (``hydra/launcher=swarmbox``): jobs in parallel processes through
joblib, with Hydra's context shipped to the workers once per launch.

Hydra loads launchers only from the ``hydra_plugins`` namespace, hence this small package beside
``swarmbox``; the logic lives in ``swarmbox.run.launcher``.
"""
