"""Workload, safety, swarm and discrepancy metrics against hand-computed values.

Default scenario (25 ms ticks): EXECUTION from tick 80 to tick 680 -> 15 s. Drone i flies north at
speeds (1, 2, 3, 4) m/s from tick 80 until its completion tick (280, 480, 380; drone 3 never
completes and flies until tick 680), drones 5 m apart eastward.
"""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest

from swarmbox.analysis import metrics
from swarmbox.analysis.report import AnalysisOptions, analyze_run


@pytest.fixture
def base(make_run):
    return analyze_run(make_run(collisions=[(0, 100), (1, 100), (2, 700)], gnss_bias_m={2: 0.3}))


def test_mission_duration(base):
    assert base.window.start == pytest.approx(2.0)
    assert base.window.end == pytest.approx(17.0) and base.window.complete
    assert base.scalars["mission_duration_s"] == pytest.approx(15.0)


def test_per_drone_workload(base):
    d = base.drones.set_index("drone")
    assert d["distance_h_m"].to_list() == pytest.approx([5.0, 20.0, 22.5, 60.0])
    assert d["busy_s"].to_list() == pytest.approx([5.0, 10.0, 7.5, 15.0])
    assert d["utilization"].to_list() == pytest.approx([1 / 3, 2 / 3, 0.5, 1.0])
    assert d["idle_s"].to_list() == pytest.approx([10.0, 5.0, 7.5, 0.0])
    assert d["completed"].to_list() == [True, True, True, False]
    assert set(d["position_source"]) == {"truth"}


def test_workload_mean_and_population_std(base):
    s = base.scalars
    busy = np.array([5.0, 10.0, 7.5, 15.0])
    assert s["busy_s_mean"] == pytest.approx(9.375)
    assert s["busy_s_std"] == pytest.approx(math.sqrt(((busy - 9.375) ** 2).mean()))   # ddof 0
    assert s["distance_h_m_mean"] == pytest.approx(107.5 / 4)
    assert s["distance_h_m_total"] == pytest.approx(107.5)
    assert s["utilization_mean"] == pytest.approx(0.625)
    assert s["idle_s_mean"] == pytest.approx(22.5 / 4)
    assert s["completed_fraction"] == pytest.approx(0.75)


def test_three_d_distance_counts_the_climb(make_run):
    a = analyze_run(make_run(climb_m_s={0: 0.75}))
    d = a.drones.set_index("drone")
    assert d.loc[0, "distance_h_m"] == pytest.approx(5.0)
    assert d.loc[0, "distance_3d_m"] == pytest.approx(5.0 * 1.25)   # sqrt(1 + 0.75^2) = 1.25


def test_completion_that_flips_back_counts_the_final_one(make_run):
    a = analyze_run(make_run(progress=[(0, 300, "exec_incomplete"), (0, 400, "exec_complete")]))
    assert a.drones.set_index("drone").loc[0, "busy_s"] == pytest.approx((400 - 80) * 0.025)


def test_safety(base):
    s = base.scalars
    assert s["min_separation_m"] == pytest.approx(5.0)
    assert s["collision_events"] == 3.0          # the whole run, tick 700 is after EXECUTION
    assert s["time_below_separation_s"] == 0.0   # threshold 2 m < 5 m
    assert len(base.swarm) == 800 and base.swarm["separation_m"].min() == pytest.approx(5.0)


def test_time_below_separation(make_run):
    # two drones 5 m apart, 1 m/s apart northward: below 6 m while 25 + dn^2 < 36, i.e.
    # dn < sqrt(11); dn = (k - 80) * 0.025 -> ticks 80..212 -> 133 ticks
    a = analyze_run(make_run(n_drones=2, speeds_m_s=(1.0, 2.0), complete_ticks={}),
                    AnalysisOptions(separation_m=6.0))
    assert a.scalars["time_below_separation_s"] == pytest.approx(133 * 0.025)


def test_order_by_tick():
    state = pd.DataFrame({
        "node": [0, 1, 0, 1, 0, 1], "tick": [0, 0, 1, 1, 2, 2],
        "vel_n": [1.0, 0.0, 1.0, -1.0, 0.0, 0.0], "vel_e": [0.0, 1.0, 0.0, 0.0, 0.0, 0.0],
        "vel_d": [0.0] * 6,
    })
    order = metrics.order_by_tick(state, [0, 1])
    assert order.iloc[0] == pytest.approx(math.sqrt(2) / 2)
    assert order.iloc[1] == pytest.approx(0.0)
    assert np.isnan(order.iloc[2])           # at rest: undefined


def test_order_of_parallel_flight(base):
    assert base.scalars["order_mean"] == pytest.approx(1.0)


def test_discrepancy(base):
    d = base.drones.set_index("drone")
    assert d.loc[2, "disc_h_m_mean"] == pytest.approx(0.3)
    assert d.loc[0, "disc_h_m_max"] == pytest.approx(0.0)
    assert base.scalars["discrepancy_h_m_max"] == pytest.approx(0.3)
    assert base.scalars["discrepancy_h_m_mean"] == pytest.approx(0.3 / 4)


def test_run_scalars_from_manifest(base):
    assert base.scalars["real_time_factor"] == 100.0
    assert base.scalars["sim_time_s"] == pytest.approx(20.0)


def test_ground_never_in_execution(make_run):
    a = analyze_run(make_run(ground_stages={1: 0, 2: 40}, complete_ticks={}))
    assert a.window is None
    assert "mission_duration_s" not in a.scalars
    assert any("never entered EXECUTION" in p for p in a.problems)
    assert a.scalars["latency_ms_mean"] == pytest.approx(25.0)


def test_execution_without_end_runs_to_last_record(make_run):
    a = analyze_run(make_run(ground_stages={1: 0, 2: 40, 3: 80}))
    assert not a.window.complete
    assert a.scalars["mission_duration_s"] == pytest.approx((799 - 80) * 0.025)   # last record: tick 799
