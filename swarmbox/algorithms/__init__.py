"""Swarm algorithms. Each module imports only ``swarmbox.api`` (and numpy/scipy)."""
