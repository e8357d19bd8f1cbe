"""Command topology: who is whose superior.

A topology is a ``superiors`` map (drone id -> superior id, -1 = the ground). Builders cover the
usual shapes; :func:`validate` refuses maps that cannot run (unknown ids, self-superiors, cycles).
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass

from swarmbox.core.messages import GROUND_ID


class TopologyError(ValueError):
    """The configured topology cannot run; the message names the offending drone(s)."""


@dataclass(frozen=True, slots=True)
class Topology:
    superiors: Mapping[int, int]

    def inferiors(self, node_id: int) -> list[int]:
        return sorted(i for i, s in self.superiors.items() if s == node_id)

    def depth(self, drone_id: int) -> int:
        """Hops from the ground (a drone commanded by the ground has depth 1)."""
        d, node = 0, drone_id
        while node != GROUND_ID:
            node, d = self.superiors[node], d + 1
        return d


def validate(superiors: Mapping[int, int], drone_ids: Iterable[int]) -> Topology:
    ids = set(drone_ids)
    missing = sorted(ids - set(superiors))
    if missing:
        raise TopologyError(f"topology: drones {missing} have no superior")
    extra = sorted(set(superiors) - ids)
    if extra:
        raise TopologyError(f"topology: drones {extra} are not in the mission (known ids {sorted(ids)})")
    for drone, sup in superiors.items():
        if sup == drone:
            raise TopologyError(f"topology: drone {drone} is its own superior")
        if sup != GROUND_ID and sup not in ids:
            raise TopologyError(f"topology: drone {drone} has unknown superior {sup}")
    for drone in superiors:
        seen, node = [drone], superiors[drone]
        while node != GROUND_ID:
            if node in seen:
                cycle = " -> ".join(str(x) for x in [*seen[seen.index(node):], node])
                raise TopologyError(f"topology: cycle {cycle} never reaches the ground")
            seen.append(node)
            node = superiors[node]
    return Topology(dict(sorted(superiors.items())))


def centralized(ids: list[int]) -> dict[int, int]:
    return {i: GROUND_ID for i in ids}


def leader_follower(ids: list[int], leader: int) -> dict[int, int]:
    if leader not in ids:
        raise TopologyError(f"topology: leader {leader} is not a drone of the mission {ids}")
    return {i: (GROUND_ID if i == leader else leader) for i in ids}


def chain(ids: list[int]) -> dict[int, int]:
    return {i: (GROUND_ID if k == 0 else ids[k - 1]) for k, i in enumerate(ids)}


def tree(ids: list[int], branching: int) -> dict[int, int]:
    if branching < 1:
        raise TopologyError(f"topology: tree branching must be >= 1, got {branching}")
    return {i: (GROUND_ID if k == 0 else ids[(k - 1) // branching]) for k, i in enumerate(ids)}


def build(kind: str, ids: list[int], *, leader: int = 0, branching: int = 2,
          explicit: Mapping[int, int] | None = None) -> Topology:
    """Build and validate a topology of the given kind over the mission's drone ids."""
    ids = sorted(ids)
    if kind == "centralized":
        sup = centralized(ids)
    elif kind == "leader_follower":
        sup = leader_follower(ids, leader)
    elif kind == "chain":
        sup = chain(ids)
    elif kind == "tree":
        sup = tree(ids, branching)
    elif kind in ("explicit", "mission"):
        if not explicit:
            raise TopologyError(f"topology '{kind}' needs a superiors map")
        sup = {int(k): int(v) for k, v in explicit.items()}
    else:
        raise TopologyError(f"unknown topology kind '{kind}' "
                            "(centralized, leader_follower, chain, tree, explicit, mission)")
    return validate(sup, ids)
