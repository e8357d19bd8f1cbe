"""An inferior whose drone superior aborts (its vehicle failed, a failsafe) hands over to the next
successor, just as when the superior falls silent; a whole-mission abort still lands everyone."""

import json

from tests.conftest import table


def test_followers_hand_over_when_the_leader_aborts(run):
    manifest, d = run("topology=leader_follower", "fault=battery_failsafe", "fault.targets=[0]",
                      "fault.onset_s=40", "mission.max_sim_time_s=150")
    assert manifest["status"] == "ok", manifest["reason"]
    assert "drones [0] aborted" in manifest["reason"]
    assert list(table(d, "drone_0", "stages")["name"])[-1] == "ABORT"
    for follower in (1, 2, 3):
        ev = table(d, f"drone_{follower}", "events")
        aborted = ev[ev["name"] == "superior_aborted"]
        handover = ev[ev["name"] == "handover"]
        assert len(aborted) == 1 and json.loads(aborted["data"].iloc[0]) == {"superior": 0}
        assert len(handover) == 1 and json.loads(handover["data"].iloc[0]) == {"lost": 0, "new": -1}
        assert 40.0 < handover["t_s"].iloc[0] < 40.5      # at the leader's next heartbeat, not a timeout
        assert list(table(d, f"drone_{follower}", "stages")["name"])[-1] == "TERMINATION"
        assert table(d, f"drone_{follower}", "state").iloc[-1]["landed"]
