import pytest

from swarmbox.core.stages import IllegalTransition, Stage, check_transition, path_to


def test_forward_and_abort_are_legal():
    check_transition(Stage.ICEBREAK, Stage.PREPARATION)
    for s in (Stage.ICEBREAK, Stage.PREPARATION, Stage.EXECUTION, Stage.LANDING):
        check_transition(s, Stage.ABORT)


def test_illegal_transition_names_both_stages():
    with pytest.raises(IllegalTransition, match="EXECUTION -> PREPARATION"):
        check_transition(Stage.EXECUTION, Stage.PREPARATION)
    with pytest.raises(IllegalTransition, match="TERMINATION -> ABORT"):
        check_transition(Stage.TERMINATION, Stage.ABORT)


def test_late_joiner_walks_every_stage():
    assert path_to(Stage.ICEBREAK, Stage.EXECUTION) == [Stage.PREPARATION, Stage.EXECUTION]
    assert path_to(Stage.PREPARATION, Stage.ABORT) == [Stage.ABORT]
    with pytest.raises(IllegalTransition):
        path_to(Stage.LANDING, Stage.PREPARATION)
