import pytest

from swarmbox.core.topology import TopologyError, build, validate


def test_builders_shape():
    ids = [0, 1, 2, 3, 4, 5]
    assert build("centralized", ids).superiors == {i: -1 for i in ids}
    assert build("leader_follower", ids, leader=2).superiors == {0: 2, 1: 2, 2: -1, 3: 2, 4: 2, 5: 2}
    assert build("chain", ids).superiors == {0: -1, 1: 0, 2: 1, 3: 2, 4: 3, 5: 4}
    tree = build("tree", ids, branching=2)
    assert tree.superiors == {0: -1, 1: 0, 2: 0, 3: 1, 4: 1, 5: 2}
    assert tree.inferiors(1) == [3, 4] and tree.depth(5) == 3


@pytest.mark.parametrize("sup, message", [
    ({0: 1, 1: 2, 2: 0}, "cycle 0 -> 1 -> 2 -> 0"),
    ({0: -1, 1: 7, 2: -1}, "drone 1 has unknown superior 7"),
    ({0: 0, 1: -1, 2: -1}, "drone 0 is its own superior"),
    ({0: -1, 1: -1}, "drones [2] have no superior"),
    ({0: -1, 1: -1, 2: -1, 9: -1}, "drones [9] are not in the mission"),
])
def test_invalid_topologies_are_refused_with_the_cause(sup, message):
    with pytest.raises(TopologyError, match=message.replace("[", r"\[").replace("]", r"\]")):
        validate(sup, [0, 1, 2])


def test_unknown_kind_and_leader():
    with pytest.raises(TopologyError, match="unknown topology kind 'ring'"):
        build("ring", [0, 1])
    with pytest.raises(TopologyError, match="leader 5 is not a drone"):
        build("leader_follower", [0, 1], leader=5)
