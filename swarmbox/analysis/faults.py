"""Fault diagnosis against injected ground truth: paper RQ3 (section 5.3, Tables 2, 4 and 5).

For a run with an injected fault (onset, target and parameters from its ``fault`` event), the
analyzer's cross-swarm outlier test (:mod:`swarmbox.analysis.anomaly`, Tukey fences over *all*
drones, k = 1.5, minimum deviations 1.5 m / 1 ms / 5 %) runs on the fault's diagnostic metric:

- GNSS faults: position discrepancy (GNSS - estimate, N/E/D) per drone and tick;
- latency: mean latency of the messages to or from each drone, per tick, binned by *receive* time
  (a latency is known only once the message has arrived);
- loss: loss ratio of the messages to or from each drone per 2.5 s (100 ticks, the reference's
  loss window), binned by send time.

Windows are aligned to the onset (the first window starts at the onset) and stamped at their end;
only detections while the fault is on (onset to onset + duration) count. Per run and detector:
``t_f_s`` = first flagged window end - onset; ``tau_d`` = the flagged value;
``sigma_a`` = its score (distance beyond the fence in IQRs; inf when IQR = 0); ``drone`` = the flagged
drone; ``is_target``. ``measured`` = the fault's magnitude as recovered over the whole fault window:
the target's mean latency (loss ratio) minus the median of the other drones'.

Baseline (GNSS faults): the per-drone estimator detector — the target's first estimator position
reset (``events`` kind ``estimator``, name ``position_reset``, the ``reset_count_pos_ne`` of PX4's EKF2)
after the onset. Its ``tau_d``/``sigma_a`` are the target's discrepancy and its cross-swarm score at
the reset's tick (the state row of that tick is the last one before the reset), i.e. the error the
swarm had let grow before the single-drone detector fired, on the same ruler as SwarmBox's.

``python -m swarmbox.analysis.faults SWEEP_DIR [...]`` writes ``rq3_runs`` and the paper's tables
(``rq3_table2``, ``rq3_table4``, ``rq3_table5``, CSV + Markdown) and the timeline figures; the Hydra
callback :class:`DiagnoseSweepCallback` does the same into ``<sweep>/rq3/`` when a multirun ends.
"""

from __future__ import annotations

import argparse
import json
import logging
import sys
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from swarmbox.analysis import anomaly, metrics, network
from swarmbox.analysis.load import load_run
from swarmbox.analysis.tables import write_table
from swarmbox.analysis.timeline import discrepancy_timeline, network_timeline
from swarmbox.analysis.unify import T, unify

log = logging.getLogger(__name__)

DISC = ("disc_n_m", "disc_e_m", "disc_d_m")
#: Diagnostic metrics and the parameter that is the fault's magnitude, per fault model.
FAMILIES: dict[str, tuple[tuple[str, ...], str]] = {
    "gps_drift": (DISC, "rate_m_s"), "gps_bias": (DISC, "bias_ned_m"), "gps_noise": (DISC, "noise_scale"),
    "latency": (("latency_ms",), "latency_ms"), "packet_loss": (("loss_ratio",), "loss_prob"),
    "burst_loss": (("loss_ratio",), "p_enter_burst"),
}
_EPS_S = 1e-6   # keeps samples stamped exactly on a window edge inside the window they start


@dataclass(frozen=True)
class DiagnosisOptions:
    disc_window_s: float = 0.025
    latency_window_s: float = 0.025
    loss_window_s: float = 2.5
    iqr_k: float = 1.5
    min_deviation: dict[str, float] = field(default_factory=dict)   # overrides per metric

    def tests(self) -> dict[str, anomaly.OutlierTest]:
        return anomaly.default_tests(self.iqr_k, self.min_deviation)


@dataclass
class RunDiagnosis:
    run_dir: Path
    fault: str
    onset: anomaly.FaultOnset
    params: dict
    timeline: pd.DataFrame     # diagnostic metrics per drone and window (t_u = window end)
    rows: pd.DataFrame         # one row per detector: swarmbox (and baseline for GNSS faults)


