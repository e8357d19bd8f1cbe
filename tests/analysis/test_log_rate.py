"""Log-rate invariance (metamorphic): one seeded flight, logged every 1st, 2nd and 4th tick and flown at
20, 40 and 50 Hz, gives the same metrics within one sample period and the same diagnosis.

Each metric's tolerance follows from the sample period T (the coarser of the two runs compared):
a time stamp on the tick grid moves by at most T, a duration (two stamps) by 2T; a distance by the
path flown in 2T; a minimum distance by the closing speed times T; a mean over samples by the
signal's total variation x T / duration (a Riemann sum's error). The message log is never thinned:
logged at another state rate its metrics must not move at all; flown at another tick rate the
messages themselves differ (heartbeats per tick, other random draws), so latency and loss are
compared within three standard errors, and the bytes sent per second, which scale with the tick
rate, are not compared.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest

from swarmbox.analysis import diagnosis as dg
from swarmbox.analysis import metrics, sampling
from swarmbox.analysis.report import AnalysisOptions, RunAnalysis, analyze_run
from tests.conftest import run_config

#: 4 drones hovering 5 m apart; drone 2's GNSS biased 3 m east from 6 s (no collision: the drone drifts
#: 3 m west, away from its neighbours' line); a lossy, jittery network.
FLIGHT = ("algo=hover", "mission=hover", "algo.params.hover_s=12", "fault=gps_bias", "fault.onset_s=6",
          "fault.targets=[2]", "fault.bias_ned_m=[0,3,0]", "network.latency_ms=1", "network.jitter_ms=1",
          "network.loss_prob=0.05")
#: Above the 5 m spacing: every logged tick is below it, so the whole window is integrated.
SEPARATION_M = 5.5
LOGGED = {"every2": ("run.state_every_ticks=2",), "every4": ("run.state_every_ticks=4",)}
FLOWN = {"hz20": ("run.tick_hz=20",), "hz50": ("run.tick_hz=50",)}
EXACT_WHEN_LOGGED = ("loss_ratio", "latency_ms_mean", "latency_ms_p50", "latency_ms_p95", "latency_ms_max",
                     "tx_bytes_per_s_mean", "connectivity_mean", "connectivity_min", "mission_duration_s",
                     "busy_s_mean", "busy_s_std", "idle_s_mean", "completed_fraction", "collision_events",
                     "safety_events")
DURATIONS = ("mission_duration_s", "busy_s_mean", "idle_s_mean", "time_below_separation_s")


@dataclass
class Flight:
    analysis: RunAnalysis
    period_s: float
    finding: dict


def _fly(root: Path, name: str, extra: tuple[str, ...]) -> Flight:
    manifest = run_config(root / name, (*FLIGHT, *extra))
    assert manifest["status"] == "ok", manifest["reason"]
    analysis = analyze_run(root / name, AnalysisOptions(separation_m=SEPARATION_M))
    series = dg.drone_series(analysis.run)
    assert not series.problems, series.problems
    return Flight(analysis, sampling.state_period_s(analysis.run), dg.finding(dg.scan(series)))


@pytest.fixture(scope="module")
def flights(tmp_path_factory) -> dict[str, Flight]:
    root = tmp_path_factory.mktemp("log_rate")
    return {name: _fly(root, name, extra) for name, extra in {"every1": (), **LOGGED, **FLOWN}.items()}


def _variation(values: np.ndarray) -> float:
    values = values[np.isfinite(values)]
    return float(np.abs(np.diff(values)).sum())


def _reference_rates(ref: RunAnalysis) -> dict[str, float]:
    """What the tolerances scale with, from the every-tick log: top speed, total variations, the
    discrepancy's excursion within a step of its peak."""
    state, window = ref.run.tables["state"], ref.window
    speed = np.linalg.norm(state[["vel_n", "vel_e", "vel_d"]].to_numpy(dtype="float64"), axis=1)
    disc = metrics.within(metrics.discrepancy(state), window).sort_values(["node", "tick"])
    tv_disc = np.mean([_variation(g["disc_h_m"].to_numpy()) for _, g in disc.groupby("node")])
    peak = disc.loc[disc["disc_h_m"].idxmax()]
    return {"v_max": float(np.nanmax(speed)), "tv_disc": float(tv_disc),
            "tv_order": _variation(metrics.within(ref.swarm, window)["order"].to_numpy()),
            "duration": window.duration, "disc_peak_t": float(peak["t_u"]),
            "disc_peak": float(peak["disc_h_m"]), "disc_peak_node": int(peak["node"]), "disc": disc}


def _peak_excursion(rates: dict, period_s: float) -> float:
    """Largest change of the peak drone's discrepancy within one period of its peak."""
    disc = rates["disc"]
    near = disc[(disc["node"] == rates["disc_peak_node"]) & ((disc["t_u"] - rates["disc_peak_t"]).abs()
                                                             <= period_s + 1e-9)]
    return float((near["disc_h_m"] - rates["disc_peak"]).abs().max())


def tolerances(rates: dict, period_s: float, same_flight: bool) -> dict[str, float]:
    """Per metric: how far a run sampled every ``period_s`` may lie from the every-tick reference."""
    tol = {m: 2 * period_s for m in DURATIONS}   # a duration: two stamps, each within one period
    tol |= {m: 2 * period_s / rates["duration"] for m in ("utilization_mean",)}
    path = 2 * rates["v_max"] * period_s   # the path flown in the two periods at the window's ends
    tol |= {"distance_h_m_mean": path, "distance_3d_m_mean": path, "distance_h_m_std": path,
            "distance_3d_m_std": path, "distance_h_m_total": 4 * path}
    tol["min_separation_m"] = 2 * rates["v_max"] * period_s
    tol["discrepancy_h_m_mean"] = rates["tv_disc"] * period_s / rates["duration"]
    tol["discrepancy_h_m_max"] = _peak_excursion(rates, period_s)
    tol["order_mean"] = rates["tv_order"] * period_s / rates["duration"]
    if same_flight:
        tol |= {m: 0.0 for m in EXACT_WHEN_LOGGED}
    return tol


