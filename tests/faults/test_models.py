"""Every fault model shows its effect in the logs with the configured magnitude."""

import json
import math

import numpy as np
import pandas as pd
import pytest

from tests.conftest import table
from tests.faults.helpers import HOVER, fault_events, flow, slope, touching

ONSET, END = 10.0, 30.0
WINDOW = (f"fault.onset_s={ONSET}", f"fault.duration_s={END - ONSET}")


def state(run_dir, drone):
    return table(run_dir, f"drone_{drone}", "state")


def during(frame, t0=ONSET, t1=END, col="t_s"):
    return frame[(frame[col] >= t0) & (frame[col] < t1)]


def fixes(st):
    """One row per GNSS fix (the state table repeats the latest fix between fixes)."""
    return st.loc[st["gnss_n"].diff().fillna(1.0) != 0.0]


# -- GNSS ---------------------------------------------------------------------------------------
def test_gps_drift_ramps_at_the_rate_and_the_discrepancy_follows(run):
    manifest, d = run(*HOVER, "fault=gps_drift", "fault.rate_m_s=2", "fault.targets=[1]", *WINDOW)
    assert manifest["status"] == "ok", manifest["reason"]
    ev = fault_events(d)
    assert list(ev["name"]) == ["gps_drift_start", "gps_drift_end"]
    assert list(ev["t_s"]) == [ONSET, END] and set(ev["subject"]) == {1}
    assert ev["info"].iloc[0] == {"fault": "gps_drift", "target": 1, "rate_m_s": 2.0, "onset_s": ONSET,
                                       "duration_s": END - ONSET, "direction_ned": [1.0, 0.0, 0.0]}
    st = state(d, 1)
    f = fixes(during(st, ONSET + 0.2, END))
    assert slope(f["t_s"].to_numpy(), (f["gnss_n"] - f["true_n"]).to_numpy()) == pytest.approx(2.0, abs=0.02)
    assert np.abs(f["gnss_e"] - f["true_e"]).max() < 0.3          # north only
    # The estimator first follows the slow ramp, then rejects the fixes: from then on the
    # discrepancy (GNSS - estimate) grows at the drift rate until the estimator resets.
    resets = table(d, "drone_1", "events").query("kind == 'estimator' and name == 'position_reset'")
    assert len(resets) and ONSET < resets["t_s"].iloc[0] < END
    t_reset = resets["t_s"].iloc[0]
    disc = st["gnss_n"] - st["pos_n"]
    rejecting = st[(st["t_s"] > t_reset - 4.0) & (st["t_s"] < t_reset - 0.1)]
    assert slope(rejecting["t_s"].to_numpy(), disc[rejecting.index].to_numpy()) == pytest.approx(2.0, abs=0.1)
    for other in (0, 2, 3):
        o = state(d, other)
        assert np.abs(o["gnss_n"] - o["true_n"]).max() < 0.5
    after = fixes(st[st["t_s"] > END + 0.2])
    assert np.abs(after["gnss_n"] - after["true_n"]).max() < 0.3   # the receiver recovered


def test_gps_bias_offsets_the_fixes_for_the_window(run):
    manifest, d = run(*HOVER, "fault=gps_bias", "fault.bias_ned_m=[0,-4,0]", "fault.targets=[2]", *WINDOW)
    assert manifest["status"] == "ok", manifest["reason"]
    st = state(d, 2)
    err = (st["gnss_e"] - st["true_e"])
    assert err[during(st, ONSET + 0.2).index].mean() == pytest.approx(-4.0, abs=0.05)
    assert abs(err[st["t_s"] > END + 0.2].mean()) < 0.05
    assert abs(err[(st["t_s"] > 1) & (st["t_s"] < ONSET)].mean()) < 0.05


def test_gps_noise_multiplies_the_fix_noise(run):
    manifest, d = run(*HOVER, "fault=gps_noise", "fault.noise_scale=10", "fault.targets=[3]", *WINDOW)
    assert manifest["status"] == "ok", manifest["reason"]
    sigma = {}
    for drone in (0, 3):
        f = fixes(during(state(d, drone), ONSET + 0.2))
        sigma[drone] = float((f["gnss_n"] - f["true_n"]).std())
    assert sigma[0] == pytest.approx(0.05, rel=0.2)          # the receiver's nominal 5 cm
    assert sigma[3] == pytest.approx(0.5, rel=0.2)


