"""Scoring every injected truth of a run: composed faults, several targets, swarm-wide faults."""

import pandas as pd
import pytest

from swarmbox.analysis import scoring
from swarmbox.analysis.diagnosis import ALARM_COLUMNS

SPAN = (0.0, 100.0)


def alarms(*rows: tuple[float, int, str]) -> pd.DataFrame:
    """Alarm episodes (t_u, drone, metric), each 1 s long."""
    return pd.DataFrame([{"t_u": t, "metric": m, "drone": d, "value": 1.0, "score": 5.0, "median": 0.0,
                          "iqr": 0.1, "end_u": t + 1.0} for t, d, m in rows], columns=ALARM_COLUMNS)


def test_composed_faults_are_each_scored_and_healthy_time_counted_once():
    truths = [scoring.Truth("latency", 2, 10.0, 30.0), scoring.Truth("packet_loss", 3, 50.0, 60.0)]
    found = alarms((10.1, 2, "latency_ms"), (50.5, 3, "loss_ratio"), (90.0, 1, "latency_ms"))
    first, second = scoring.score_truths(found, truths, SPAN, n_drones=5, grace_s=10.0)
    assert first["detected"] and first["t_f_s"] == pytest.approx(0.1) and first["localized"]
    assert second["detected"] and second["t_f_s"] == pytest.approx(0.5) and second["localized"]
    # healthy: 100 s minus [10, 40] and [50, 70] = 50 s x 5 drones, on the first row only
    assert first["healthy_drone_h"] == pytest.approx(50 * 5 / 3600) and second["healthy_drone_h"] == 0
    assert first["false_alarms"] == 1 and second["false_alarms"] == 0     # the alarm at 90 s


def test_a_fault_on_every_drone_is_one_swarm_wide_truth_found_by_any_alarm():
    raw = [scoring.Truth("latency", d, 10.0, 30.0, {"target": d, "latency_ms": 5}) for d in (0, 1, 2)]
    [swarm] = scoring.scored_truths(raw, drones=[0, 1, 2])
    assert swarm.target is None and swarm.params == {"latency_ms": 5} and swarm.end_u == 30.0
    [row] = scoring.score_truths(alarms((12.0, 1, "latency_ms")), [swarm], SPAN, n_drones=3)
    assert row["detected"] and row["localized"] and row["first_drone"] == 1
    [row] = scoring.score_truths(alarms((40.5, 1, "latency_ms")), [swarm], SPAN, n_drones=3)
    assert not row["detected"]                                            # after the window


def test_a_fault_on_some_drones_stays_one_truth_per_target():
    raw = [scoring.Truth("gps_drift", d, 10.0, None, {"target": d}) for d in (0, 2)]
    assert [t.target for t in scoring.scored_truths(raw, drones=[0, 1, 2])] == [0, 2]
    ground = [scoring.Truth("link_cut", -1, 5.0, None, {"target": -1})]
    assert [t.target for t in scoring.scored_truths(ground, drones=[0, 1])] == [None]
    [row] = scoring.score_truths(alarms((12.0, 1, "disc_h_m")), raw[:1], SPAN, n_drones=3)
    assert not row["detected"] and not row["localized"]                    # drone 1 is not drone 0


def test_simultaneous_faults_on_two_drones_each_localize_their_own():
    """Two faults over one window: the other target's earlier alarm is that fault's answer, not a
    wrong drone for this one; an alarm on a healthy drone first still mislocalizes."""
    truths = [scoring.Truth("gps_drift", 2, 10.0, 30.0), scoring.Truth("latency", 6, 10.0, 30.0)]
    found = alarms((10.2, 6, "latency_ms"), (12.0, 2, "disc_n_m"))
    drift, latency = scoring.score_truths(found, truths, SPAN, n_drones=9)
    assert drift["detected"] and drift["localized"] and drift["first_drone"] == 2
    assert drift["t_f_s"] == pytest.approx(2.0)
    assert latency["detected"] and latency["localized"] and latency["t_f_s"] == pytest.approx(0.2)
    drift, latency = scoring.score_truths(alarms((10.1, 4, "disc_n_m"), *[(12.0, 2, "disc_n_m")]), truths,
                                          SPAN, n_drones=9)
    assert drift["detected"] and not drift["localized"] and drift["first_drone"] == 4
    assert not latency["detected"] and not latency["localized"]
