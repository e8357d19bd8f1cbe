"""Conformance suites shipped with SwarmBox, for its own plug-ins and for yours.

:mod:`swarmbox.testing.backend_suite` holds the checks every backend must pass;
:mod:`swarmbox.testing.algorithm_suite` the one every algorithm must pass (:func:`check_algorithm`);
:mod:`swarmbox.testing.batch` compares a batch algorithm with the per-drone one it ports
(:func:`check_batch_matches`).
"""

from swarmbox.testing.algorithm_suite import ConformanceError, ConformanceReport, check_algorithm
from swarmbox.testing.backend_suite import (
    BACKEND_CHECKS,
    BackendFactory,
    Flight,
    check_acceleration_fence,
    check_disarmed_setpoint_ignored,
    check_held_velocity_fence,
    check_hold_stops,
    check_mission_cycle,
    check_nonfinite_setpoint_refused,
    check_protocol,
    check_return_to_launch,
    check_setpoint_verdicts,
    check_velocity_fence,
    run_backend_suite,
)
from swarmbox.testing.batch import BatchMismatch, BatchReport, check_batch_matches

__all__ = [
    "BACKEND_CHECKS", "BackendFactory", "BatchMismatch", "BatchReport", "ConformanceError",
    "ConformanceReport", "Flight", "check_algorithm", "check_disarmed_setpoint_ignored",
    "check_hold_stops", "check_mission_cycle", "check_nonfinite_setpoint_refused", "check_protocol",
    "check_return_to_launch", "check_setpoint_verdicts", "check_acceleration_fence",
    "check_batch_matches", "check_held_velocity_fence", "check_velocity_fence", "run_backend_suite",
]
