"""The RQ3 experiment presets: what they configure, and one run of each fault family end to end."""

import pytest

from swarmbox.analysis import detection
from swarmbox.analysis.diagnosis import DiagnosisOptions
from swarmbox.faults import selected
from tests.conftest import compose_config

CHEVRON = {0: [0.0, 0.0], **{2 * k - 1: [-5.0 * k, -5.0 * k] for k in range(1, 5)},
           **{2 * k: [-5.0 * k, 5.0 * k] for k in range(1, 5)}}


@pytest.mark.parametrize("kind, model", [
    ("drift", "gps_drift"), ("latency", "latency"), ("loss", "packet_loss")])
def test_preset_composes_the_rq3_set_up(kind, model):
    cfg, choices = compose_config([f"+experiment=rq3_{kind}"])
    assert (choices["algo"], choices["mission"], choices["fault"]) == ("formation9", "formation9", model)
    assert {int(k): list(v) for k, v in cfg.mission.initial_positions.items()} == CHEVRON
    p = cfg.algo.params
    assert (p.radius_m, p.altitude_m, p.start_s, p.angular_rate_rad_s) == (50.0, 10.0, 5.0, 0.13333)
    assert cfg.topology.kind == "centralized"
    (params,) = selected(cfg.fault).values()
    assert params["onset_s"] == 25.0 and params["duration_s"] == 20.0


@pytest.mark.parametrize("overrides, fault", [
    (["+experiment=rq3_drift", "fault.rate_m_s=4.0", "fault.targets=8"], "gps_drift"),
    (["+experiment=rq3_loss", "fault.loss_prob=0.3", "fault.targets=3"], "packet_loss"),
])
@pytest.mark.slow
def test_one_rq3_run_is_diagnosed_on_its_target(run, overrides, fault):
    manifest, d = run(*overrides)
    assert manifest["status"] == "ok", manifest["reason"]
    rows = detection.evaluate_run(d, [DiagnosisOptions()]).set_index("detector")
    assert rows.loc["swarmbox", "detected"] and rows.loc["swarmbox", "localized"]
    assert rows.loc["swarmbox", "false_alarms"] == 0
    if fault == "gps_drift":
        base = rows.loc["baseline"]
        assert base["detected"] and rows.loc["swarmbox", "t_f_s"] < base["t_f_s"]
        assert rows.loc["swarmbox", "tau_d"] < base["tau_d"]
    else:
        assert rows.loc["swarmbox", "measured"] == pytest.approx(0.3, abs=0.03)
