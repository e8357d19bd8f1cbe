"""Faults on the fleet core (``run.core=fleet``): the object core's logs, table for table.

Every fault preset of the simulator flies through both cores (``assert_same_run``: every Parquet
table and run.json's outcome equal), and each case also asserts that the fault acted during the
flight (drops with its reason, a removed drone, a clock jump, a GNSS error...), so a fault that
silently does nothing on either core fails. Five drones hover for about 15 s; the faults begin at
3 s, while they hover, on drone 0 unless a case says otherwise.
"""

from __future__ import annotations

from pathlib import Path

import pandas as pd
import pytest

from swarmbox.bench.hover import grid
from tests.core.test_fleet_identity import HOVER, assert_same_run

HOVER5 = [*HOVER, "algo.params.hover_s=6"]
ONSET_S = 3.0
TICK_S = 0.025   # the default run.tick_hz (40 Hz): a row's true time is tick * TICK_S
FAULT_DIR = Path(__file__).resolve().parents[2] / "swarmbox" / "conf" / "fault"
#: presets that act through the medium's hooks: three seeds each by default
NETWORK = ["burst_loss", "latency", "link_cut", "packet_loss", "partition"]
NODE = ["battery_failsafe", "clock_skew", "crash", "gps_bias", "gps_drift", "gps_dropout", "gps_noise",
        "motor_loss"]
#: presets for an autopilot's own failure handling (MAV_CMD_INJECT_FAILURE): no simulator backend
AUTOPILOT_ONLY = {"gps_failure"}
#: CPU-heavy identity checks: out of the default run, in CI's seeds job (both markers: pyproject)
HEAVY = (pytest.mark.slow, pytest.mark.seeds)
#: a preset's overrides beyond ``fault=<preset>`` and the onset (motor loss acts on the climb)
EXTRA = {"motor_loss": ["fault.onset_s=0.5", "fault.accel_scale=0.1"]}


def _fleet(tmp_path: Path, node: str, table: str) -> pd.DataFrame:
    return pd.read_parquet(tmp_path / "fleet" / "logs" / node / f"{table}.parquet")


def _drops(tmp_path: Path, reason: str) -> int:
    net = tmp_path / "fleet" / "logs" / "net" / "messages.parquet"
    return int((pd.read_parquet(net)["reason"] == reason).sum()) if net.exists() else 0


def _after(state: pd.DataFrame) -> pd.DataFrame:
    return state[state["tick"] * TICK_S >= ONSET_S + 0.05]


def _acted(tmp_path: Path, preset: str, manifest: dict) -> None:
    """What ``preset`` (on drone 0) must have done to the flight."""
    d0 = _fleet(tmp_path, "drone_0", "state")
    before, after = d0[d0["tick"] * TICK_S < ONSET_S], _after(d0)
    if preset in ("burst_loss", "link_cut", "packet_loss", "partition"):
        assert _drops(tmp_path, f"fault:{preset}") > 0
    elif preset == "latency":   # 20 ms more on every message to drone 0 (an ideal network: 0 before)
        recv = _fleet(tmp_path, "drone_0", "messages").query("kind == 'recv'")
        assert (recv["t_s"] - recv["t_sent_s"]).max() == pytest.approx(0.020)
    elif preset == "clock_skew":   # drone 0's clock jumps 0.5 s ahead of drone 1's
        d1 = _fleet(tmp_path, "drone_1", "state")
        both = d0.merge(d1, on="tick")
        assert (both["t_s_x"] - both["t_s_y"]).max() == pytest.approx(0.5)
    elif preset == "crash":
        assert "drone 0 removed" in manifest["reason"] and _drops(tmp_path, "unreachable") > 0
    elif preset == "battery_failsafe":
        assert "battery_low" in set(_fleet(tmp_path, "drone_0", "events")["name"])
    elif preset == "gps_bias":
        assert (after["gnss_n"] - after["true_n"]).max() > 4.0
    elif preset == "gps_drift":
        assert (after["gnss_n"] - after["true_n"]).max() > 5.0
    elif preset == "gps_dropout":   # the reading freezes
        assert after["gnss_n"].nunique() == 1 and before["gnss_n"].nunique() > 1
    elif preset == "gps_noise":
        assert (after["gnss_n"] - after["true_n"]).std() > 3 * (before["gnss_n"] - before["true_n"]).std()
    elif preset == "motor_loss":   # a tenth of the thrust from 0.5 s: drone 0 climbs much slower
        events = [_fleet(tmp_path, f"drone_{k}", "events") for k in (0, 1)]
        reached = [e.loc[e["name"] == "reached_altitude", "t_s"].min() for e in events]
        assert reached[0] > reached[1] + 1.0
    else:
        raise AssertionError(f"no evidence check for preset {preset}")


