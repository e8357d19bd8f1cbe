"""The setpoint log records the safety monitor's verdict and reason for every setpoint."""

from tests.conftest import table


def test_refused_and_clamped_setpoints_are_logged_as_such_with_the_reason(run):
    manifest, d = run("algo=hover", "mission=hover",
                      "algo.drone._target_=tests.core.algos.BadSetpointDrone")
    assert manifest["status"] == "ok", manifest["reason"]
    sp = table(d, "drone_0", "setpoints")
    ex = sp.set_index("tick")
    first = int(table(d, "drone_0", "stages").set_index("stage").loc[3, "tick"])
    rows = {k: ex.loc[first + k] for k in (40, 41, 42, 43)}
    assert (rows[40]["verdict"], rows[40]["reason"]) == ("refused", "nonfinite")
    assert (rows[41]["verdict"], rows[41]["reason"]) == ("refused", "jump") and rows[41]["n"] == 1500.0
    assert (rows[42]["verdict"], rows[42]["reason"]) == ("clamped", "geofence")
    assert (rows[43]["verdict"], rows[43]["reason"]) == ("clamped", "ceiling")
    others = sp.drop(index=sp.index[sp["tick"].isin([first + k for k in (40, 41, 42, 43)])])
    assert set(others["verdict"]) == {"ok"} and set(others["reason"]) == {""}
