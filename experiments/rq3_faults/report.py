"""Tables and figures of the RQ3 study and of the diagnosis benchmark, from the rows the sweep wrote.

    python experiments/rq3_faults/report.py rq3   results/rq3   --out experiments/rq3_faults/tables
    python experiments/rq3_faults/report.py bench results/bench --out experiments/rq3_faults/bench
    python experiments/rq3_faults/report.py bench experiments/rq3_faults/bench/bench_runs.csv \
        --out experiments/rq3_faults/bench       # again from the committed rows, no runs needed

The rows come from :func:`swarmbox.analysis.detection.evaluate_run`: the analyzer scanned every run
without the fault events, and the scoring columns were added afterwards from them. Paper Tables 2,
4 and 5 use the default detector (Tukey, k = 1.5, thresholds x 1) and, for Table 2, the per-drone
estimator-reset baseline.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
import pandas as pd

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
sys.path.insert(0, str(HERE.parents[1]))

import bench_tables as bt  # noqa: E402
from sweep import calibration_seeds, collect  # noqa: E402

from swarmbox.analysis import benchstats, detection  # noqa: E402
from swarmbox.analysis.tables import to_markdown, write_table  # noqa: E402

UNITS = bt.UNITS


def is_default_setting(rows: pd.DataFrame) -> pd.Series:
    """The default detector's rows and the baseline's."""
    sb = (rows["detector"] == "swarmbox") & (rows["rule"] == "tukey") & (rows["threshold_scale"] == 1.0)
    return sb | (rows["detector"] == "baseline")


def default_rows(rows: pd.DataFrame) -> pd.DataFrame:
    return rows[is_default_setting(rows)]


def _mean(values: pd.Series) -> float:
    v = values.dropna().to_numpy(dtype="float64")
    return float("nan") if v.size == 0 else float(np.inf) if np.isinf(v).any() else float(v.mean())


def summarize(rows: pd.DataFrame) -> pd.DataFrame:
    """Per fault, magnitude and detector: runs, target detected, first alarm on the target, means over
    the detected runs of t_f, tau_d and Sigma_a, and the mean measured excess."""
    out = []
    groups = default_rows(rows).groupby(["fault", "magnitude", "detector"], sort=True)
    for (fault, mag, detector), g in groups:
        hit = g[g["detected"].astype(bool)]
        out.append({"fault": fault, "magnitude": mag, "detector": detector, "runs": len(g),
                    "detected": len(hit),
                    "localized": int(g["localized"].astype(bool).sum()), "t_f_s": _mean(hit["t_f_s"]),
                    "tau_d": _mean(hit["tau_d"]), "sigma_a": _mean(hit["sigma_a"]),
                    "measured": _mean(g["measured"]) if "measured" in g else np.nan,
                    "false_alarms": int(g["false_alarms"].sum())})
    return pd.DataFrame(out)


def _cell(r: pd.Series | None, key: str, scale: float = 1.0) -> str:
    if r is None or r["detected"] == 0:
        return "not detected" if key == "t_f_s" else "N/A"
    v = r[key] * scale
    text = "∞" if np.isinf(v) else f"{v:.2f}"
    return text if r["detected"] == r["runs"] else f"{text} ({r['detected']}/{r['runs']})"


def count_ci(k: int, n: int) -> str:
    """``k/n [low, high]``: a count with its exact 95 % interval, in percent."""
    low, high = benchstats.binomial_ci(int(k), int(n))
    return f"{int(k)}/{int(n)} [{100 * low:.0f} %, {100 * high:.0f} %]"


def paper_values(path: Path = HERE / "tables" / "paper.csv") -> dict[tuple, str]:
    """The paper's Tables 2, 4 and 5 as printed (transcribed): (fault, magnitude, detector, quantity)
    -> text."""
    paper = pd.read_csv(path, dtype={"paper": str}, keep_default_na=False)
    return {(f, float(m), d, q): v for f, m, d, q, v in paper.itertuples(index=False)}


def _with_paper(now: str, paper: dict, key: tuple) -> str:
    return f"{now} / {paper[key]}" if key in paper else now


def table2(summary: pd.DataFrame, paper: dict | None = None) -> pd.DataFrame:
    """Paper Table 2 (GNSS drift): each cell ``now / paper``; detection and localization counts of
    the SwarmBox detector with their 95 % intervals."""
    paper = paper_values() if paper is None else paper
    out = []
    for mag, g in summary[summary["fault"] == "gps_drift"].groupby("magnitude", sort=True):
        by = {r["detector"]: r for _, r in g.iterrows()}
        b, s = by.get("baseline"), by.get("swarmbox")
        row = {"drift_m_s": f"{mag:g}"}
        for key, name, q in (("t_f_s", "t_f (s)", "t_f"), ("tau_d", "tau_d (m)", "tau_d"),
                             ("sigma_a", "Sigma_a", "sigma_a")):
            row[f"{name} baseline"] = _with_paper(_cell(b, key), paper, ("gps_drift", mag, "baseline", q))
            row[f"{name} SwarmBox"] = _with_paper(_cell(s, key), paper, ("gps_drift", mag, "swarmbox", q))
        row["detected (SwarmBox)"] = count_ci(s["detected"], s["runs"]) if s is not None else ""
        row["first alarm on target"] = count_ci(s["localized"], s["runs"]) if s is not None else ""
        out.append(row)
    return pd.DataFrame(out)


def network_table(summary: pd.DataFrame, fault: str, paper: dict | None = None) -> pd.DataFrame:
    """Paper Table 4 (latency) or 5 (loss): each cell ``now / paper``, the measured excess, and the
    detection and localization counts with their 95 % intervals."""
    paper = paper_values() if paper is None else paper
    part = summary[(summary["fault"] == fault) & (summary["detector"] == "swarmbox")].sort_values("magnitude")
    unit, k, label = ("ms", 1.0, " ms") if fault == "latency" else ("%", 100.0, " %")

    def now_paper(q: str, cell):
        return lambda r: _with_paper(cell(r), paper, (fault, float(r["magnitude"]), "swarmbox", q))

    lines = {"t_f (ms)": now_paper("t_f", lambda r: _cell(r, "t_f_s", 1e3)),
             f"tau_d ({unit})": now_paper("tau_d", lambda r: _cell(r, "tau_d", k)),
             "Sigma_a": now_paper("sigma_a", lambda r: _cell(r, "sigma_a")),
             f"measured excess ({unit})": lambda r: f"{r['measured'] * k:.2f}",
             "detected": lambda r: count_ci(r["detected"], r["runs"]),
             "first alarm on target": lambda r: count_ci(r["localized"], r["runs"])}
    return pd.DataFrame([{"metric": name, **{f"{r['magnitude'] * k:g}{label}": fn(r)
                                             for _, r in part.iterrows()}}
                         for name, fn in lines.items()])


def timeline_figures(root: Path, out: Path) -> list[Path]:
    """Per fault, the run of the middle magnitude on drone 4: what the analyzer saw, with the
    injected fault drawn as a separate ground-truth overlay."""
    from swarmbox.analysis import diagnosis as dg
    from swarmbox.analysis import diagnosis_plots, figures, scoring
    from swarmbox.analysis.load import load_run
    from swarmbox.analysis.unify import unify

    written = []
    for kind in ("drift", "latency", "loss"):
        run_dir = root / kind / "m2_t4"
        if not (run_dir / "run.json").exists():
            continue
        run = load_run(run_dir)
        unify(run)
        series = dg.drone_series(run)
        truth = scoring.ground_truth(run.tables["events"])[0]
        fig = diagnosis_plots.timeline(series, dg.scan(series), truth=truth)
        written += figures.save(fig, out / "figures", f"rq3_timeline_{truth.name}", formats=("png",))
    return written


def totals(rows: pd.DataFrame) -> pd.DataFrame:
    """Over every run, per detector (default setting): runs, detected and first alarm on the target
    with their 95 % intervals, false alarms over the healthy drone-hours and the rate's 95 % bound."""
    out = []
    for detector, g in default_rows(rows).groupby("detector", sort=False):
        hours = float(g["healthy_drone_h"].sum())
        alarms = int(g["false_alarms"].sum())
        out.append({"detector": detector, "runs": len(g),
                    "detected": count_ci(g["detected"].astype(bool).sum(), len(g)),
                    "first alarm on target": count_ci(g["localized"].astype(bool).sum(), len(g)),
                    "false alarms": alarms, "healthy drone-hours": f"{hours:.2f}",
                    "false alarms per drone-hour, 95 % upper bound":
                        f"{benchstats.poisson_rate_ci(alarms, hours)[1]:.2f}"})
    return pd.DataFrame(out)


