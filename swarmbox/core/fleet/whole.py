"""The fleet core with every drone ticking whole: drones commanding drones, and peer Heartbeats.

When a drone's superior is another drone (``chain``, ``tree``, ``leader_follower``, a mission's own
superiors map) or every drone subscribes to every other (``topology.peers=all``), a drone receives
Reports and Heartbeats from drones, ages its inferiors, publishes its own Heartbeat (its successors
hook), relays its descendants in its Report and hands over to a successor when its superior falls
silent. The ground's arrays (:class:`~swarmbox.core.fleet.ground.FleetGround`) hold only direct
inferiors that are leaves, so here the ground is the object core's
:class:`~swarmbox.core.ground.GroundNode` and every drone runs the object core's tick
(:meth:`~swarmbox.core.fleet.agents.FleetAgent.fleet_tick` with ``FleetState.whole``), its
Heartbeat and Report sent as message objects in its turn. The network, the telemetry readings,
the state rows and the end-of-run watch stay the fleet's arrays, so the logs are the object
core's, table for table.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from swarmbox.core.clock import readings
from swarmbox.core.fleet.swarm import FleetSwarm

_NONE = np.empty(0, dtype=np.intp)


class WholeSwarm(FleetSwarm):
    """A FleetSwarm whose drones all tick through the object core's path, every tick."""

    def __init__(self, **kw: Any) -> None:
        super().__init__(**kw)
        self.fleet.whole = True
        self._inboxes = [self.ground.inbox, *(a.inbox for a in self.agents)]   # by node index

    def deliver(self) -> None:
        """Every arrival to its node's inbox, in hand-over order (all are message objects here)."""
        due = self.network.deliver()
        if not len(due["dsti"]):
            return
        net, inboxes = self.network, self._inboxes
        for node, msg in zip(due["dsti"].tolist(), net.objects(due["obj"]), strict=True):
            inboxes[node].append(msg)
        net.release(due["obj"])

    def tick_drones(self) -> None:
        f = self.fleet
        self.backend.state_into(self._values, self._landed)
        crashed = self._crashed is not None and bool(self._crashed.any())
        f.read(self._vehicles, self._landed, crashed)
        self.now = readings(self._clocks, self.time.t_s)
        live = np.array([k for k, a in enumerate(self.agents) if not a.removed], dtype=np.intp)
        if self.fleet_driver is not None:
            self.run_batch(live, _NONE)
        else:
            self.run_hooks(live, _NONE)
        f.busy[:] = False
