"""Pure swarm logic: stages, messages, topology, ground node and agent nodes.

Nothing here imports a backend, Hydra or an analysis library.
"""
