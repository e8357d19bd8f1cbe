"""The interface every swarm transport implements (the in-process medium and Zenoh).

A node sees only :class:`swarmbox.core.node.Transport` (send, publish, subscriptions); the run loop
and the fault models need the rest: registering a node with its clock and log, handing over due
messages once per tick, cutting a node off, and the per-(message, destination) ``hooks`` through
which network faults delay or drop traffic.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, Protocol, runtime_checkable

from swarmbox.core.clock import NodeClock
from swarmbox.net.medium import LinkHook, LinkSpec


@runtime_checkable
class Medium(Protocol):
    hooks: list[LinkHook]

    def register(self, node_id: int, clock: NodeClock, log: Callable[[tuple], None]) -> list:
        """Attach a node; returns the inbox list it drains each tick."""

    def disconnect(self, node_id: int) -> None:
        """The node falls silent: nothing it sends leaves, nothing reaches it."""

    def subscribe(self, subscriber: int, publisher: int) -> None: ...
    def unsubscribe(self, subscriber: int, publisher: int) -> None: ...
    def has_subscribers(self, publisher: int) -> bool: ...
    def link(self, src: int, dst: int) -> LinkSpec: ...
    def publish(self, msg: Any) -> None: ...
    def send(self, msg: Any, dst: int) -> None: ...

    def deliver_due(self) -> None:
        """Hand every message due by now to its node's inbox, logging a ``recv`` (or ``drop``) row."""
