"""Detection benchmark over many runs: detection rate, false alarms per drone-hour, localization and
t_f per fault and magnitude, for the swarm-level analyzer and for the per-drone baseline.

:func:`evaluate_run` diagnoses one run under several detector settings (the analyzer never sees the
fault events) and grades each with :mod:`.scoring`; the other functions are pure reductions of the
resulting rows (one per run, detector and setting). Everything is deterministic: same runs, same
tables.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from pathlib import Path

import numpy as np
import pandas as pd

from swarmbox.analysis import benchstats, network, sampling, scoring
from swarmbox.analysis import diagnosis as dg
from swarmbox.analysis.load import load_run
from swarmbox.analysis.unify import T, unify

#: The parameter that is each fault model's magnitude.
MAGNITUDE = {"gps_drift": "rate_m_s", "gps_bias": "bias_ned_m", "gps_noise": "noise_scale",
             "latency": "latency_ms", "packet_loss": "loss_prob", "burst_loss": "p_enter_burst"}
SETTING = ["detector", "rule", "threshold_scale", "persist_s"]


def magnitude(truth: scoring.Truth | None) -> float:
    """The fault's magnitude as one number (a vector parameter: its Euclidean norm); NaN when healthy."""
    if truth is None or truth.name not in MAGNITUDE:
        return np.nan
    value = truth.params.get(MAGNITUDE[truth.name])
    if isinstance(value, list | tuple):
        return float(np.linalg.norm(np.asarray(value, dtype="float64")))
    return float(value) if value is not None else np.nan


def baseline_alarms(resets: pd.DataFrame, series: dg.Series, opts: dg.DiagnosisOptions) -> pd.DataFrame:
    """Estimator resets as alarms, each with the drone's largest discrepancy component at that tick
    and its cross-swarm score (excess over the fence in IQRs, 0 inside): the same ruler as the analyzer's."""
    rows = []
    ticks = dg.nearest_tick(resets[T], series.step_s) if len(resets) else np.array([], dtype="int64")
    for (t_u, drone), tick in zip(zip(resets[T], resets["drone"], strict=True), ticks, strict=True):
        i = int(np.searchsorted(series.ticks, tick))
        j = series.drones.index(int(drone))
        best = None
        for metric in dg.DISC:
            mat = series.values[metric]
            if i >= len(mat) or not np.isfinite(mat[i, j]):
                continue
            scores, med, iqr = dg.outlier_matrix(mat[i:i + 1], 0.0, opts.rule, opts.min_n)
            dev = abs(mat[i, j] - med[0])
            if best is None or dev > best[0]:
                score = float(np.nan_to_num(scores[0, j], nan=0.0, posinf=np.inf))
                best = (dev, metric, float(mat[i, j]), score, float(med[0]), float(iqr[0]))
        _, metric, value, score, med, iqr = best or (0.0, "estimator_reset", np.nan, np.nan, np.nan, np.nan)
        rows.append({T: float(t_u), "metric": metric, "drone": int(drone), "value": value, "score": score,
                     "median": med, "iqr": iqr, "end_u": float(t_u)})
    return pd.DataFrame(rows, columns=dg.ALARM_COLUMNS)


def truth_fields(truth: scoring.Truth | None, index: int, run, flow=None) -> dict:
    """The columns that say which injected fault a row is scored against."""
    row = {"truth": index, "fault": truth.name if truth else "none", "magnitude": magnitude(truth),
           "target": truth.target if truth else None, "onset_u": truth.onset_u if truth else np.nan}
    if flow is not None and truth is not None and truth.name in ("latency", "packet_loss", "burst_loss"):
        row["measured"] = scoring.measured_excess(flow, run.drones, truth)
    return row


