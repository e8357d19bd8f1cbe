"""Throughput benchmarks: SwarmBox against the bare pymunk loop (``python -m swarmbox.bench``)."""
