"""Transports that carry swarm messages between nodes (the simulated medium; real links later)."""