def _aligned(times: pd.Series, onset_u: float) -> pd.Series:
    return times - onset_u + _EPS_S


def _unaligned(frame: pd.DataFrame, onset_u: float) -> pd.DataFrame:
    return frame.assign(**{T: frame[T] + onset_u})


def fault_timeline(state: pd.DataFrame, flow: pd.DataFrame, drones: list[int], fault: str,
                   onset_u: float, opts: DiagnosisOptions) -> pd.DataFrame:
    """The fault's diagnostic metrics per drone and onset-aligned window (tidy: t_u, drone, metric, value)."""
    wanted = FAMILIES[fault][0]
    if wanted == DISC:
        disc = metrics.discrepancy(state)
        disc = disc.assign(**{T: _aligned(disc[T], onset_u)})
        frame = discrepancy_timeline(disc, drones, opts.disc_window_s)
    elif wanted == ("latency_ms",):
        got = flow[flow["delivered"]]
        frame = network_timeline(got.assign(t_send=_aligned(got["t_recv"], onset_u)), drones,
                                 opts.latency_window_s)
    else:
        frame = network_timeline(flow.assign(t_send=_aligned(flow["t_send"], onset_u)), drones,
                                 opts.loss_window_s)
    frame = frame[frame["metric"].isin(wanted)]
    return _unaligned(frame, onset_u).astype({"drone": "int64", "value": "float64"}).reset_index(drop=True)


def _swarmbox_row(flags: pd.DataFrame, onset: anomaly.FaultOnset) -> dict:
    diag = anomaly.diagnose(flags, onset)
    found = diag[diag["metric"] == "any"] if len(diag) else diag
    if found.empty:
        return {"detector": "swarmbox", "detected": False}
    row = found.iloc[0]
    return {"detector": "swarmbox", "detected": True, "t_f_s": row["t_f_s"], "tau_d": row["tau_d"],
            "sigma_a": row["sigma_a"], "drone": int(row["drone"]), "is_target": bool(row["is_target"]),
            "metric": row["detected_metric"]}


def _baseline_row(run_tables: dict[str, pd.DataFrame], onset: anomaly.FaultOnset, end_u: float, metric: str,
                  tests: dict[str, anomaly.OutlierTest]) -> dict:
    """The per-drone estimator detector: the target's first position reset while the fault is on."""
    ev = run_tables["events"]
    resets = ev[(ev["kind"] == "estimator") & (ev["name"] == "position_reset") & (ev["node"] == onset.target)
                & (ev[T] > onset.t_u) & (ev[T] <= end_u)].sort_values(T)
    if resets.empty:
        return {"detector": "baseline", "detected": False, "metric": metric}
    first = resets.iloc[0]
    disc = metrics.discrepancy(run_tables["state"])
    tick = disc[disc["tick"] == first["tick"]].sort_values("node")
    scores, _ = anomaly.outlier_scores(tick[metric].to_numpy(), tests[metric])
    mine = np.flatnonzero(tick["node"].to_numpy() == onset.target)
    value = float(tick[metric].iloc[mine[0]]) if len(mine) else np.nan
    score = float(scores[mine[0]]) if len(mine) else np.nan
    return {"detector": "baseline", "detected": True, "t_f_s": float(first[T] - onset.t_u), "tau_d": value,
            "sigma_a": score, "drone": int(first["node"]), "is_target": True, "metric": metric}


def _measured(flow: pd.DataFrame, drones: list[int], onset: anomaly.FaultOnset, end_u: float,
              fault: str) -> float:
    """Target's latency (ms) or loss ratio over the fault window minus the median of the others'."""
    if fault not in ("latency", "packet_loss", "burst_loss"):
        return np.nan
    window = network.between(flow, onset.t_u, end_u)
    stats = network.agent_stats(window, end_u - onset.t_u).set_index("agent")
    col = "latency_ms_mean" if fault == "latency" else "loss_ratio"
    values = stats[col].reindex(drones)
    if onset.target not in values.index or pd.isna(values.get(onset.target)):
        return np.nan
    others = values.drop(onset.target).dropna()
    return float(values[onset.target] - (others.median() if len(others) else 0.0))