def evaluate_run(run_dir: str | Path, settings: Sequence[dg.DiagnosisOptions],
                 grace_s: float = scoring.GRACE_S) -> pd.DataFrame:
    """One row per detector setting (and for the estimator baseline) and injected truth of one run:
    every fault is scored (composed faults, every target), a fault on every drone once, as swarm-wide
    (:func:`.scoring.scored_truths`)."""
    run = load_run(run_dir)
    unify(run)
    span = dg.scan_span(run, settings[0].stage)
    series = dg.drone_series(run, settings[0], span)
    truths = scoring.scored_truths(scoring.ground_truth(run.tables["events"]), list(run.drones))
    n = len(run.drones)
    base = {"run": str(run_dir), "seed": run.manifest.get("seed"), "n_drones": n,
            "network": run.manifest.get("choices", {}).get("network"), "scan_s": span[1] - span[0]}
    network_truths = any(t.name in ("latency", "packet_loss", "burst_loss") for t in truths)
    flow = (network.message_flow(run.tables["messages"], max_latency_s=sampling.max_latency_s(run))
            if network_truths else None)
    per_truth = [truth_fields(t, i, run, flow) for i, t in enumerate(truths)] or [truth_fields(None, 0, run)]
    rows = []
    for opts in settings:
        alarms = dg.scan(series, opts)
        first = dg.finding(alarms)
        setting = {"detector": "swarmbox", "rule": opts.rule, "threshold_scale": opts.threshold_scale,
                   "persist_s": opts.persist_s, "alarms": len(alarms),
                   "first_alarm_drone": first.get("drone"), "first_alarm_metric": first.get("metric")}
        grades = scoring.score_truths(alarms, truths, span, n, grace_s)
        rows += [{**base, **t, **setting, **g} for t, g in zip(per_truth, grades, strict=True)]
    resets = baseline_alarms(dg.estimator_alarms(run, span), series, settings[0])
    setting = {"detector": "baseline", "rule": "estimator_reset", "threshold_scale": 1.0, "persist_s": 0.0,
               "alarms": len(resets),
               "first_alarm_drone": int(resets["drone"].iloc[0]) if len(resets) else None,
               "first_alarm_metric": "estimator_reset" if len(resets) else None}
    grades = scoring.score_truths(resets, truths, span, n, grace_s)
    rows += [{**base, **t, **setting, **g} for t, g in zip(per_truth, grades, strict=True)]
    return pd.DataFrame(rows)


def false_alarm_rates(rows: pd.DataFrame, by: Sequence[str] = ("n_drones", "network"),
                      healthy_runs_only: bool = False) -> pd.DataFrame:
    """False alarms per drone-hour of healthy time, per detector setting and ``by`` group."""
    data = rows[rows["fault"] == "none"] if healthy_runs_only else rows
    keys = [*SETTING, *by]
    g = data.groupby(keys, dropna=False)
    out = g.agg(false_alarms=("false_alarms", "sum"), healthy_drone_h=("healthy_drone_h", "sum"),
                runs=("run", "nunique")).reset_index()   # a run with two truths is one run
    out["fa_per_drone_h"] = out["false_alarms"] / out["healthy_drone_h"].where(out["healthy_drone_h"] > 0)
    return out


def detection_rates(rows: pd.DataFrame, by: Sequence[str] = ("n_drones", "network")) -> pd.DataFrame:
    """Per setting, group, fault and magnitude: runs, detection and localization rates, t_f quantiles,
    mean tau_d and Sigma_a over the detected runs."""
    data = rows[rows["fault"] != "none"]
    keys = [*SETTING, *by, "fault", "magnitude"]
    out = []
    for key, g in data.groupby(keys, dropna=False, sort=True):
        hit = g[g["detected"].astype(bool)]
        tf = hit["t_f_s"].to_numpy(dtype="float64")
        sig = hit["sigma_a"].to_numpy(dtype="float64")
        out.append({**dict(zip(keys, key, strict=True)), "runs": len(g), "detected": len(hit),
                    "detection_rate": len(hit) / len(g),
                    "localization": float(g["localized"].astype(bool).mean()),
                    "t_f_median_s": float(np.median(tf)) if tf.size else np.nan,
                    "t_f_p90_s": float(np.quantile(tf, 0.9)) if tf.size else np.nan,
                    "tau_d_mean": float(hit["tau_d"].mean()) if len(hit) else np.nan,
                    "sigma_a_median": float(np.median(sig)) if sig.size else np.nan})
    return pd.DataFrame(out)