def test_gps_dropout_stops_the_fixes(run):
    manifest, d = run(*HOVER, "fault=gps_dropout", "fault.targets=[0]", *WINDOW)
    assert manifest["status"] == "ok", manifest["reason"]
    assert during(state(d, 0), ONSET + 0.2)["gnss_n"].nunique() == 1
    assert during(state(d, 1), ONSET + 0.2)["gnss_n"].nunique() > 100
    assert state(d, 0)[state(d, 0)["t_s"] > END + 0.5]["gnss_n"].nunique() > 10


# -- network ------------------------------------------------------------------------------------
def test_latency_is_measured_as_injected(run):
    manifest, d = run(*HOVER, "fault=latency", "fault.latency_ms=20", "fault.targets=[2]", *WINDOW)
    assert manifest["status"] == "ok", manifest["reason"]
    fl = during(flow(d)).dropna(subset=["t_recv"])
    mine = touching(fl, 2)
    assert len(mine) > 1000 and set(mine["src"]) == {-1, 2} and set(mine["dst"]) == {-1, 2}
    assert mine["latency_ms"].mean() == pytest.approx(20.0, abs=1.0)
    assert mine["latency_ms"].min() == pytest.approx(20.0, abs=1e-6)
    others = fl[~fl.index.isin(mine.index)]
    assert others["latency_ms"].abs().max() < 1e-6


def test_latency_jitter_is_uniform_on_top(run):
    manifest, d = run(*HOVER, "fault=latency", "fault.latency_ms=10", "fault.jitter_ms=10",
                      "fault.targets=[1]", *WINDOW)
    assert manifest["status"] == "ok", manifest["reason"]
    lat = touching(during(flow(d)).dropna(subset=["t_recv"]), 1)["latency_ms"]
    assert lat.mean() == pytest.approx(15.0, abs=0.5)
    assert 10.0 - 1e-6 <= lat.min() < 10.5 and 19.5 < lat.max() <= 20.0 + 1e-6


def test_bernoulli_loss_is_measured_as_injected(run):
    manifest, d = run(*HOVER, "fault=packet_loss", "fault.loss_prob=0.3", "fault.targets=[2]", *WINDOW)
    assert manifest["status"] == "ok", manifest["reason"]
    fl = during(flow(d), ONSET, END - 0.1)
    mine = touching(fl, 2)
    lost = mine["t_recv"].isna()
    assert len(mine) > 1000
    assert lost.mean() == pytest.approx(0.30, abs=0.03)
    assert set(mine.loc[lost, "reason"]) == {"fault:packet_loss"}
    assert fl[~fl.index.isin(mine.index)]["t_recv"].notna().all()


def test_burst_loss_matches_the_gilbert_elliott_chain(run):
    manifest, d = run(*HOVER, "fault=burst_loss", "fault.p_enter_burst=0.05", "fault.p_leave_burst=0.25",
                      "fault.targets=[1]", *WINDOW)
    assert manifest["status"] == "ok", manifest["reason"]
    mine = touching(during(flow(d), ONSET, END - 0.1), 1)
    # the chain steps in send order: by tick, the ground before the drones
    mine = mine.assign(order=np.where(mine["src"] == -1, 0, 1)).sort_values(["tick", "order", "msg_id"])
    lost = mine["t_recv"].isna().to_numpy()
    # Tolerances of 4 standard errors (a false alarm about 1 in 16,000 seeds). The loss indicator is
    # the chain's state: stationary mean pi = p_enter / (p_enter + p_leave), lag-1 autocorrelation
    # lam = 1 - p_enter - p_leave, so the mean of n correlated samples has variance
    # pi (1 - pi) / n * (1 + lam) / (1 - lam). Burst lengths are geometric: variance (1 - p) / p^2.
    p_enter, p_leave = 0.05, 0.25
    pi, lam = p_enter / (p_enter + p_leave), 1 - p_enter - p_leave
    se_loss = math.sqrt(pi * (1 - pi) / len(lost) * (1 + lam) / (1 - lam))
    assert lost.mean() == pytest.approx(pi, abs=4 * se_loss)
    edges = np.flatnonzero(np.diff(np.concatenate([[0], lost.astype(int), [0]])))
    bursts = edges[1::2] - edges[0::2]
    se_burst = math.sqrt((1 - p_leave) / p_leave**2 / len(bursts))
    assert bursts.mean() == pytest.approx(1 / p_leave, abs=4 * se_burst)   # geometric, mean 1 / p_leave