def _fly_preset(tmp_path: Path, preset: str, seed: int, extra: list[str] | None = None) -> dict:
    overrides = [*HOVER5, f"fault={preset}", f"fault.onset_s={ONSET_S}", *EXTRA.get(preset, []),
                 *(extra or []), f"seed={seed}"]
    manifest = assert_same_run(tmp_path, overrides, grid(5))
    assert manifest["status"] == "ok", manifest["reason"]
    return manifest


def _seeds(presets: list[str], default: tuple[int, ...]) -> list:
    """Every preset with every seed 0-2; those not in ``default`` are slow (CI's seeds job)."""
    return [pytest.param(p, s, marks=() if s in default else HEAVY)
            for p in presets for s in (0, 1, 2)]


def test_every_simulator_fault_preset_is_flown_here():
    presets = {p.stem for p in FAULT_DIR.glob("*.yaml")} - {"none"}
    assert presets - AUTOPILOT_ONLY == set(NETWORK) | set(NODE)


@pytest.mark.parametrize(("preset", "seed"), _seeds(NETWORK, (0, 1, 2)))
def test_network_fault_presets_logs_equal(tmp_path, preset, seed):
    """The medium's hooks see the fleet's messages in the object core's order: same draws, same
    verdicts, same drops and delays."""
    manifest = _fly_preset(tmp_path, preset, seed)
    _acted(tmp_path, preset, manifest)


@pytest.mark.parametrize(("preset", "seed"), _seeds(NODE, (0,)))
def test_node_fault_presets_logs_equal(tmp_path, preset, seed):
    manifest = _fly_preset(tmp_path, preset, seed)
    _acted(tmp_path, preset, manifest)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_fault_targets_and_windows_logs_equal(tmp_path, seed):
    """The ground's radio lossy (a ground target), two directed links cut for 4 s: hooks come and go."""
    assert_same_run(tmp_path, [*HOVER5, "fault=[packet_loss,link_cut]", "fault.packet_loss.targets=[-1]",
                               "fault.link_cut.targets=[[-1,1],[2,-1]]", "fault.link_cut.duration_s=4",
                               f"fault.onset_s={ONSET_S}", f"seed={seed}"], grid(5))
    events = _fleet(tmp_path, "ground", "events")
    assert {"link_cut_start", "link_cut_end", "packet_loss_start"} <= set(events["name"])
    assert _drops(tmp_path, "fault:packet_loss") > 0 and _drops(tmp_path, "fault:link_cut") > 0


@pytest.mark.parametrize("network", [[], ["network=wifi"]])
def test_latency_with_jitter_reorders_as_the_object_core_does(tmp_path, network):
    """Delayed messages leave the constant-delay queue (ideal network) or reorder in the heap (wifi):
    the hand-over order, and so the receive rows, are the object core's."""
    assert_same_run(tmp_path, [*HOVER5, *network, "fault=latency", "fault.targets=[0,-1]",
                               "fault.latency_ms=30", "fault.jitter_ms=40", f"fault.onset_s={ONSET_S}",
                               "fault.duration_s=5"], grid(5))
    recv = _fleet(tmp_path, "drone_1", "messages").query("kind == 'recv' and src == -1")
    assert (recv["t_s"] - recv["t_sent_s"]).max() > 0.030


def test_ground_clock_skew_with_drift_logs_equal(tmp_path):
    """The ground's clock (the unified timeline) and a drone's jump and drift, then resynchronise."""
    assert_same_run(tmp_path, [*HOVER5, "network=wifi", "fault=clock_skew", "fault.targets=[-1,2]",
                               "fault.drift_ppm=5000", f"fault.onset_s={ONSET_S}", "fault.duration_s=4"],
                    grid(5))
    names = set(_fleet(tmp_path, "ground", "events")["name"])
    assert {"clock_skew_start", "clock_skew_end"} <= names


LINKS = ("network.links=[{src: 0, dst: -1, latency_ms: 30, jitter_ms: 20, loss_prob: 0.2},"
         " {src: -1, dst: 1, loss_prob: 0.5}, {src: 2, dst: -1, latency_ms: 40}]")


@pytest.mark.parametrize("seed", [0, 1, 2])
@pytest.mark.parametrize("network", [[], ["network=wifi"]])
def test_per_link_specs_logs_equal(tmp_path, network, seed):
    """``network.links``: each link's own latency, jitter and loss, drawn message by message."""
    assert_same_run(tmp_path, [*HOVER5, *network, LINKS, f"seed={seed}"], grid(5))
    net = pd.read_parquet(tmp_path / "fleet" / "logs" / "net" / "messages.parquet")
    assert (net.query("reason == 'loss' and src == -1")["dst"] == 1).sum() > 0
    recv = _fleet(tmp_path, "ground", "messages").query("kind == 'recv' and src == 2")
    assert (recv["t_s"] - recv["t_sent_s"]).min() == pytest.approx(0.040)


