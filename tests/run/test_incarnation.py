"""Each process of a node counts its boot in ``nodes/<node>.boots``: the count is its incarnation."""

from __future__ import annotations

import pytest

from swarmbox.core.messages import make_msg_id
from swarmbox.run.node import NodeSetupError, next_incarnation


def test_boots_are_counted_per_node_from_zero(tmp_path):
    assert [next_incarnation(tmp_path, "ground") for _ in range(3)] == [0, 1, 2]
    assert next_incarnation(tmp_path, "drone_3") == 0
    assert (tmp_path / "nodes" / "ground.boots").read_text() == "3"


def test_a_damaged_boot_count_is_named(tmp_path):
    (tmp_path / "nodes").mkdir()
    (tmp_path / "nodes" / "ground.boots").write_text("x")
    with pytest.raises(NodeSetupError, match="ground.boots holds no boot count"):
        next_incarnation(tmp_path, "ground")


def test_message_ids_of_two_incarnations_never_meet():
    first = {make_msg_id(3, seq, 0) for seq in range(1, 5000)}
    again = {make_msg_id(3, seq, 1) for seq in range(1, 5000)}
    assert not first & again
    assert make_msg_id(3, 7, 0) == (5 << 40) | 7          # incarnation 0: the single-process ids
    assert make_msg_id(3, 7, 1) >> 40 == 5                 # the sender stays readable from the id