def _drift_metric(params: dict) -> str:
    direction = params.get("direction_ned") or params.get("bias_ned_m") or [1.0, 0.0, 0.0]
    return DISC[int(np.argmax(np.abs(np.asarray(direction, dtype=float))))]


def diagnose_run(run_dir: str | Path, opts: DiagnosisOptions | None = None) -> RunDiagnosis | None:
    """Diagnose one run's first injected fault; None when the run has no (known) fault event."""
    opts = opts or DiagnosisOptions()
    run = load_run(run_dir)
    unify(run)
    onset = anomaly.fault_onset(run.tables["events"])
    if onset is None or onset.target is None:
        return None
    fault = onset.name.removesuffix("_start")
    if fault not in FAMILIES:
        return None
    params = dict(onset.extra)
    flow = network.message_flow(run.tables["messages"])
    duration = params.get("duration_s")
    end_u = onset.t_u + float(duration) if duration else float(flow["t_send"].max())
    timeline = fault_timeline(run.tables["state"], flow, run.drones, fault, onset.t_u, opts)
    tests = opts.tests()
    flags = anomaly.detect(timeline, tests)
    rows = [_swarmbox_row(flags[flags[T] <= end_u + _EPS_S], onset)]
    if FAMILIES[fault][0] == DISC:
        metric = rows[0].get("metric") or _drift_metric(params)
        rows.append(_baseline_row(run.tables, onset, end_u, metric, tests))
    magnitude = params.get(FAMILIES[fault][1])
    base = {"run": str(run_dir), "status": run.status, "seed": run.manifest.get("seed"), "fault": fault,
            "magnitude": json.dumps(magnitude) if isinstance(magnitude, list) else magnitude,
            "target": onset.target, "onset_u": onset.t_u,
            "measured": _measured(flow, run.drones, onset, end_u, fault)}
    frame = pd.DataFrame([{**base, **r} for r in rows])
    return RunDiagnosis(Path(run_dir), fault, onset, params, timeline, frame)


def _diagnose_rows(run_dir: Path, opts: DiagnosisOptions) -> pd.DataFrame:
    diag = diagnose_run(run_dir, opts)
    return diag.rows if diag is not None else pd.DataFrame()


def diagnose_sweep(roots: list[Path], opts: DiagnosisOptions | None = None, n_jobs: int = 1) -> pd.DataFrame:
    """One row per run and detector over every run below ``roots`` (runs without a fault are skipped)."""
    from joblib import Parallel, delayed

    from swarmbox.analysis.load import find_runs

    opts = opts or DiagnosisOptions()
    dirs = [d for root in roots for d in find_runs(root)]
    parts = Parallel(n_jobs=n_jobs)(delayed(_diagnose_rows)(d, opts) for d in dirs)
    parts = [p for p in parts if len(p)]
    return pd.concat(parts, ignore_index=True) if parts else pd.DataFrame()


def _mean(values: pd.Series) -> float:
    v = values.to_numpy(dtype="float64")
    if v.size == 0:
        return np.nan
    return float(np.inf) if np.isinf(v).any() else float(v.mean())


def summarize(runs: pd.DataFrame) -> pd.DataFrame:
    """Per fault, magnitude and detector: runs, detections, target hits, and the means over the
    detected runs of t_f (s), tau_d, Sigma_a (inf if any run's is inf) and of the measured magnitude."""
    rows = []
    for (fault, magnitude, detector), g in runs.groupby(["fault", "magnitude", "detector"], sort=True):
        hit = g[g["detected"].astype(bool)]
        rows.append({"fault": fault, "magnitude": magnitude, "detector": detector, "runs": len(g),
                     "detected": len(hit), "on_target": int(hit["is_target"].astype(bool).sum()),
                     "t_f_s": _mean(hit["t_f_s"]), "tau_d": _mean(hit["tau_d"]),
                     "sigma_a": _mean(hit["sigma_a"]), "measured": _mean(g["measured"].dropna())})
    return pd.DataFrame(rows)


