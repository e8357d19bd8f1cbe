"""Whole runs against the safety envelope: algorithms flying velocity or acceleration outward and
upward stay inside the geofence and under the ceiling, with ``clamped`` verdicts, ``safety`` events
and the tally in run.json; a position below ground is raised to the floor."""

from __future__ import annotations

import math

import numpy as np
import pytest

from swarmbox.hal.safety import REASONS
from tests.conftest import table

FENCE_M, CEILING_M = 20.0, 8.0
ENVELOPE = (f"run.safety.geofence_radius_m={FENCE_M:g}", f"run.safety.max_alt_m={CEILING_M:g}")


def outward(kind: str, target: str = "OutwardDrone", fly_s: float = 14.0) -> tuple[str, ...]:
    """Hover's four drones (on the north axis), even ids flying east, odd ones west, and up."""
    return ("algo=hover", "mission=hover", f"algo.drone._target_=tests.run.outward.{target}",
            f"+algo.params.kind={kind}", "+algo.params.vector=[0,5,-2]", f"+algo.params.fly_s={fly_s:g}",
            "+algo.params.turn_deg=180", *ENVELOPE)


def envelope_reached(run_dir, i: int) -> tuple[float, float]:
    st = table(run_dir, f"drone_{i}", "state")
    return float(np.hypot(st["true_n"], st["true_e"]).max()), float((-st["true_d"]).max())


@pytest.mark.parametrize("kind, target", [("velocity", "OutwardDrone"), ("acceleration", "OutwardDrone"),
                                          ("velocity", "OnceOutwardDrone")])
def test_outward_flight_is_held_inside_the_fence_and_under_the_ceiling(run, kind, target):
    manifest, d = run(*outward(kind, target))
    assert manifest["status"] == "ok", manifest["reason"]
    assert "setpoint_clamped" in manifest["safety"] and "setpoint_clamped" in manifest["reason"]
    for i in range(4):
        radius, alt = envelope_reached(d, i)
        assert FENCE_M - 1.5 < radius <= FENCE_M + 1.0, (i, radius)
        assert CEILING_M - 1.0 < alt <= CEILING_M + 0.5, (i, alt)
        ev = table(d, f"drone_{i}", "events")
        safety = ev[(ev["kind"] == "safety") & (ev["name"] == "setpoint_clamped")]
        assert safety["data"].str.contains('"reason": "[a-z+]*geofence', regex=True).any()
        assert safety["data"].str.contains('"reason": "[a-z+]*ceiling', regex=True).any()
        sp = table(d, f"drone_{i}", "setpoints")
        if target == "OutwardDrone":   # sent every tick: the last verdicts say why
            assert sp["verdict"].iloc[-1] == "clamped" and {"geofence", "ceiling"} <= set(
                sp["reason"].iloc[-1].split("+"))
        # fixed codes (a few combinations), not one text per setpoint
        assert {code for r in set(sp["reason"]) - {""} for code in r.split("+")} <= set(REASONS)


def test_a_setpoint_below_ground_is_clamped_to_the_floor_and_the_run_says_so(run):
    manifest, d = run("algo=hover", "mission=hover", "algo.params.altitude_m=-3", "mission.max_sim_time_s=20",
                      "run.timeouts_s.EXECUTION=6")
    sp = table(d, "drone_0", "setpoints")
    assert set(sp["verdict"]) == {"clamped"} and set(sp["reason"]) == {"floor"}
    assert manifest["status"] != "ok"
    assert "setpoint_clamped" in manifest["reason"] and "(first: floor)" in manifest["reason"]
    st = table(d, "drone_0", "state")
    assert st["true_d"].max() <= 0.05   # never under ground (the sim's ground is d = 0)
    assert math.isfinite(st["pos_d"].iloc[-1])
