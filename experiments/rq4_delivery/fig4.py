"""Paper Fig. 4 and Table 6 from an analyzed RQ4 sweep.

    python -m experiments.rq4_delivery.fig4 SWEEP_DIR      # from the repository root

Reads the analyzer's ``SWEEP_DIR/tables/summary.csv`` (runs the sweep analysis first if it is
missing) and writes, beside the analyzer's own outputs:

- ``figures/fig4_heatmaps.{png,svg}``: one 3 x 3 grid per Table-6 metric (rows: assignment, columns:
  sorting rule), each coloured on its own range, darker = better, as the paper's Fig. 4;
- ``figures/fig4_delivery_time.{png,svg}``: every package's delivery wait pooled over the datasets,
  one box per (assignment, sort), as the paper's "Delivery Time" box plot;
- ``tables/rq4_table.{csv,md}``: per algorithm, the mean, 95 % bootstrap CI and rank (1 = best) of
  the eight Table-6 metrics, the mean delivered count and the mean rank;
- ``tables/rq4_package_waits.{csv,md}``: the pooled per-package waits per algorithm;
- with ``--publish``, the README's data in ``experiments/rq4_delivery/results/`` (:mod:`.publish`).

Per-package waits are read from the ground's ``delivered`` markers with the analyzer's own marker
metric (the ground clock is the analyzer's reference, so no clock correction applies).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import matplotlib
import numpy as np
import pandas as pd
import seaborn as sns
from matplotlib.figure import Figure

from experiments.rq4_delivery import publish
from swarmbox.analysis import analyze_sweep, find_runs
from swarmbox.analysis.figures import save
from swarmbox.analysis.load import GROUND, read_manifest, read_table
from swarmbox.analysis.metrics import exec_window
from swarmbox.analysis.mission import marker_values, parse_spec
from swarmbox.analysis.outputs import write_sweep
from swarmbox.analysis.tables import write_table
from swarmbox.analysis.unify import T

SORTS = {"none": "NS", "azimuth": "AZ", "distance": "DI"}
ASSIGNS = {"dynamic": "DYN", "rr": "RR", "block": "BLK"}   # the paper's row order
#: Table 6: analyzer metric -> (label, unit, scale for display).
TABLE6 = {
    "distance_h_m_mean": ("Total flight distance (per drone)", "m", 1.0),
    "mission_duration_s": ("Total mission duration", "s", 1.0),
    "idle_s_mean": ("Idle time", "s", 1.0),
    "utilization_mean": ("Utilization", "%", 100.0),
    "distance_h_m_std": ("Workload deviation: distance", "m", 1.0),
    "busy_s_std": ("Workload deviation: time", "s", 1.0),
    "delivery_wait_s_mean": ("Average delivery wait", "s", 1.0),
    "delivery_wait_s_max": ("Maximum delivery wait", "s", 1.0),
}
DELIVERED = "delivery_wait_s_count"
WAIT_SPEC = {"name": "delivery_wait_s", "marker": "delivered", "node": "ground",
             "measure": "since_exec_start"}


def split_algo(algo: str) -> tuple[str, str]:
    """``delivery_<sort>_<assign>`` -> (sort, assign)."""
    _, sort, assign = algo.split("_")
    return sort, assign


def grid(summary: pd.DataFrame, metric: str) -> pd.DataFrame:
    """Mean of ``metric`` as an assign x sort frame (paper order)."""
    rows = summary[summary["metric"] == metric]
    parts = pd.DataFrame([(*split_algo(a), m) for a, m in zip(rows["algo"], rows["mean"], strict=True)],
                         columns=["sort", "assign", "mean"])
    wide = parts.pivot(index="assign", columns="sort", values="mean")
    return wide.reindex(index=list(ASSIGNS), columns=list(SORTS))


def heatmaps(summary: pd.DataFrame, *, metrics: dict = TABLE6) -> Figure:
    """One annotated 3 x 3 heatmap per metric; darker = better on that metric's own range."""
    fig = Figure(figsize=(16, 7.5), layout="constrained")
    axes = fig.subplots(2, 4).ravel()
    directions = summary.drop_duplicates("metric").set_index("metric")["direction"]
    for ax, (metric, (label, unit, scale)) in zip(axes, metrics.items(), strict=False):
        values = grid(summary, metric) * scale
        cmap = "Greens" if directions.get(metric) == "higher" else "Greens_r"
        labels = values.map(lambda v, unit=unit: f"{v:.1f} {unit}")
        sns.heatmap(values.astype("float64"), ax=ax, cmap=cmap, annot=labels, fmt="", cbar=False,
                    linewidths=0.5, xticklabels=list(SORTS.values()),
                    yticklabels=list(ASSIGNS.values()))
        ax.set_title(label)
        ax.set_xlabel("")
        ax.set_ylabel("")
    return fig


