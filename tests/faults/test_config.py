"""The fault config: one-line and composed forms, shortcuts, and clear refusals of bad input."""

import dataclasses

import pytest
from hydra.errors import ConfigCompositionException

from swarmbox.faults import MODELS, FaultConfig, describe, selected
from swarmbox.faults.schema import param_types
from tests.conftest import compose_config
from tests.faults.helpers import HOVER, fault_events


def test_default_is_no_fault():
    cfg, choices = compose_config()
    assert choices["fault"] == "none" and selected(cfg.fault) == {} and describe(cfg.fault) == "none"


def test_one_line_form_sets_the_selected_model():
    cfg, _ = compose_config(["fault=gps_drift", "fault.rate_m_s=2", "fault.targets=[3]"])
    assert selected(cfg.fault) == {"gps_drift": {"targets": [3], "onset_s": 30.0, "duration_s": None,
                                                 "rate_m_s": 2.0, "direction_ned": [1.0, 0.0, 0.0]}}


def test_composition_shared_shortcuts_and_per_model_keys():
    cfg, _ = compose_config(["fault=[gps_drift,packet_loss]", "fault.targets=[2]", "fault.onset_s=12",
                             "fault.packet_loss.loss_prob=0.2", "fault.gps_drift.rate_m_s=4"])
    models = selected(cfg.fault)
    assert list(models) == ["gps_drift", "packet_loss"] and describe(cfg.fault) == "gps_drift+packet_loss"
    assert models["gps_drift"]["rate_m_s"] == 4.0 and models["packet_loss"]["loss_prob"] == 0.2
    assert {m["onset_s"] for m in models.values()} == {12.0}
    assert {tuple(m["targets"]) for m in models.values()} == {(2,)}


@pytest.mark.slow
def test_every_model_has_a_config_file_and_the_schema_covers_every_parameter():
    fields = {f.name for f in dataclasses.fields(FaultConfig)}
    for name, cls in MODELS.items():
        cfg, choices = compose_config([f"fault={name}"])
        assert choices["fault"] == name and list(selected(cfg.fault)) == [name]
        assert name in fields
        assert {f.name for f in dataclasses.fields(cls.Params)} <= fields
    assert set(param_types()) | set(MODELS) == fields


@pytest.mark.parametrize("override", ["fault.gps_drift.rate=3", "fault.rate=3"])
def test_misspelt_key_fails_at_compose_time(override):
    with pytest.raises(ConfigCompositionException):
        compose_config(["fault=gps_drift", override])


@pytest.mark.parametrize("overrides, message", [
    (["fault=gps_drift", "fault.targets=[7]"],
     "fault gps_drift: unknown drone 7 in targets (drones: [0, 1, 2, 3])"),
    (["fault=gps_drift", "fault.rate_m_s=-2"], "fault gps_drift: rate_m_s must be >= 0 m/s, got -2.0"),
    (["fault=packet_loss", "fault.onset_s=500"],
     "fault packet_loss: onset_s 500 s is after the mission's end (mission.max_sim_time_s = 120 s)"),
    (["fault=packet_loss", "fault.loss_prob=1.5"], "fault packet_loss: loss_prob must be within [0, 1]"),
    (["fault=latency", "fault.latency_ms=-5"], "fault latency: latency_ms must be >= 0 ms"),
    (["fault=gps_drift", "fault.targets=[[0,1]]"],
     "fault gps_drift: targets are drones for this fault, not links"),
    (["fault=gps_drift", "fault.targets=[-1]"], "fault gps_drift: unknown drone -1"),
    (["fault=latency", "fault.targets=[[0,9]]"], "fault latency: unknown drone 9"),
    (["fault=gps_drift", "fault.targets=[]"], "fault gps_drift: no targets"),
    (["fault=crash", "fault.duration_s=5"], "fault crash: the fault is permanent"),
    (["fault=gps_drift", "fault.duration_s=0"], "fault gps_drift: duration_s must be > 0"),
    (["fault=gps_drift", "fault.loss_prob=0.3"],
     "fault.loss_prob is set but no selected fault has that parameter (selected: gps_drift)"),
    (["fault.targets=[1]"], "fault.targets is set but no selected fault has that parameter (selected: none)"),
])
def test_bad_fault_config_is_refused_before_the_first_tick(run, overrides, message):
    manifest, d = run(*HOVER, *overrides)
    assert manifest["status"] == "failed" and manifest["ticks"] == 0
    assert "FaultConfigError" in manifest["reason"] and message in manifest["reason"], manifest["reason"]


@pytest.mark.parametrize("fault, needs", [
    ("gps_drift", "a GNSS offset input (gnss_offset_ned_m)"),
    ("gps_noise", "a GNSS noise input (gnss_noise_scale)"),
    ("crash", "a crash input (crashed)"),
    ("motor_loss", "a thrust (acceleration scale) input (accel_scale)"),
])
def test_fault_the_backend_cannot_express_names_fault_and_backend(run, fault, needs):
    manifest, _ = run(*HOVER, "backend._target_=tests.faults.backends.BareBackend", f"fault={fault}")
    assert manifest["status"] == "failed", manifest["reason"]
    assert (f"fault {fault} cannot run on backend 'sim' (tests.faults.backends.BareBackend): it needs "
            f"{needs}, which this backend does not provide") in manifest["reason"]


def test_backend_independent_faults_run_on_a_bare_backend(run):
    manifest, d = run(*HOVER, "algo.params.hover_s=5", "backend._target_=tests.faults.backends.BareBackend",
                      "fault=[latency,battery_failsafe]", "fault.targets=[1]", "fault.onset_s=4",
                      "mission.max_sim_time_s=25")
    assert set(fault_events(d)["name"]) == {"latency_start", "battery_failsafe_start"}
