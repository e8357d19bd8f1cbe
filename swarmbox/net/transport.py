"""The interface every swarm transport implements (the in-process medium and Zenoh).

A node sees only :class:`swarmbox.core.ports.Transport` (send, publish, subscriptions); the run loop
needs a :class:`swarmbox.core.ports.Network` (registering a node with its clock and log, handing over
due messages once per tick, cutting a node off); the fault models need the rest: the
per-(message, destination) ``hooks`` through which network faults delay or drop traffic.
"""

from __future__ import annotations

from typing import Protocol, runtime_checkable

from swarmbox.core.ports import Network
from swarmbox.net.medium import LinkHook, LinkSpec


@runtime_checkable
class Medium(Network, Protocol):
    """A swarm network as the run loop and the fault models see it: a :class:`~swarmbox.core.ports.Network`
    with the per-(message, destination) fault ``hooks`` and the link specs they start from."""

    hooks: list[LinkHook]

    def link(self, src: int, dst: int) -> LinkSpec: ...