def _cell(row: pd.Series, key: str, scale: float = 1.0, digits: int = 2) -> str:
    if row["detected"] == 0:
        return "Not detected" if key == "t_f_s" else "N/A"
    value = row[key] * scale
    text = "∞" if np.isinf(value) else f"{value:.{digits}f}"
    return text if row["detected"] == row["runs"] else f"{text} ({row['detected']}/{row['runs']})"


def table2(summary: pd.DataFrame) -> pd.DataFrame:
    """Paper Table 2: GNSS drift, baseline vs SwarmBox."""
    drift = summary[summary["fault"] == "gps_drift"]
    out = []
    for magnitude, g in drift.groupby("magnitude", sort=True):
        by = {r["detector"]: r for _, r in g.iterrows()}
        b, s = by.get("baseline"), by.get("swarmbox")
        row = {"drift_m_s": magnitude}
        for key, name in (("t_f_s", "t_f (s)"), ("tau_d", "tau_d (m)"), ("sigma_a", "Sigma_a")):
            row[f"{name} baseline"] = _cell(b, key) if b is not None else ""
            row[f"{name} SwarmBox"] = _cell(s, key) if s is not None else ""
        row["SwarmBox on target"] = f"{s['on_target']}/{s['runs']}" if s is not None else ""
        out.append(row)
    return pd.DataFrame(out)


def _network_table(summary: pd.DataFrame, fault: str, label: str, scale: float) -> pd.DataFrame:
    part = summary[(summary["fault"] == fault) & (summary["detector"] == "swarmbox")].sort_values("magnitude")
    cols = {f"{m * scale:g}{label}": r for m, (_, r) in zip(part["magnitude"], part.iterrows(), strict=True)}
    unit, k = ("ms", 1.0) if fault == "latency" else ("%", 100.0)
    lines = {
        "t_f (ms)": lambda r: _cell(r, "t_f_s", 1e3),
        f"tau_d ({unit})": lambda r: _cell(r, "tau_d", k),
        "Sigma_a": lambda r: _cell(r, "sigma_a"),
        f"measured excess ({unit})": lambda r: f"{r['measured'] * k:.2f}",
        "faulty drone identified": lambda r: f"{r['on_target']}/{r['runs']}",
    }
    return pd.DataFrame([{"metric": name, **{c: fn(r) for c, r in cols.items()}}
                         for name, fn in lines.items()])


def table4(summary: pd.DataFrame) -> pd.DataFrame:
    """Paper Table 4: injected network delay."""
    return _network_table(summary, "latency", " ms", 1.0)


def table5(summary: pd.DataFrame) -> pd.DataFrame:
    """Paper Table 5: injected packet loss."""
    return _network_table(summary, "packet_loss", " %", 100.0)


def timeline_figure(diag: RunDiagnosis, *, before_s: float = 5.0, after_s: float = 20.0):
    """The diagnostic metric of every drone around the onset, with onset and detections marked."""
    from swarmbox.analysis import figures

    rows = diag.rows.set_index("detector")
    sb = rows.loc["swarmbox"] if "swarmbox" in rows.index else None
    metric = sb["metric"] if sb is not None and isinstance(sb.get("metric"), str) else \
        FAMILIES[diag.fault][0][0] if FAMILIES[diag.fault][0] != DISC else _drift_metric(diag.params)
    t0 = diag.onset.t_u
    frame = diag.timeline[(diag.timeline[T] >= t0 - before_s) & (diag.timeline[T] <= t0 + after_s)]
    detection = t0 + sb["t_f_s"] if sb is not None and sb["detected"] else None
    fig = figures.timeline(frame, metric=metric, onset=t0, detection=detection, target=diag.onset.target)
    ax = fig.axes[0]
    if "baseline" in rows.index and rows.loc["baseline", "detected"]:
        ax.axvline(t0 + rows.loc["baseline", "t_f_s"], color="grey", ls="-.",
                   label="baseline (estimator reset)")
        ax.legend(loc="best", fontsize="small")
    ax.set_title(f"{diag.fault} {diag.params.get(FAMILIES[diag.fault][1])} on drone {diag.onset.target}")
    return fig