def rq3_report(rows: pd.DataFrame, out: Path, root: Path) -> list[Path]:
    summary = summarize(rows)
    from_csv = root.suffix == ".csv"      # the committed rows: the input, not rewritten; no run dirs
    written = [] if from_csv else write_table(rows, out, "rq3_runs", markdown=False)
    written += write_table(summary, out, "rq3_summary")
    for name, table in (("rq3_totals", totals(rows)), ("rq3_table2", table2(summary)),
                        ("rq3_table4", network_table(summary, "latency")),
                        ("rq3_table5", network_table(summary, "packet_loss"))):
        written += write_table(table, out, name)
        print(f"## {name}\n\n{to_markdown(table)}")
    return written + ([] if from_csv else timeline_figures(root, out))


def bench_report(rows: pd.DataFrame, out: Path, root: Path) -> list[Path]:
    """Every table and figure of ``bench/`` (bench_tables.py): measured on the report seeds; the
    tuned settings chosen on the calibration seeds (``sweep.calibration_seeds``)."""
    from swarmbox.analysis import diagnosis_plots, figures

    # rows read back from a committed bench_runs.csv are its input: not rewritten
    written = [] if root.suffix == ".csv" else write_table(rows, out, "bench_runs", markdown=False)
    tables = bench_tables_of(rows)
    for name, table in tables.items():
        written += write_table(table, out, name)
    single = bt.reported(rows)
    single = single[single["part"].isin(bt.SINGLE)]
    det = benchstats.with_detection_ci(detection.detection_rates(single))
    written += write_table(det, out, "detection_rates")
    default = det[bt.is_default(det) & (det["rule"] != "paper")]
    written += figures.save(diagnosis_plots.detection_curves(default, units=bt.UNITS), out, "detection_rate",
                            formats=("png",))
    written += figures.save(diagnosis_plots.roc_curves(detection.roc(single)), out, "roc", formats=("png",))
    print(to_markdown(tables["detection_default"]))
    return written


