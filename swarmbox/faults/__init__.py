"""Fault injection: seeded, scheduled faults on sensors, links, vehicles and clocks.

Any fault is one config line (models and parameters: ``conf/fault/*.yaml``; the schema:
:mod:`swarmbox.faults.schema`)::

    python -m swarmbox.run fault=gps_drift fault.rate_m_s=2 fault.targets=[3] fault.onset_s=25
    python -m swarmbox.run fault=[latency,packet_loss] fault.targets=[2] fault.latency.latency_ms=15

Every fault has targets, an onset, an optional duration and its own random streams from the run
seed, so a run replays identically. Each activation and end is a ``fault`` event
(``<model>_start`` / ``<model>_end``) in the ground's event log, with the target and parameters:
the analyzer's ground truth.

This package runs inside the runtime: no pandas, no matplotlib.
"""

from swarmbox.faults.base import Fault, FaultConfigError, FaultEnv, FaultParams, Target
from swarmbox.faults.install import build_faults, describe, install_faults, selected
from swarmbox.faults.schema import MODELS, FaultConfig

__all__ = [
    "MODELS", "Fault", "FaultConfig", "FaultConfigError", "FaultEnv", "FaultParams", "Target",
    "build_faults", "describe", "install_faults", "selected",
]