def smallest_detected(det: pd.DataFrame, fa: pd.DataFrame, min_rate: float = 0.9, max_fa: float = 1.0,
                      by: Sequence[str] = ("n_drones", "network")) -> pd.DataFrame:
    """Per fault and group: the most sensitive setting whose false-alarm rate is <= ``max_fa`` per
    drone-hour, and the smallest magnitude it detects in >= ``min_rate`` of the runs (NaN: none)."""
    keys = [*SETTING, *by]
    ok = fa[fa["fa_per_drone_h"].fillna(np.inf) <= max_fa]
    merged = det.merge(ok[[*keys, "fa_per_drone_h", "healthy_drone_h"]], on=keys, how="inner")
    out = []
    for key, g in merged.groupby(["detector", *by, "fault"], sort=True):
        best = None
        for _, s in g.groupby(["rule", "threshold_scale", "persist_s"], sort=True):
            good = s[s["detection_rate"] >= min_rate].sort_values("magnitude")
            mag = float(good["magnitude"].iloc[0]) if len(good) else np.inf
            cand = (mag, -s["detection_rate"].mean(), s.iloc[0]["threshold_scale"], s, good)
            if best is None or cand[:3] < best[:3]:
                best = cand
        mag, _, _, s, good = best
        first = good.iloc[0] if len(good) else s.iloc[0]
        out.append({**dict(zip(["detector", *by, "fault"], key, strict=True)), "rule": first["rule"],
                    "threshold_scale": first["threshold_scale"], "fa_per_drone_h": first["fa_per_drone_h"],
                    "healthy_drone_h": first["healthy_drone_h"],
                    "smallest_magnitude": mag if np.isfinite(mag) else np.nan,
                    "detection_rate": first["detection_rate"] if len(good) else np.nan,
                    "localization": first["localization"] if len(good) else np.nan,
                    "t_f_median_s": first["t_f_median_s"] if len(good) else np.nan,
                    "runs_per_magnitude": int(s["runs"].min())})
    return pd.DataFrame(out)


def split_by_seed(rows: pd.DataFrame, calibration_seeds: Iterable[int]) -> tuple[pd.DataFrame, pd.DataFrame]:
    """(calibration rows, held-out rows): a run belongs to one side by its seed."""
    calib = rows["seed"].isin(set(calibration_seeds))
    return rows[calib], rows[~calib]


def held_out_smallest(rows: pd.DataFrame, calibration_seeds: Iterable[int], min_rate: float = 0.9,
                      max_fa: float = 1.0, by: Sequence[str] = ("n_drones", "network"),
                      level: float = benchstats.LEVEL) -> pd.DataFrame:
    """Per detector, group and fault: the setting chosen on the calibration seeds (most sensitive with
    <= ``max_fa`` false alarms per drone-hour there, as :func:`.smallest_detected`), and
    on the held-out seeds, with that setting: the smallest magnitude detected in >= ``min_rate`` of
    the runs, its detected/runs with the exact interval, and the false-alarm count, drone-hours and
    exact rate interval."""
    calib, test = split_by_seed(rows, calibration_seeds)
    if calib.empty or test.empty:
        raise ValueError("both the calibration and the held-out seeds need runs")
    chosen = smallest_detected(detection_rates(calib, by),
                                         false_alarm_rates(calib, by), min_rate, max_fa, by)
    det = benchstats.with_detection_ci(detection_rates(test, by), level)
    fa = benchstats.with_false_alarm_ci(false_alarm_rates(test, by), level)
    setting = [c for c in SETTING if c != "detector"]
    out = []
    for _, c in chosen.iterrows():
        key = {k: c[k] for k in ("detector", *by)}
        match = {**key, **{k: _setting_of(calib, c, k) for k in setting}}
        d = det[_rows_matching(det, {**match, "fault": c["fault"]})].sort_values("magnitude")
        f = fa[_rows_matching(fa, match)]
        good = d[d["detection_rate"] >= min_rate]
        hit = good.iloc[0] if len(good) else None
        out.append({**key, "fault": c["fault"], **{k: match[k] for k in setting},
                    "calibration_magnitude": c["smallest_magnitude"],
                    "smallest_magnitude": hit["magnitude"] if hit is not None else np.nan,
                    "detected": f"{int(hit['detected'])}/{int(hit['runs'])}" if hit is not None else "",
                    "detection_ci_low": hit["detection_ci_low"] if hit is not None else np.nan,
                    "detection_ci_high": hit["detection_ci_high"] if hit is not None else np.nan,
                    "false_alarms": int(f["false_alarms"].sum()),
                    "healthy_drone_h": float(f["healthy_drone_h"].sum()),
                    "fa_ci_high": float(f["fa_ci_high"].iloc[0]) if len(f) == 1 else np.nan})
    return pd.DataFrame(out)


def _setting_of(calib: pd.DataFrame, chosen: pd.Series, column: str):
    """The chosen setting's value of ``column`` (``smallest_detected`` keeps rule and scale only)."""
    if column in chosen.index:
        return chosen[column]
    same = calib[(calib["detector"] == chosen["detector"]) & (calib["rule"] == chosen["rule"])
                 & (calib["threshold_scale"] == chosen["threshold_scale"])]
    values = same[column].unique()
    if len(values) != 1:
        raise ValueError(f"setting column {column} is ambiguous for {chosen['rule']} "
                         f"x{chosen['threshold_scale']}")
    return values[0]


