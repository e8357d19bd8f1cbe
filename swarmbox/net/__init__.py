"""Transports that carry swarm messages between nodes.

:class:`~swarmbox.net.transport.Medium` is the interface; :class:`~swarmbox.net.medium.SimMedium`
is the deterministic in-process network of single-process runs and
:class:`~swarmbox.net.zenoh_medium.ZenohMedium` the real one of ``run.runtime=processes``
(``codec`` is its wire encoding, ``auth`` its signed envelope). Import the Zenoh one from its own
module: this package does not load Zenoh for a simulation run.
"""
