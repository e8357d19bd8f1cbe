"""The px4 bridge against real PX4 SITL (SIH) instances: CI's real-PX4 job (``.ci/px4.sh``).

Skipped unless a PX4 build is found (``SWARMBOX_PX4_BUILD``, else ``../shared/px4-sitl`` next to the
repository). PX4 runs at ``PX4_SIM_SPEED`` (default 2) times real time while the drivers keep the wall
clock, so every check is done that many times sooner. A bridge that breaks (a wrong type mask, a wrong
frame, a command PX4 refuses) fails the conformance checks: the vehicle does not follow.
"""

from __future__ import annotations

import math
import os

import numpy as np
import pytest

from swarmbox.hal.px4.backend import Px4Backend
from swarmbox.hal.px4.sitl import resolve_build
from swarmbox.testing import BACKEND_CHECKS
from tests.conftest import table

BUILD = resolve_build("auto")
SPEED = float(os.environ.get("PX4_SIM_SPEED", "2"))
#: the single-vehicle checks hold tolerances tuned on the simulator: at 2x PX4 SIH's estimator drifts
#: further past them, so they run at 1x
CHECK_SPEED = float(os.environ.get("PX4_CHECK_SPEED", "1"))
#: PX4 instance numbers (ports, /tmp/px4-sock-<n>) start here: two jobs on one machine need disjoint ranges
FIRST = int(os.environ.get("PX4_FIRST_INSTANCE", "0"))
#: checks whose simulator-tuned tolerances PX4 SIH does not meet, with what was measured on a quiet machine
#: (docs/px4.md, known gaps). The formation runs below still fly position setpoints, land and disarm on PX4.
PX4_GAPS = {
    "check_mission_cycle": "a landed vehicle's estimated altitude wanders past 0.5 m (0.8 m in 3 s)",
    "check_disarmed_setpoint_ignored": "a landed vehicle's estimated altitude wanders past 0.5 m",
    "check_return_to_launch": "RTL lands 1.6-1.8 m from home, always to the west (limit 1.0 m); ground truth "
                              "agrees (1.4 m west): PX4's home, not the bridge",
    "check_protocol": "estimated speed at rest sometimes >= 0.1 m/s",
    "check_hold_stops": "the vehicle wanders in HOLD past the simulator's tolerance (seen at 1x and 2x); "
                        "ground truth moves as much as the estimate",
}
if BUILD is None and os.environ.get("SWARMBOX_REQUIRE_PX4"):
    raise RuntimeError("SWARMBOX_REQUIRE_PX4 is set but no PX4 SITL build was found")
pytestmark = [pytest.mark.slow,
              pytest.mark.skipif(BUILD is None, reason="no PX4 SITL build: set SWARMBOX_PX4_BUILD "
                                 "(see docs/px4.md)")]


def px4_fleet(homes, **kw) -> Px4Backend:
    kw.setdefault("speed", CHECK_SPEED)
    return Px4Backend(homes_ned_m=list(homes), tick_s=0.025, rng=np.random.default_rng(1),
                      px4_build=str(BUILD), **kw,
                      sitl={"logger": False, "start_stagger_s": 0.1, "first_instance": FIRST})


@pytest.mark.parametrize("check", [
    pytest.param(c, marks=pytest.mark.skip(reason=f"PX4 SIH: {PX4_GAPS[c.__name__]}"))
    if c.__name__ in PX4_GAPS else c for c in BACKEND_CHECKS], ids=lambda c: c.__name__)
def test_conformance_on_px4(check):
    check(px4_fleet)


def test_formation_on_four_px4_instances(run):
    """The default 4-drone formation flies to ``ok`` on real PX4, faster than real time."""
    manifest, d = run("backend=px4", f"backend.px4_build={BUILD}", f"run.speed={SPEED:g}",
                      "backend.sitl.logger=false", f"backend.sitl.first_instance={FIRST}",
                      name="px4formation")
    assert manifest["status"] == "ok", manifest["reason"] or manifest["traceback"]
    assert manifest["real_time_factor"] > 0.8 * SPEED * 0.5   # the run loop kept up with PX4
    for i in range(4):
        st = table(d, f"drone_{i}", "state")
        assert st["pos_d"].min() < -2.0, f"drone {i} never climbed"
        assert not st.iloc[-1]["armed"] and st.iloc[-1]["landed"], f"drone {i} did not land"
        sp = table(d, f"drone_{i}", "setpoints")
        assert len(sp) and math.isfinite(sp["n"].iloc[-1])


def test_leader_px4_killed_followers_hand_over_and_finish(run):
    """Killing the leader's PX4 instance: its drone loses the link and aborts, the followers hand
    over to the next successor (the ground) and the mission completes with three drones."""
    def kill_leader(swarm) -> None:
        swarm.backend.launcher.procs[0].kill()

    manifest, d = run("backend=px4", f"backend.px4_build={BUILD}", f"run.speed={SPEED:g}",
                      "backend.sitl.logger=false", "topology=leader_follower",
                      f"backend.sitl.first_instance={FIRST}", name="px4leader",
                      prepare=lambda s: s.schedule(30.0, kill_leader))
    stages = table(d, "drone_0", "stages")
    assert stages["name"].iloc[-1] == "ABORT" and stages["reason"].iloc[-1] == "link to the autopilot lost"
    for follower in (1, 2, 3):
        ev = table(d, f"drone_{follower}", "events")
        assert "superior_aborted" in set(ev["name"]), f"drone {follower} did not see its leader abort"
        handover = ev[ev["name"] == "handover"]
        assert len(handover) == 1 and 30.0 < handover["t_s"].iloc[0] < 36.0
        assert table(d, f"drone_{follower}", "stages")["name"].iloc[-1] == "TERMINATION"
        last = table(d, f"drone_{follower}", "state").iloc[-1]
        assert last["landed"] and not last["armed"], f"drone {follower} did not land"
    assert "drones [0] aborted" in manifest["reason"] or "drone 0 link lost" in manifest["reason"], manifest


