"""The diagnosis benchmark's tables, from the per-run diagnosis rows of ``sweep.py bench``.

Every row carries its plan ``part`` (single, healthy, composed, swarm, single36, healthy36) and
``split`` (calibration or report). Everything reported here is measured on the report seeds only:
seeds that chose no threshold, neither the defaults (settled on an earlier benchmark's seeds) nor
the per-cell tuned settings (chosen on the calibration seeds). Every count carries its exact 95 %
interval: Clopper–Pearson on detections, Poisson on false alarms per drone-hour.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from swarmbox.analysis import benchstats, detection

UNITS = {"gps_drift": "m/s", "gps_bias": "m", "gps_noise": "x sigma", "latency": "ms", "packet_loss": "ratio",
         "burst_loss": "p_enter"}
SINGLE = ("single", "single36", "healthy", "healthy36")


def is_default(rows: pd.DataFrame) -> pd.Series:
    """The default detector's rows (Tukey, thresholds x 1) and the per-drone baseline's."""
    sb = (rows["detector"] == "swarmbox") & (rows["rule"] == "tukey") & (rows["threshold_scale"] == 1.0)
    return sb | (rows["detector"] == "baseline")


def reported(rows: pd.DataFrame) -> pd.DataFrame:
    """The report seeds' rows."""
    return rows[rows["split"] == "report"]


def count_ci(k: int, n: int) -> str:
    """``k/n [low %, high %]``: a count with its exact 95 % interval."""
    low, high = benchstats.binomial_ci(int(k), int(n))
    return f"{int(k)}/{int(n)} [{100 * low:.0f} %, {100 * high:.0f} %]"


def _median(values: pd.Series) -> str:
    v = values.dropna().to_numpy(dtype="float64")
    return f"{np.median(v):.2f}" if v.size else "–"


def magnitude_label(fault: str, value: float) -> str:
    return f"{value:g} {UNITS.get(fault, '')}".strip()


def _cell_columns(rows: pd.DataFrame) -> list[tuple[int, str]]:
    return sorted({(int(n), str(net)) for n, net in zip(rows["n_drones"], rows["network"], strict=True)})


def detection_table(rows: pd.DataFrame, detector: str = "swarmbox") -> pd.DataFrame:
    """Single faults, default setting, report seeds: per fault and magnitude (rows) and swarm size and
    network (columns), ``detected/runs [95 % interval]`` and the median t_f over the detected runs."""
    data = reported(rows)
    data = data[is_default(data) & data["part"].isin(SINGLE) & (data["fault"] != "none")
                & (data["detector"] == detector)]
    cells = _cell_columns(data)
    out = []
    for (fault, mag), g in data.groupby(["fault", "magnitude"], sort=True):
        row = {"fault": fault, "magnitude": magnitude_label(fault, mag)}
        for n, net in cells:
            c = g[(g["n_drones"] == n) & (g["network"] == net)]
            hit = c[c["detected"].astype(bool)]
            row[f"{n} drones, {net}: detected"] = count_ci(len(hit), len(c)) if len(c) else ""
            row[f"{n} drones, {net}: t_f (s)"] = _median(hit["t_f_s"]) if len(c) else ""
        out.append(row)
    return pd.DataFrame(out)


def false_alarm_table(rows: pd.DataFrame) -> pd.DataFrame:
    """Report seeds, every run's healthy flight (healthy runs, and every faulty run outside its fault
    window + 10 s): false alarms, drone-hours and the rate's exact 95 % upper bound, per detector
    setting, swarm size and network."""
    fa = detection.false_alarm_rates(reported(rows))
    fa = benchstats.with_false_alarm_ci(fa)
    fa = fa.assign(healthy_drone_h=fa["healthy_drone_h"].round(2), fa_ci_high=fa["fa_ci_high"].round(3))
    cols = ["n_drones", "network", "detector", "rule", "threshold_scale", "runs", "false_alarms",
            "healthy_drone_h", "fa_ci_high"]
    return fa[cols].sort_values(["n_drones", "network", "detector", "rule", "threshold_scale"]).reset_index(
        drop=True)


def false_alarm_summary(rows: pd.DataFrame) -> pd.DataFrame:
    """:func:`false_alarm_table` for the default detector, the paper's rule and the baseline only."""
    fa = false_alarm_table(rows)
    keep = (fa["detector"] == "baseline") | (fa["rule"] == "paper") | (fa["threshold_scale"] == 1.0)
    return fa[keep].reset_index(drop=True)


