"""Run SwarmBox experiments: ``python -m swarmbox.run [overrides]`` (Hydra; ``-m`` for sweeps)."""
