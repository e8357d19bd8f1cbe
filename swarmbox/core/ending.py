"""When a run is over, and why — in words that name the drone, the link and the limit.

A run ends normally when the ground and every agent have finished. It also ends once every drone
is *down* (landed and disarmed in TERMINATION or ABORT) or *lost* (its node removed, or its
autopilot link gone) and has stayed so for a settling time: nothing the swarm does can change the
outcome any more, so idling to ``max_sim_time_s`` would only record a misleading reason.
:func:`outcome` turns the final state into a status and a reason.
"""

from __future__ import annotations

from typing import Any

from swarmbox.core.stages import TERMINAL, Stage


def drone_state(agent: Any) -> str:
    """``removed`` | ``link lost`` | ``down`` | ``airborne`` | ``on the ground``."""
    tel = agent.telemetry
    if agent.removed:
        return "removed"
    if not tel.link_ok:
        return "link lost"
    if tel.landed and not tel.armed:
        return "down" if agent.stage in TERMINAL else "on the ground"
    return "airborne" if not tel.landed else "on the ground"


class EndWatch:
    """Tracks how long every drone has been down or lost (called once per tick by the loop)."""

    def __init__(self, settle_ticks: int) -> None:
        self.settle_ticks = max(1, int(settle_ticks))
        self._since: int | None = None

    def all_down(self, swarm: Any) -> bool:
        """Every drone down (landed and disarmed in a terminal stage), removed or its link lost."""
        return all(drone_state(agent) in ("down", "removed", "link lost") for agent in swarm.agents)

    def over(self, swarm: Any) -> bool:
        if not self.all_down(swarm):
            self._since = None
            return False
        tick = swarm.time.tick
        if self._since is None:
            self._since = tick
        return tick - self._since >= self.settle_ticks


def _ids(ids: list[int]) -> str:
    return f"drone {ids[0]}" if len(ids) == 1 else f"drones {ids}"


def drones_summary(swarm: Any, *, abnormal_only: bool = False) -> str:
    """Each drone's end state, grouped: e.g. ``drone 2 link lost (ABORT: link to the autopilot lost)``."""
    groups: dict[str, list[int]] = {}
    for agent in swarm.agents:
        state = drone_state(agent)
        what = {"down": "landed and disarmed"}.get(state, state)
        if agent.stage is Stage.ABORT and agent.reason:
            what += f" (ABORT: {agent.reason})"
        elif abnormal_only and state == "down":
            continue
        groups.setdefault(what, []).append(agent.node_id)
    return "; ".join(f"{_ids(ids)} {what}" for what, ids in groups.items())


def outcome(swarm: Any, max_sim_time_s: float, settled: bool) -> tuple[str, str]:
    """``(status, reason)`` of a run that stopped: ``ok`` or ``aborted``, with the real cause.

    ``ok``: the ground reached TERMINATION (the mission completed), even if some drones were lost
    or aborted on the way (named in the reason).
    """
    g = swarm.ground
    t = swarm.time.t_s
    if (swarm.done() or settled) and g.stage is Stage.TERMINATION:   # the mission completed
        lost = sorted(i for i, inf in g.inferiors.items() if not inf.alive)
        aborted = sorted(a.node_id for a in swarm.agents if a.stage is Stage.ABORT)
        return "ok", "; ".join(filter(None, [f"lost drones {lost}" if lost else "",
                                             f"drones {aborted} aborted" if aborted else "",
                                             drones_summary(swarm, abnormal_only=True)]))
    if g.stage is Stage.ABORT:
        head = g.reason   # the ground's own cause first, then each drone's end state
    elif settled:
        head = f"every drone down or lost at t={t:.1f} s with the ground in {g.stage.name}"
    else:
        head = f"max_sim_time_s {max_sim_time_s:g} reached with the ground in {g.stage.name}"
    return "aborted", f"{head}; {drones_summary(swarm)}"
