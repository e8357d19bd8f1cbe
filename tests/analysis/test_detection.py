"""The benchmark reductions: detection rates, false alarms per drone-hour, the smallest magnitude
found at an acceptable false-alarm rate, ROC points."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from swarmbox.analysis import detection


def rows_for(scale: float, detected: dict[float, int], false_alarms: int, runs: int = 10) -> list[dict]:
    """``runs`` faulty runs per magnitude (the first ``detected[m]`` detected) and one healthy run
    of 2 drone-hours with ``false_alarms``."""
    base = {"detector": "swarmbox", "rule": "tukey", "threshold_scale": scale, "persist_s": 0.1,
            "n_drones": 9, "network": "ideal"}
    out = [{**base, "run": f"h{scale}", "fault": "none", "magnitude": np.nan, "false_alarms": false_alarms,
            "healthy_drone_h": 2.0, "detected": np.nan, "localized": np.nan, "t_f_s": np.nan,
            "tau_d": np.nan, "sigma_a": np.nan}]
    for mag, hits in detected.items():
        for r in range(runs):
            hit = r < hits
            out.append({**base, "run": f"f{scale}_{mag}_{r}", "fault": "latency", "magnitude": mag,
                        "false_alarms": 0, "healthy_drone_h": 0.0, "detected": hit, "localized": hit,
                        "t_f_s": 0.1 * (r + 1) if hit else np.nan, "tau_d": mag if hit else np.nan,
                        "sigma_a": 3.0 if hit else np.nan})
    return out


ROWS = pd.DataFrame([*rows_for(0.5, {0.5: 10, 1.0: 10, 2.0: 10}, false_alarms=6),   # 3 per drone-hour
                     *rows_for(1.0, {0.5: 5, 1.0: 9, 2.0: 10}, false_alarms=1),     # 0.5 per drone-hour
                     *rows_for(2.0, {0.5: 0, 1.0: 4, 2.0: 10}, false_alarms=0)])


def test_rates_per_setting_and_magnitude():
    fa = detection.false_alarm_rates(ROWS).set_index("threshold_scale")["fa_per_drone_h"]
    assert fa.to_dict() == {0.5: pytest.approx(6 / 2.0), 1.0: pytest.approx(0.5), 2.0: 0.0}
    det = detection.detection_rates(ROWS).set_index(["threshold_scale", "magnitude"])
    assert det.loc[(1.0, 1.0), "detection_rate"] == pytest.approx(0.9)
    assert det.loc[(1.0, 1.0), "t_f_median_s"] == pytest.approx(0.5)


def test_smallest_magnitude_at_an_acceptable_false_alarm_rate():
    det, fa = detection.detection_rates(ROWS), detection.false_alarm_rates(ROWS)
    (row,) = detection.smallest_detected(det, fa).to_dict("records")
    # scale 0.5 finds 0.5 but raises 3 false alarms per drone-hour: not allowed; scale 1.0 finds 1.0
    assert row["threshold_scale"] == 1.0 and row["smallest_magnitude"] == 1.0
    assert row["detection_rate"] == pytest.approx(0.9) and row["fa_per_drone_h"] == pytest.approx(0.5)
    (strict,) = detection.smallest_detected(det, fa, min_rate=1.0, max_fa=0.0).to_dict("records")
    assert strict["threshold_scale"] == 2.0 and strict["smallest_magnitude"] == 2.0


def test_roc_points_over_the_threshold():
    curve = detection.roc(ROWS)
    small = curve[curve["magnitude"] == 0.5].sort_values("threshold_scale")
    assert small["detection_rate"].tolist() == [1.0, 0.5, 0.0]
    assert small["fa_per_drone_h"].tolist() == [3.0, 0.5, 0.0]


def test_magnitude_of_a_vector_parameter_is_its_norm():
    from swarmbox.analysis.scoring import Truth

    assert detection.magnitude(Truth("gps_bias", 1, 0.0, None, {"bias_ned_m": [3.0, 4.0, 0.0]})) == 5.0
    assert np.isnan(detection.magnitude(None))