def _rows_matching(frame: pd.DataFrame, values: dict) -> pd.Series:
    mask = pd.Series(True, index=frame.index)
    for k, v in values.items():
        mask &= frame[k] == v
    return mask


def roc(rows: pd.DataFrame, by: Sequence[str] = ("fault", "magnitude")) -> pd.DataFrame:
    """Detection rate against false alarms per drone-hour over the threshold settings, per ``by``."""
    fa = false_alarm_rates(rows, by=())
    det = detection_rates(rows, by=())
    det = det.groupby([*SETTING, *by], dropna=False).agg(runs=("runs", "sum"), detected=("detected", "sum"))
    det = det.reset_index()
    det["detection_rate"] = det["detected"] / det["runs"]
    return det.merge(fa[[*SETTING, "fa_per_drone_h"]], on=SETTING, how="left")


def default_settings() -> list[dg.DiagnosisOptions]:
    """The default detector, its threshold swept for ROC curves, and the paper's 2.5 x IQR rule."""
    return [*(dg.DiagnosisOptions(threshold_scale=s) for s in (0.25, 0.5, 0.75, 1.0, 1.5, 2.0, 3.0)),
            dg.DiagnosisOptions(rule="paper")]


def evaluate_sweep(roots: Sequence[Path], settings: Sequence[dg.DiagnosisOptions] | None = None,
                   n_jobs: int = 1) -> pd.DataFrame:
    """:func:`evaluate_run` over every run below ``roots`` (runs that cannot be scanned are skipped)."""
    from joblib import Parallel, delayed

    from swarmbox.analysis.load import find_runs

    settings = list(settings or default_settings())
    dirs = [d for root in roots for d in find_runs(root)]
    parts = Parallel(n_jobs=n_jobs)(delayed(_evaluate_or_skip)(d, settings) for d in dirs)
    parts = [p for p in parts if len(p)]
    return pd.concat(parts, ignore_index=True) if parts else pd.DataFrame()


def _evaluate_or_skip(run_dir: Path, settings: list[dg.DiagnosisOptions]) -> pd.DataFrame:
    try:
        return evaluate_run(run_dir, settings)
    except ValueError as exc:   # no EXECUTION stage: nothing to scan
        import logging

        logging.getLogger(__name__).warning("%s", exc)
        return pd.DataFrame()


def write_report(rows: pd.DataFrame, out: Path) -> list[Path]:
    """Rows, detection rates, false-alarm rates and the smallest detected magnitudes (CSV + Markdown),
    and the detection-rate and ROC figures."""
    from swarmbox.analysis import diagnosis_plots, figures
    from swarmbox.analysis.tables import write_table

    fa = false_alarm_rates(rows)
    written = write_table(rows, out, "diagnosis_runs", markdown=False)
    written += write_table(benchstats.with_false_alarm_ci(fa), out, "false_alarms")
    if (rows["fault"] != "none").any():
        det = detection_rates(rows)
        written += write_table(benchstats.with_detection_ci(det), out, "detection_rates")
        # in-sample: the setting is chosen on the runs it is reported on (held_out_smallest splits by
        # seed when there are seeds to spare)
        written += write_table(smallest_detected(det, fa), out, "smallest_detected")
        chosen = (det["threshold_scale"] == 1.0) | (det["detector"] == "baseline")
        default = det[(det["rule"] != "paper") & chosen]
        written += figures.save(diagnosis_plots.detection_curves(default), out, "detection_rate")
        written += figures.save(diagnosis_plots.roc_curves(roc(rows)), out, "roc")
    return written


def main(argv: list[str] | None = None) -> int:
    import argparse
    import sys

    p = argparse.ArgumentParser(prog="python -m swarmbox.analysis.detection",
                                description="Onset-agnostic diagnosis of every run below the given "
                                            "directories, scored against any injected faults.")
    p.add_argument("paths", nargs="+", type=Path, help="sweep or run directories (searched recursively)")
    p.add_argument("--out", type=Path, help="output directory (default: <first path>/diagnosis)")
    p.add_argument("--jobs", type=int, default=2, help="parallel analysis jobs (2)")
    args = p.parse_args(argv)
    import matplotlib

    matplotlib.use("Agg")
    rows = evaluate_sweep(args.paths, n_jobs=args.jobs)
    if rows.empty:
        print("error: no run with an EXECUTION stage found", file=sys.stderr)
        return 2
    out = args.out or args.paths[0] / "diagnosis"
    written = write_report(rows, out)
    print(f"{rows['run'].nunique()} runs, {len(written)} files written under {out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