def test_gnss_failure_on_px4_detected_with_the_ulog_baseline(run):
    """GNSS off on drone 1's real PX4 (SIH: SIM_GPS_USED=0, no fix): PX4's EKF2 marks it in its ULog,
    those markers land on the run's timeline, and the analyzer detects the fault, the estimator
    baseline on drone 1 within 3 s of the onset."""
    from swarmbox.analysis.detection import evaluate_run
    from swarmbox.analysis.diagnosis import DiagnosisOptions
    from swarmbox.analysis.load import load_run

    manifest, d = run("algo=hover", "algo.params.hover_s=25", "backend=px4", f"backend.px4_build={BUILD}",
                      f"run.speed={SPEED:g}", "fault=gps_dropout", "fault.gps_dropout.targets=[1]",
                      "fault.gps_dropout.onset_s=15", f"backend.sitl.first_instance={FIRST}", name="px4gnss")
    assert manifest["status"] == "ok", manifest["reason"] or manifest["traceback"]
    # PX4's position failsafe takes the vehicle out of OFFBOARD: drone 1 aborts, and says why
    assert "drone 1 landed and disarmed (ABORT: autopilot took over: left OFFBOARD" in manifest["reason"], \
        manifest["reason"]
    assert "(Failsafe activated)" in manifest["reason"], manifest["reason"]
    ev = table(d, "drone_1", "events")
    accepted = ev[(ev["kind"] == "fault") & (ev["name"] == "inject_accepted")]
    assert len(accepted) and 15.0 <= accepted["t_s"].iloc[0] < 16.0, ev[ev["kind"] == "fault"]
    est = load_run(d).tables["events"]
    est = est[(est["kind"] == "estimator") & (est["node"] == 1)]
    assert {"gnss_fix_lost", "dead_reckoning"} <= set(est["name"]), est
    assert "estimator" not in set(table(d, "drone_1", "events")["kind"])   # from the ULog, not the run
    rows = evaluate_run(d, [DiagnosisOptions()]).set_index("detector")
    base = rows.loc["baseline"]
    assert base["detected"] and base["localized"] and 0.0 <= base["t_f_s"] < 3.0, base
    assert rows.loc["swarmbox", "detected"], rows.loc["swarmbox"]


def test_signing_key_refuses_a_px4_that_does_not_sign():
    """This PX4 build (main of Aug 2025) has no MAVLink signing (no MAV_SIGN_CFG; SETUP_SIGNING is
    ignored; it accepts commands unsigned, signed and wrongly signed alike). With ``signing_key`` set the
    bridge must not fly it unprotected: start-up fails and names the unsigned packets."""
    if b"MAV_SIGN_CFG" in (BUILD / "bin" / "px4").read_bytes():
        pytest.skip("this PX4 build knows MAV_SIGN_CFG: signing end to end is not covered by this test")
    with pytest.raises(TimeoutError, match=r"drone 0: \d+ packets unsigned or wrongly signed"):
        px4_fleet([(0.0, 0.0, 0.0)], signing_key="swarmbox px4 signing test", connect_timeout_s=8.0)


@pytest.mark.parametrize("kind", ["velocity", "acceleration"])
def test_outward_flight_is_held_inside_the_envelope_on_px4(run, kind):
    """Four PX4 vehicles flying a velocity / an acceleration out (east or west) and up, every tick for
    14 s, stop at a 20 m geofence (+1 m) and an 8 m ceiling (+0.5 m), with ``clamped`` verdicts and
    safety events; PX4's own geofence (just outside) never has to act. Checked while the setpoints fly
    (EXECUTION): in PX4's LAND mode that follows, SIH's estimate wanders (see PX4_GAPS; 1.2 m seen)."""
    from tests.hal.test_fence_runs import CEILING_M, FENCE_M, outward

    manifest, d = run(*outward(kind), "backend=px4", f"backend.px4_build={BUILD}", f"run.speed={SPEED:g}",
                      "backend.sitl.logger=false", f"backend.sitl.first_instance={FIRST}", name=f"px4{kind}")
    assert manifest["status"] == "ok", manifest["reason"] or manifest["traceback"]
    assert "setpoint_clamped" in manifest["safety"]
    boot = (d / "px4" / "instance_0" / "out.log").read_text(errors="replace")   # drone 0's home: the origin
    assert "GF_MAX_HOR_DIST: curr: 0.0000 -> new: 25.0000" in boot and "GF_ACTION: curr: 2 -> new: 3" in boot
    for i in range(4):
        st = table(d, f"drone_{i}", "state")
        st = st[st["stage"] == 3]   # EXECUTION
        assert np.hypot(st["pos_n"], st["pos_e"]).max() <= FENCE_M + 1.0, i
        assert (-st["pos_d"]).max() <= CEILING_M + 0.5, i
        sp = table(d, f"drone_{i}", "setpoints")
        assert (sp["verdict"] == "clamped").any() and sp["reason"].str.contains("geofence").any()
        ev = table(d, f"drone_{i}", "events")
        assert ((ev["kind"] == "safety") & (ev["name"] == "setpoint_clamped")).any()
        px4 = ev[ev["kind"] != "safety"]   # PX4's own layer stayed quiet (no status text about it)
        assert not px4["data"].str.contains("geofence", case=False).any(), px4[px4["data"].str.contains(
            "geofence", case=False)]
