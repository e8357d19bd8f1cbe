"""The log schema: every table every node writes, column by column, with dtype and unit.

Layout of a run directory::

    run.json                 manifest: seed, config choices, status, timings, versions
    config.yaml              the resolved config
    logs/<node>/<table>.parquet   node = "ground", "drone_<i>", or "net" (the simulated medium)

Every time column (``t_s``) is the writing node's *local* clock; node clocks may be offset or drift
(the analyzer estimates and removes that). ``tick`` is the run's global tick counter at the write.
The schema version is stored in each Parquet file's metadata under ``swarmbox.schema``.
"""

from __future__ import annotations

from typing import NamedTuple

from swarmbox.core.messages import GROUND_ID, NET_ID, NO_SUBJECT

# The node-id sentinels are the core's (the ids it writes); NO_SUBJECT is re-exported for log readers.
__all__ = ["NO_SUBJECT", "READABLE_VERSIONS", "SCHEMA_VERSION", "TABLES", "Column", "node_name"]

#: 2: a published Heartbeat is one ``send`` row (``dst`` = BROADCAST, destinations in ``reason``)
#: instead of one per subscriber; :mod:`swarmbox.record.broadcast` expands it back. 1: otherwise same.
SCHEMA_VERSION = "2"
#: Versions the readers accept (older ones are converted on load).
READABLE_VERSIONS = ("1", "2")


class Column(NamedTuple):
    name: str
    dtype: str   # pyarrow type name: float64, int64, int32, int16, int8, bool, string
    unit: str
    doc: str


def _cols(*spec: tuple[str, str, str, str]) -> tuple[Column, ...]:
    return tuple(Column(*s) for s in spec)


_T = ("t_s", "float64", "s", "node-local clock time of the record")
_TICK = ("tick", "int64", "tick", "run tick counter")

TABLES: dict[str, tuple[Column, ...]] = {
    # One row per tick per drone (drone nodes only).
    "state": _cols(
        _T, _TICK,
        ("stage", "int8", "", "agent stage code (Stage enum)"),
        ("armed", "bool", "", ""),
        ("landed", "bool", "", ""),
        ("mode", "string", "", "FlightMode value"),
        ("pos_n", "float64", "m", "estimated position, mission frame"),
        ("pos_e", "float64", "m", ""),
        ("pos_d", "float64", "m", ""),
        ("vel_n", "float64", "m/s", "estimated velocity"),
        ("vel_e", "float64", "m/s", ""),
        ("vel_d", "float64", "m/s", ""),
        ("gnss_n", "float64", "m", "latest GNSS fix, mission frame (NaN before the first)"),
        ("gnss_e", "float64", "m", ""),
        ("gnss_d", "float64", "m", ""),
        ("true_n", "float64", "m", "ground-truth position (simulators only, else NaN)"),
        ("true_e", "float64", "m", ""),
        ("true_d", "float64", "m", ""),
        ("yaw_rad", "float64", "rad", ""),
        ("battery_frac", "float64", "", "remaining battery fraction"),
    ),
    # One row per message sent (per destination; a published Heartbeat: one row for all its
    # subscribers), received, or dropped by the network.
    "messages": _cols(
        _T, _TICK,
        ("kind", "string", "", "send | recv | drop"),
        ("msg_id", "int64", "", "run-unique message id"),
        ("type", "string", "", "heartbeat | report | task | ack | prox"),
        ("src", "int16", "", "sender node id (-1 ground)"),
        ("dst", "int16", "", "destination node id; -4: a Heartbeat to every id listed in reason"),
        ("nbytes", "int32", "B", "encoded size"),
        ("t_sent_s", "float64", "s", "sender's clock at send (as carried by the message)"),
        ("reason", "string", "", "why dropped; on a dst -4 send row the destination ids "
                                 "(comma-separated); else empty"),
    ),
    # One row per stage entered.
    "stages": _cols(
        _T, _TICK,
        ("stage", "int8", "", "Stage code"),
        ("name", "string", "", "Stage name"),
        ("reason", "string", "", "why (for ABORT and timeouts)"),
    ),
    # Markers, safety interventions, collisions, faults, losses, handovers, failsafes, errors.
    "events": _cols(
        _T, _TICK,
        ("kind", "string", "", "marker | progress | safety | collision | command | estimator | link | "
                               "fault | topology | failsafe | proximity | error"),
        ("name", "string", "", "what happened"),
        ("subject", "int16", "", "drone the event is about (-1 ground, -3 none)"),
        ("data", "string", "", "JSON object with the event's fields"),
    ),
    # One row per setpoint handed to the vehicle (drone nodes only).
    "setpoints": _cols(
        _T, _TICK,
        ("kind", "string", "", "position | velocity | acceleration"),
        ("n", "float64", "m|m/s|m/s2", "as requested"),
        ("e", "float64", "", ""),
        ("d", "float64", "", ""),
        ("yaw_rad", "float64", "rad", "NaN: keep heading"),
        ("verdict", "string", "", "safety monitor: ok | clamped | refused; ignored: vehicle disarmed"),
        ("reason", "string", "", "why clamped, refused or ignored (empty when ok)"),
    ),
}

def node_name(node_id: int) -> str:
    """Directory name of a node's logs."""
    if node_id == GROUND_ID:
        return "ground"
    if node_id == NET_ID:
        return "net"
    return f"drone_{node_id}"