def bench_tables_of(rows: pd.DataFrame) -> dict[str, pd.DataFrame]:
    """The benchmark's tables by name (each is written as ``<name>.csv`` and ``<name>.md``)."""
    return {"runs": bt.runs_table(rows), "detection_default": bt.detection_table(rows),
            "detection_baseline": bt.detection_table(rows, "baseline"),
            "false_alarms": bt.false_alarm_table(rows), "false_alarms_default": bt.false_alarm_summary(rows),
            "smallest_detected_heldout": bt.held_out_table(rows, calibration_seeds()),
            "composed": bt.composed_table(rows), "swarm_wide": bt.swarm_table(rows)}


def read_rows(source: Path) -> pd.DataFrame:
    """Diagnosis rows: every ``diagnosis.parquet`` below a sweep directory (:func:`sweep.collect`), or
    a committed ``bench_runs.csv`` / ``rq3_runs.csv``. Rows written before persistence was a duration
    (``persist_ticks`` of the 25 ms grid) get the ``persist_s`` the analyzer now uses."""
    rows = pd.read_csv(source) if source.suffix == ".csv" else collect(source)
    if rows.empty:
        return rows
    if "persist_s" in detection.SETTING and "persist_ticks" in rows and "persist_s" not in rows:
        ticks = rows.pop("persist_ticks")
        rows["persist_s"] = np.where(ticks > 1, ticks * 0.025, 0.0)
    return rows


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("which", choices=["rq3", "bench"])
    p.add_argument("root", type=Path, help="a sweep directory, or a committed *_runs.csv")
    p.add_argument("--out", type=Path, required=True)
    args = p.parse_args(argv)
    import matplotlib

    matplotlib.use("Agg")
    rows = read_rows(args.root)
    if rows.empty:
        print(f"error: no diagnosis rows in {args.root}", file=sys.stderr)
        return 2
    rows = rows.sort_values(["run", "detector", "rule", "threshold_scale"]).reset_index(drop=True)
    written = (rq3_report if args.which == "rq3" else bench_report)(rows, args.out, args.root)
    print(f"{rows['run'].nunique()} runs, {len(written)} files written under {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