def composed_table(rows: pd.DataFrame) -> pd.DataFrame:
    """Two faults in one run, default detector, report seeds: each injected truth scored on its own."""
    data = reported(rows)
    data = data[is_default(data) & (data["part"] == "composed") & (data["detector"] == "swarmbox")]
    out = []
    for (combo, net, _), g in data.groupby([_combo(data), "network", "truth"], sort=True):
        hit = g[g["detected"].astype(bool)]
        fault = str(g["fault"].iloc[0])
        both = _both_detected(data[(_combo(data) == combo) & (data["network"] == net)])
        truth = f"{fault} {magnitude_label(fault, g['magnitude'].iloc[0])}"
        out.append({"faults": combo, "network": net, "truth": truth,
                    "detected": count_ci(len(hit), len(g)),
                    "first alarm on target": count_ci(g["localized"].astype(bool).sum(), len(g)),
                    "t_f median (s)": _median(hit["t_f_s"]), "both truths detected": both})
    return pd.DataFrame(out)


def _combo(data: pd.DataFrame) -> pd.Series:
    return data["run"].str.split("/").str[3]


def _both_detected(g: pd.DataFrame) -> str:
    per_run = g.groupby("run")["detected"].agg(lambda d: bool(d.astype(bool).all()))
    return count_ci(int(per_run.sum()), len(per_run))


def swarm_table(rows: pd.DataFrame) -> pd.DataFrame:
    """Faults on every drone (or on the ground), default detector, report seeds: one swarm-wide truth
    per run, detected by an alarm on any drone while the fault is on."""
    data = reported(rows)
    data = data[is_default(data) & (data["part"] == "swarm") & (data["detector"] == "swarmbox")]
    out = []
    for (kind, net), g in data.groupby([_combo(data), "network"], sort=True):
        hit = g[g["detected"].astype(bool)]
        fault = str(g["fault"].iloc[0])
        out.append({"fault": kind, "injected": f"{fault} {magnitude_label(fault, g['magnitude'].iloc[0])}",
                    "network": net, "detected (alarm on any drone)": count_ci(len(hit), len(g)),
                    "t_f median (s)": _median(hit["t_f_s"])})
    return pd.DataFrame(out)


def runs_table(rows: pd.DataFrame) -> pd.DataFrame:
    """How many runs each part of the plan flew, per split, and how they ended."""
    runs = rows.drop_duplicates("run")
    out = []
    for (part, split), g in runs.groupby(["part", "split"], sort=True):
        status = g["status"].value_counts()
        out.append({"part": part, "split": split, "runs": len(g), "ok": int(status.get("ok", 0)),
                    "aborted": int(status.get("aborted", 0)), "failed": int(status.get("failed", 0)),
                    "seeds": f"{int(g['seed'].min())}–{int(g['seed'].max())}"})
    return pd.DataFrame(out)


def held_out_table(rows: pd.DataFrame, calibration_seeds: set[int]) -> pd.DataFrame:
    """Single faults with 9 drones: the setting chosen per cell on the calibration seeds (the most
    sensitive with <= 1 false alarm per drone-hour there and a magnitude detected in >= 90 % of the
    calibration runs), then measured on the report seeds."""
    data = rows[rows["part"].isin(("single", "healthy"))]
    if not set(reported(data)["seed"]).isdisjoint(calibration_seeds):
        raise ValueError("a report seed is also a calibration seed: the held-out table would be in-sample")
    out = detection.held_out_smallest(data, calibration_seeds)
    out = out[out["detector"] == "swarmbox"].copy()
    for col in ("calibration_magnitude", "smallest_magnitude"):
        out[col] = [magnitude_label(f, m) if np.isfinite(m) else "none of the swept"
                    for m, f in zip(out[col], out["fault"], strict=True)]
    for col in ("detection_ci_low", "detection_ci_high", "healthy_drone_h", "fa_ci_high"):
        out[col] = out[col].astype(float).round(3)
    cols = ["fault", "network", "threshold_scale", "calibration_magnitude", "smallest_magnitude", "detected",
            "detection_ci_low", "false_alarms", "healthy_drone_h", "fa_ci_high"]
    return out.sort_values(["fault", "network"])[cols].reset_index(drop=True)
