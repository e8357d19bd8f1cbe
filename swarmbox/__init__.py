"""SwarmBox: develop, test and benchmark drone-swarm algorithms.

Write an algorithm once against :mod:`swarmbox.api`; run it on the pymunk 2.5D simulator or on PX4
over MAVLink; analyse the per-node logs with :mod:`swarmbox.analysis`.
"""

__version__ = "0.1.0"