def test_link_cut_on_a_node_and_on_one_direction(run):
    manifest, d = run(*HOVER, "fault=link_cut", "fault.targets=[3,[-1,1]]", "fault.onset_s=10",
                      "fault.duration_s=0.4")
    assert manifest["status"] == "ok", manifest["reason"]
    fl = flow(d)
    cut = fl[(fl["t_s"] >= 10.0) & (fl["t_s"] < 10.4)]
    node3 = touching(cut, 3)
    assert len(node3) and node3["t_recv"].isna().all() and set(node3["reason"]) == {"fault:link_cut"}
    down1 = cut[(cut["src"] == -1) & (cut["dst"] == 1)]
    up1 = cut[(cut["src"] == 1) & (cut["dst"] == -1)]
    assert down1["t_recv"].isna().all() and up1["t_recv"].notna().all()
    after = fl[fl["t_s"] >= 10.45]
    assert touching(after, 3)["t_recv"].notna().mean() > 0.99


def test_partition_drops_only_what_crosses(run):
    manifest, d = run(*HOVER, "topology.peers=all", "fault=partition", "fault.targets=[2,3]",
                      "fault.onset_s=10", "fault.duration_s=0.4")
    assert manifest["status"] == "ok", manifest["reason"]
    fl = flow(d)
    cut = fl[(fl["t_s"] >= 10.0) & (fl["t_s"] < 10.4)]
    side = cut["src"].isin([2, 3]) != cut["dst"].isin([2, 3])
    assert side.sum() > 50 and cut.loc[side, "t_recv"].isna().all()
    assert cut.loc[~side, "t_recv"].notna().all()
    inside = cut[(cut["src"] == 2) & (cut["dst"] == 3)]
    assert len(inside) >= 15


# -- vehicle ------------------------------------------------------------------------------------
def test_crash_silences_the_node_and_drops_the_vehicle(run):
    swarms = []
    manifest, d = run(*HOVER, "fault=crash", "fault.targets=[2]", "fault.onset_s=10", prepare=swarms.append)
    assert manifest["status"] == "ok" and "lost drones [2]" in manifest["reason"]
    ev = table(d, "drone_2", "events")
    assert {("failsafe", "node_removed"), ("fault", "crash")} <= set(zip(ev["kind"], ev["name"], strict=True))
    crash = ev[ev["name"] == "crash"]
    assert json.loads(crash["data"].iloc[0])["alt_m"] == pytest.approx(3.0, abs=0.2)
    sent = table(d, "drone_2", "messages").query("kind == 'send'")
    assert sent["t_s"].max() < 10.0
    assert state(d, 2)["t_s"].max() < 10.0             # the node logged nothing more
    backend = swarms[0].backend
    assert backend.true_pos_ned_m[2, 2] == 0.0 and backend.crashed[2]   # it fell to the ground
    lost = table(d, "ground", "events").query("name == 'inferior_lost'")
    assert list(lost["subject"]) == [2] and 10.4 < lost["t_s"].iloc[0] < 10.6


def test_motor_loss_scales_the_climb_acceleration(run):
    manifest, d = run(*HOVER, "fault=motor_loss", "fault.accel_scale=0.3", "fault.targets=[1]",
                      "fault.onset_s=0", "fault.duration_s=20")
    assert manifest["status"] == "ok", manifest["reason"]

    def max_climb_accel(drone):
        st = during(state(d, drone), 0.0, 20.0)
        z = st["true_d"].to_numpy()
        acc = np.diff(z, 2) / 0.025 ** 2
        airborne = (z[2:] < -0.3) & (z[1:-1] < -0.3) & (z[:-2] < -0.3)
        return -acc[airborne].min()

    nominal, weak = max_climb_accel(0), max_climb_accel(1)
    assert nominal == pytest.approx(4.0, abs=0.4)            # MPC_ACC_UP_MAX, less drag
    assert weak / nominal == pytest.approx(0.3, abs=0.03)