def _standard_error(a: RunAnalysis, b: RunAnalysis, metric: str) -> float:
    """Standard error of the difference of a network metric between two independent flights."""
    def one(run: RunAnalysis) -> float:
        counted = run.flow[run.flow["counted"]]
        if metric == "loss_ratio":
            p = counted["lost"].mean()
            return p * (1 - p) / len(counted)
        got = run.flow[run.flow["delivered"]]["latency_ms"]
        return got.var() / len(got)
    return float(np.sqrt(one(a) + one(b)))


@pytest.mark.parametrize("name", [*LOGGED, *FLOWN])
def test_metrics_move_by_at_most_one_sample_period(flights, name):
    ref, got = flights["every1"], flights[name]
    period = max(ref.period_s, got.period_s)
    rates = _reference_rates(ref.analysis)
    tol = tolerances(rates, period, same_flight=name in LOGGED)
    if name in FLOWN:
        tol |= {m: 3 * _standard_error(ref.analysis, got.analysis, m)
                for m in ("loss_ratio", "latency_ms_mean")}
    assert got.period_s == pytest.approx({"every2": 0.05, "every4": 0.1, "hz20": 0.05, "hz50": 0.02}[name])
    assert ref.analysis.scalars["time_below_separation_s"] == pytest.approx(rates["duration"], abs=0.025)
    off = {m: (ref.analysis.scalars[m], got.analysis.scalars[m], t) for m, t in tol.items()
           if not abs(got.analysis.scalars[m] - ref.analysis.scalars[m]) <= t + 1e-9}
    assert not off, off


@pytest.mark.parametrize("name", [*LOGGED, *FLOWN])
def test_same_diagnosis_within_one_sample(flights, name):
    """The onset-agnostic finding (drone, metric, first alarm) and the fault-scored diagnosis."""
    ref, got = flights["every1"], flights[name]
    assert ref.finding["detected"] and (ref.finding["drone"], ref.finding["metric"]) == (2, "disc_e_m")
    assert got.finding["detected"]
    assert (got.finding["drone"], got.finding["metric"]) == (ref.finding["drone"], ref.finding["metric"])
    assert abs(got.finding["t_u"] - ref.finding["t_u"]) <= max(ref.period_s, got.period_s) + 1e-9
    scored = {k: got.analysis.scalars[k] for k in ("anomaly_is_target", "anomaly_t_f_s")}
    assert scored == {k: ref.analysis.scalars[k] for k in scored}


def test_persistence_is_a_duration():
    """0.1 s is 4 points of 25 ms, 2 of 50 ms, 1 of 100 ms (and never less than one)."""
    opts = dg.DiagnosisOptions()
    assert [opts.persist_points(s) for s in (0.025, 0.02, 0.05, 0.1, 0.5)] == [4, 5, 2, 1, 1]
    assert dg.DiagnosisOptions(persist_s=0.0).persist_points(0.025) == 1


def test_a_grid_finer_than_the_log_is_reported(flights):
    """Scanning the every-4th-tick log on a 25 ms grid leaves three cells in four empty: said, not silent."""
    run = flights["every4"].analysis.run
    series = dg.drone_series(run, dg.DiagnosisOptions(step_s=0.025))
    assert len(series.problems) == 1 and "grid" in series.problems[0]
    assert not dg.drone_series(run).problems


#: A moving flight: 5 drones delivering 6 packages in a 60 m square (GNSS at 10 Hz: a 4-tick sawtooth
#: of the GNSS - estimate gap, which a 20 Hz state log sees only just after each fix).
MOVING = ("mission=delivery", "algo=delivery_distance_rr", "mission.generator.count=6",
          "mission.generator.half_size_m=30")


@pytest.fixture(scope="module")
def moving(tmp_path_factory) -> dict[int, RunAnalysis]:
    root = tmp_path_factory.mktemp("moving")
    out = {}
    for every in (1, 2, 4):
        manifest = run_config(root / str(every), (*MOVING, f"run.state_every_ticks={every}"))
        assert manifest["status"] == "ok", manifest["reason"]
        out[every] = analyze_run(root / str(every))
    return out


@pytest.mark.parametrize("every", [2, 4])
def test_a_moving_flight_s_discrepancy_is_not_aliased(moving, every):
    """Between two logged rows the estimate moves with its velocity; it departs from that by at most
    a T^2 / 2 (a: the configured acceleration limit), so that bounds the discrepancy's change."""
    ref, got = moving[1], moving[every]
    period = sampling.state_period_s(got.run)
    tol = float(got.run.config["run"]["safety"]["max_accel_m_s2"]) * period**2 / 2
    for metric in ("discrepancy_h_m_mean", "discrepancy_h_m_max"):
        assert got.scalars[metric] == pytest.approx(ref.scalars[metric], abs=tol), metric
    # the logged rows alone (what the mean was before) are off by far more: the test has teeth
    rows = metrics.within(metrics.discrepancy(got.run.tables["state"]), got.window)
    assert rows.groupby("node")["disc_h_m"].mean().mean() < ref.scalars["discrepancy_h_m_mean"] - 2 * tol
    assert got.scalars["distance_h_m_mean"] == pytest.approx(ref.scalars["distance_h_m_mean"],
                                                             abs=2 * period * 12.0)   # 12 m/s: speed limit