def write_report(runs: pd.DataFrame, out: Path, figures_for: list[RunDiagnosis] = ()) -> list[Path]:
    """Write rq3_runs, rq3_summary and the paper's tables (CSV + Markdown) and timeline figures."""
    summary = summarize(runs)
    written = write_table(runs, out, "rq3_runs", markdown=False) + write_table(summary, out, "rq3_summary")
    for name, make in (("rq3_table2", table2), ("rq3_table4", table4), ("rq3_table5", table5)):
        table = make(summary)
        if len(table) and len(table.columns) > 1:
            written += write_table(table, out, name)
    from swarmbox.analysis import figures

    for diag in figures_for:
        written += figures.save(timeline_figure(diag), out / "figures", f"rq3_timeline_{diag.fault}")
    return written


def _representatives(runs: pd.DataFrame) -> list[Path]:
    """Per fault: the run of the median magnitude on the middle target (for the timeline figures)."""
    picks = []
    for _, g in runs[runs["detector"] == "swarmbox"].groupby("fault"):
        mags = sorted(g["magnitude"].unique(), key=str)
        targets = sorted(g["target"].unique())
        mid = g[(g["magnitude"] == mags[len(mags) // 2]) & (g["target"] == targets[len(targets) // 2])]
        picks.append(Path((mid if len(mid) else g).iloc[0]["run"]))
    return picks


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m swarmbox.analysis.faults",
                                description="RQ3 fault diagnosis tables over one or more sweep directories.")
    p.add_argument("paths", nargs="+", type=Path, help="sweep or run directories (searched recursively)")
    p.add_argument("--out", type=Path, help="output directory (default: <first path>/rq3)")
    p.add_argument("--jobs", type=int, default=2, help="parallel analysis jobs (2)")
    p.add_argument("--no-figures", action="store_true")
    args = p.parse_args(argv)
    import matplotlib

    matplotlib.use("Agg")
    runs = diagnose_sweep(args.paths, n_jobs=args.jobs)
    if runs.empty:
        print("error: no run with an injected fault found", file=sys.stderr)
        return 2
    out = args.out or args.paths[0] / "rq3"
    reps = [] if args.no_figures else [d for d in map(diagnose_run, _representatives(runs)) if d]
    written = write_report(runs, out, reps)
    from swarmbox.analysis.tables import to_markdown

    summary = summarize(runs)
    for name, make in (("Table 2", table2), ("Table 4", table4), ("Table 5", table5)):
        table = make(summary)
        if len(table) and len(table.columns) > 1:
            print(f"## {name}\n\n{to_markdown(table)}")
    print(f"{len(runs)} rows, {len(written)} files written under {out}")
    return 0


def _hydra_callback_base() -> type:
    from hydra.experimental.callback import Callback

    return Callback


class DiagnoseSweepCallback(_hydra_callback_base()):
    """Hydra callback: the fault-diagnosis tables and figures of a sweep, in ``<sweep>/rq3/``.

    ``group_by`` is accepted and ignored, so that this callback can take the place of the generic
    ``analyze`` callback of the root config. It never raises: a failure is logged.
    """

    def __init__(self, jobs: int = 2, figures: bool = True, group_by: Sequence[str] = ()) -> None:
        self.jobs, self.figures = jobs, figures

    def on_multirun_end(self, config: Any, **kwargs: Any) -> None:
        try:
            sweep = str(config.hydra.sweep.dir)
            main([sweep, "--jobs", str(self.jobs), *([] if self.figures else ["--no-figures"])])
        except Exception:  # noqa: BLE001 - an analysis failure must not fail the multirun
            log.exception("fault diagnosis of the sweep failed")


if __name__ == "__main__":
    sys.exit(main())
