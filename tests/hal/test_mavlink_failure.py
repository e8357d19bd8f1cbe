"""MAV_CMD_INJECT_FAILURE requests and their acknowledgement (swarmbox.hal.mavlink.failure)."""

from __future__ import annotations

from typing import NamedTuple

import pytest

from swarmbox.hal.mavlink import codec as mc
from swarmbox.hal.mavlink.failure import CMD_INJECT_FAILURE, FailureInjector, FailureRequest
from swarmbox.hal.mavlink.link import CommandTracker
from swarmbox.hal.mavlink.paramset import PARAM_INT32, ParamSetter, param_from_wire, param_to_wire


class Autopilot:
    """A command tracker whose sends are recorded; acks are fed by the test."""

    def __init__(self, retries: int = 1) -> None:
        self.sent: list[tuple[int, tuple[float, ...]]] = []
        self.events: list[tuple[str, str, dict]] = []
        self.injector: FailureInjector
        self.tracker = CommandTracker(lambda c, p, k: self.sent.append((c, p)) or True, lambda n, d: None,
                                      1.0, retries, on_failed=lambda cmd, r: self.injector.on_failed(cmd, r))
        self.now = 0.0
        self.injector = FailureInjector(lambda cmd: self.tracker.submit(cmd, self.now),
                                        lambda kind, name, data: self.events.append((kind, name, data)))

    def ack(self, result: int) -> None:
        self.tracker.on_ack(mc.CommandAckMsg(CMD_INJECT_FAILURE, result, 255), self.now)


def test_request_params_round_trip_and_bad_names():
    req = FailureRequest("gps", "off")
    assert req.params == (4.0, 1.0, 0.0)
    assert FailureRequest.from_params((4.0, 2.0, 1.0)) == FailureRequest("gps", "stuck", 1)
    with pytest.raises(ValueError, match="unit 'gnss' unknown"):
        FailureRequest("gnss", "off")
    with pytest.raises(ValueError, match="type 'broken' unknown"):
        FailureRequest("gps", "broken")
    with pytest.raises(ValueError, match="not MAVLink codes"):
        FailureRequest.from_params((99.0, 1.0))


def test_accepted_failure_is_active_until_ended():
    ap = Autopilot()
    ap.injector.inject(FailureRequest("gps", "off"))
    assert ap.sent == [(CMD_INJECT_FAILURE, (4.0, 1.0, 0.0))]
    ap.ack(mc.RESULT_ACCEPTED)
    assert ap.injector.active == {("gps", 0): "off"}
    assert ap.events[-1] == ("fault", "inject_accepted", {"unit": "gps", "type": "off", "instance": 0,
                                                   "via": "MAV_CMD_INJECT_FAILURE"})
    ap.injector.end("gps")
    ap.ack(mc.RESULT_ACCEPTED)
    assert ap.injector.active == {} and ap.sent[-1][1] == (4.0, 0.0, 0.0)


def test_denied_and_unanswered_injections_name_the_cause():
    ap = Autopilot(retries=1)
    ap.injector.inject(FailureRequest("gps", "off"))
    ap.ack(mc.RESULT_DENIED)           # retried once, a timeout later (a refusal that may pass) ...
    ap.now = 1.0
    ap.tracker.service(ap.now)
    assert len(ap.sent) == 2
    ap.ack(mc.RESULT_DENIED)           # ... then given up
    kind, name, data = ap.events[-1]
    assert (kind, name, data["result"]) == ("fault", "inject_refused", "denied")
    assert "SYS_FAILURE_EN" in data["cause"] and not ap.injector.active
    ap.injector.inject(FailureRequest("baro", "off"))
    for ap.now in (2.0, 3.0, 4.0):
        ap.tracker.service(ap.now)
    assert ap.events[-1][2]["result"] == "no ack" and ap.injector.refused == 2


def test_injections_of_different_units_queue_in_order():
    ap = Autopilot()
    ap.injector.inject(FailureRequest("gps", "off"))
    ap.injector.inject(FailureRequest("baro", "off"))
    ap.ack(mc.RESULT_ACCEPTED)
    ap.ack(mc.RESULT_UNSUPPORTED)
    assert [e[1] for e in ap.events] == ["inject_accepted", "inject_refused"]
    assert ap.events[1][2]["unit"] == "baro" and ap.events[1][2]["result"] == "unsupported"


class Value(NamedTuple):
    name: str
    value: float


def test_param_setter_confirms_by_echo_and_gives_up_with_what_it_saw():
    sent: list[tuple[str, float, int]] = []
    outcome: list[tuple[bool, str]] = []
    ps = ParamSetter(lambda n, v, k: sent.append((n, v, k)) or True, timeout_s=1.0, retries=1)
    ps.set("SIM_GPS_USED", 0, 0.0, lambda ok, why: outcome.append((ok, why)))
    ps.on_value(Value("SIM_GPS_USED", 10.0))      # an older value: not yet
    ps.service(1.0)                                # re-sent
    ps.on_value(Value("SIM_GPS_USED", 0.0))
    assert outcome == [(True, "")] and len(sent) == 2 and sent[0][2] == PARAM_INT32
    ps.set("SIM_GPS_USED", 10, 2.0, lambda ok, why: outcome.append((ok, why)))
    ps.on_value(Value("SIM_GPS_USED", 0.0))
    for now in (3.0, 4.0, 5.0):
        ps.service(now)
    assert outcome[-1] == (False, "SIM_GPS_USED=10 not confirmed after 2 tries (it holds 0)")
    assert param_from_wire(param_to_wire(10, PARAM_INT32), PARAM_INT32) == 10.0


def test_gnss_failure_through_sim_gps_used_when_asked():
    writes: list[tuple[str, float]] = []
    events: list[tuple[str, str, dict]] = []

    def set_param(name, value, done):
        writes.append((name, value))
        done(True, "")

    inj = FailureInjector(lambda cmd: pytest.fail("no command expected"),
                          lambda kind, name, data: events.append((kind, name, data)), set_param,
                          gnss_via_param=True)
    inj.inject(FailureRequest("gps", "off"))
    assert writes == [("SIM_GPS_USED", 0)] and inj.active == {("gps", 0): "off"}
    assert events[-1][2]["via"] == "SIM_GPS_USED"
    inj.end("gps")
    assert writes[-1] == ("SIM_GPS_USED", 10) and not inj.active
    inj.inject(FailureRequest("gps", "stuck"))
    assert events[-1][1] == "inject_refused" and events[-1][2]["result"] == "unsupported"