def package_waits(sweep: Path) -> pd.DataFrame:
    """Every package's delivery wait of every ok run: columns algo, seed, sort, assign, wait_s."""
    spec = parse_spec(WAIT_SPEC)
    frames = []
    for run_dir in find_runs(sweep):
        manifest = read_manifest(run_dir)
        if manifest.get("status") != "ok":
            continue
        problems: list[str] = []
        ground = run_dir / "logs" / "ground"
        events = read_table(ground / "events.parquet", "events", GROUND, problems)
        stages = read_table(ground / "stages.parquet", "stages", GROUND, problems)
        if events is None or stages is None:
            continue
        events, stages = events.assign(**{T: events["t_s"]}), stages.assign(**{T: stages["t_s"]})
        window = exec_window(stages, float(stages[T].max()))
        waits = marker_values(events, spec, window.start)
        algo = manifest["choices"]["algo"]
        frames.append(pd.DataFrame({"algo": algo, "seed": manifest["seed"], "wait_s": waits.to_numpy()}))
    out = pd.concat(frames, ignore_index=True)
    sort_assign = out["algo"].map(split_algo)
    return out.assign(sort=sort_assign.str[0], assign=sort_assign.str[1])


def delivery_boxplot(waits: pd.DataFrame) -> Figure:
    """Pooled per-package waits: x = assignment (BLK, RR, DYN), one box per sort, mean marked."""
    fig = Figure(figsize=(7.5, 4.5), layout="constrained")
    ax = fig.add_subplot()
    data = waits.assign(assign=waits["assign"].map(ASSIGNS), sort=waits["sort"].map(SORTS))
    sns.boxplot(data=data, x="assign", y="wait_s", hue="sort", order=["BLK", "RR", "DYN"],
                hue_order=list(SORTS.values()), showmeans=True, fliersize=1.5, ax=ax,
                palette=["#3D9970", "#FF4136", "#004A82"])
    sns.move_legend(ax, "upper left", bbox_to_anchor=(1.0, 1.0), title="sort")
    ax.set_xlabel("assignment")
    ax.set_ylabel("delivery wait (s)")
    ax.set_title("Delivery time, every package of every dataset")
    return fig


def table6_ranks(summary: pd.DataFrame) -> pd.DataFrame:
    """Per Table-6 metric, the algorithms ranked by mean (1 = best, by the metric's direction; means
    equal to 5 significant digits tie and share the lower rank) and their mean rank; index: algo."""
    rows = summary[summary["metric"].isin(list(TABLE6))]
    key = rows["mean"].map(lambda v: float(f"{v:.5g}"))
    rows = rows.assign(key=np.where(rows["direction"] == "higher", -key, key))
    rows = rows.assign(rank=rows.groupby("metric")["key"].rank(method="min"))
    wide = rows.pivot(index="algo", columns="metric", values="rank")
    return wide.assign(mean_rank=wide.mean(axis=1))


def results_table(summary: pd.DataFrame) -> pd.DataFrame:
    """Per algorithm: ``mean [95 % CI] #rank`` of each Table-6 metric, the delivered count, the mean
    rank over the eight metrics (1 = best); best mean rank first."""
    rank = table6_ranks(summary)
    rows = []
    for algo, group in summary.groupby("algo", sort=False):
        by_metric = group.set_index("metric")
        row = {"algo": algo, "runs": int(by_metric.loc["mission_duration_s", "n"])}
        for metric, (label, unit, scale) in TABLE6.items():
            r = by_metric.loc[metric]
            row[f"{label} ({unit})"] = (f"{r['mean'] * scale:.1f} [{r['ci_low'] * scale:.1f}, "
                                        f"{r['ci_high'] * scale:.1f}] #{int(rank.loc[algo, metric])}")
        row["delivered"] = f"{by_metric.loc[DELIVERED, 'mean']:.1f}"
        row["mean rank"] = round(float(rank.loc[algo, "mean_rank"]), 2)
        rows.append(row)
    return pd.DataFrame(rows).sort_values("mean rank", kind="stable").reset_index(drop=True)


def summary_of(sweep: Path) -> pd.DataFrame:
    path = sweep / "tables" / "summary.csv"
    if not path.is_file():
        write_sweep(analyze_sweep(sweep), sweep)
    return pd.read_csv(path)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("sweep", type=Path, help="the RQ4 sweep directory")
    parser.add_argument("--publish", action="store_true",
                        help="also write the README's data and tables (experiments/rq4_delivery/results/)")
    args = parser.parse_args(argv)
    matplotlib.use("Agg")
    summary = summary_of(args.sweep)
    summary = summary[summary["algo"].str.startswith("delivery_")]
    if summary.empty:
        print(f"error: no delivery runs summarized under {args.sweep}", file=sys.stderr)
        return 2
    figures, tables = args.sweep / "figures", args.sweep / "tables"
    save(heatmaps(summary), figures, "fig4_heatmaps")
    waits = package_waits(args.sweep)
    save(delivery_boxplot(waits), figures, "fig4_delivery_time")
    pooled = waits.groupby("algo")["wait_s"].agg(["count", "mean", "median", "std", "max"]).reset_index()
    write_table(pooled, tables, "rq4_package_waits")
    result = results_table(summary)
    write_table(result, tables, "rq4_table")
    print((tables / "rq4_table.md").read_text())
    print(f"pooled package waits:\n{(tables / 'rq4_package_waits.md').read_text()}")
    print(f"figures written under {figures}")
    if args.publish:
        for path in publish.write(tables):
            print(f"published {path}")
    return 0 if np.isfinite(summary["mean"]).any() else 1


if __name__ == "__main__":
    sys.exit(main())