def test_per_link_specs_and_a_fault_hook_logs_equal(tmp_path):
    assert_same_run(tmp_path, [*HOVER5, LINKS, "fault=packet_loss", "fault.targets=[1]",
                               f"fault.onset_s={ONSET_S}"], grid(5))
    assert _drops(tmp_path, "fault:packet_loss") > 0 and _drops(tmp_path, "loss") > 0


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_two_faults_at_once_logs_equal(tmp_path, seed):
    """GNSS drift and packet loss on drone 1 together."""
    assert_same_run(tmp_path, [*HOVER5, "fault=[gps_drift,packet_loss]", "fault.targets=[1]",
                               f"fault.onset_s={ONSET_S}", f"seed={seed}"], grid(5))
    assert _drops(tmp_path, "fault:packet_loss") > 0
    d1 = _after(_fleet(tmp_path, "drone_1", "state"))
    assert (d1["gnss_n"] - d1["true_n"]).max() > 5.0


def test_two_drones_crash_on_a_lossy_jittery_network_logs_equal(tmp_path):
    """Messages in flight to a crashed drone are dropped as it drops them: at hand-over, unreachable."""
    manifest = assert_same_run(tmp_path, [*HOVER5, "network=wifi", "fault=crash", "fault.targets=[0,3]",
                                          f"fault.onset_s={ONSET_S}", "seed=1"], grid(5))
    assert "drones [0, 3] removed" in manifest["reason"]
    assert _drops(tmp_path, "unreachable") > 0 and _drops(tmp_path, "loss") > 0


@pytest.mark.parametrize("preset", ["crash", "packet_loss"])
def test_faults_with_a_batch_algorithm_logs_equal(tmp_path, preset):
    """hover_batch on both cores: a crashed drone leaves the fleet's hooks, losses reach its inbox."""
    overrides = ["algo=hover_batch", "mission=hover", "algo.params.hover_s=6", f"fault={preset}",
                 f"fault.onset_s={ONSET_S}"]
    manifest = assert_same_run(tmp_path, overrides, grid(5))
    _acted(tmp_path, preset, manifest)


@pytest.mark.slow
@pytest.mark.seeds
@pytest.mark.parametrize("preset", NETWORK + NODE)
def test_fault_presets_on_a_formation_logs_equal(tmp_path, preset):
    """Formation: the ground streams a task to every drone every tick, so faults meet task traffic."""
    timing = EXTRA.get(preset, ["fault.onset_s=5"])
    manifest = assert_same_run(tmp_path, ["algo=formation", f"fault={preset}", *timing])
    assert manifest["status"] == "ok", manifest["reason"]
    names = set(_fleet(tmp_path, "ground", "events")["name"])
    assert f"{preset}_start" in names


@pytest.mark.slow
@pytest.mark.seeds
@pytest.mark.parametrize("fault", [["fault=packet_loss", "fault.targets=[-1]"],
                                   ["fault=latency", "fault.jitter_ms=30", "fault.duration_s=10"]])
def test_faults_on_a_delivery_logs_equal(tmp_path, fault):
    """The RQ4 CI preset's delivery: reliable tasks re-sent across lost and delayed messages."""
    manifest = assert_same_run(tmp_path, ["algo=delivery_distance_dynamic", "mission=delivery",
                                          "mission.generator.count=15", "mission.generator.half_size_m=50.0",
                                          "run.state_every_ticks=2", *fault, "fault.onset_s=5"])
    assert manifest["status"] == "ok", manifest["reason"]


_TOPOLOGY_FAULTS = [("leader_follower", "crash"), ("chain", "partition"), ("leader_follower", "link_cut"),
                    ("chain", "crash"), ("leader_follower", "packet_loss"), ("chain", "clock_skew")]


@pytest.mark.parametrize(("topology", "fault"), [
    *_TOPOLOGY_FAULTS[:2], *(pytest.param(*tf, marks=[pytest.mark.slow, pytest.mark.seeds])
                             for tf in _TOPOLOGY_FAULTS[2:])])
def test_faults_under_drones_commanding_drones_logs_equal(tmp_path, topology, fault):
    """A fault on a drone that commands drones (its inferiors hand over or abort), on the fleet core's
    whole-tick path: the same logs as the object core's."""
    manifest = assert_same_run(tmp_path, [*HOVER, "algo.params.hover_s=8", f"topology={topology}",
                                          f"fault={fault}", "fault.targets=[1]", "fault.onset_s=3",
                                          "network=wifi"])
    events = pd.read_parquet(tmp_path / "fleet" / "logs" / "ground" / "events.parquet")
    assert f"{fault}_start" in set(events["name"]), "the fault never started"
    inferiors = [d for d in range(manifest["n_drones"]) if d != 1 and
                 (tmp_path / "fleet" / "logs" / f"drone_{d}" / "events.parquet").exists() and
                 (pd.read_parquet(tmp_path / "fleet" / "logs" / f"drone_{d}" / "events.parquet")["name"]
                  .isin(["handover", "superior_lost", "inferior_lost"]).any())]
    assert inferiors or fault in ("packet_loss", "clock_skew"), "no drone noticed the faulty commander"