def test_battery_failsafe_returns_home_and_lands(run):
    manifest, d = run(*HOVER, "fault=battery_failsafe", "fault.targets=[1]", "fault.onset_s=10",
                      "mission.max_sim_time_s=45")
    st = state(d, 1)
    assert "rtl" in set(st["mode"])
    stages = table(d, "drone_1", "stages")
    assert stages["name"].iloc[-1] == "ABORT" and "battery" in stages["reason"].iloc[-1]
    last = st.iloc[-1]
    assert last["landed"] and not last["armed"]
    assert math.hypot(last["true_n"] - 5.0, last["true_e"]) < 1.0
    ev = table(d, "drone_1", "events")
    assert ((ev["kind"] == "failsafe") & (ev["name"] == "battery_low")).sum() == 1
    for other in (0, 2, 3):
        assert (table(d, f"drone_{other}", "events")["name"] == "exec_complete").any()


# -- clocks -------------------------------------------------------------------------------------
def test_clock_skew_offsets_and_drifts_one_node(run):
    manifest, d = run(*HOVER, "fault=clock_skew", "fault.offset_s=0.5", "fault.drift_ppm=1000",
                      "fault.targets=[1]", *WINDOW)
    assert manifest["status"] == "ok", manifest["reason"]
    st = state(d, 1)
    err = st["t_s"] - st["tick"] * 0.025
    assert np.abs(err[st["t_s"] < ONSET]).max() < 1e-9
    skewed = st[(st["tick"] >= 400) & (st["tick"] < 1200)]
    true_t = skewed["tick"].to_numpy() * 0.025
    assert err[skewed.index].iloc[0] == pytest.approx(0.5, abs=1e-9)
    assert slope(true_t, err[skewed.index].to_numpy()) == pytest.approx(1e-3, rel=1e-6)
    assert np.abs(err[st["tick"] >= 1200]).max() < 1e-9           # resynchronised at the end
    sent = table(d, "drone_1", "messages").query("kind == 'send' and tick >= 400 and tick < 1200")
    assert np.allclose(sent["t_sent_s"], sent["t_s"])             # messages carry the skewed clock
    other = state(d, 2)
    assert np.abs(other["t_s"] - other["tick"] * 0.025).max() < 1e-9
    info = fault_events(d)["info"].iloc[0]
    assert json.loads(json.dumps(info))["offset_s"] == 0.5


# -- determinism ----------------------------------------------------------------------------------
def _tables(run_dir):
    out = {}
    for node in ("ground", "net", "drone_1", "drone_2"):
        for name in ("messages", "state", "events"):
            path = run_dir / "logs" / node / f"{name}.parquet"
            if path.is_file():
                out[(node, name)] = pd.read_parquet(path)
    return out


def test_same_seed_same_drops_delays_and_trajectories(run):
    faults = ("algo=hover", "mission=hover", "algo.params.hover_s=10",
              "fault=[latency,packet_loss,gps_noise]", "fault.targets=[1,2]", "fault.onset_s=5",
              "fault.jitter_ms=8", "fault.loss_prob=0.2", "fault.noise_scale=20")
    _, a = run(*faults, "seed=3")
    _, b = run(*faults, "seed=3")
    _, c = run(*faults, "seed=4")
    ta, tb, tc = _tables(a), _tables(b), _tables(c)
    assert ("net", "messages") in ta
    for key in ta:
        pd.testing.assert_frame_equal(ta[key], tb[key], obj=str(key))
    drops = [t[("net", "messages")]["msg_id"].tolist() for t in (ta, tc)]
    assert drops[0] != drops[1]
    assert not ta[("drone_1", "state")]["true_n"].equals(tc[("drone_1", "state")]["true_n"])
