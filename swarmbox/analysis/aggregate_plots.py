"""Figures of the aggregates across tasks: IQM with its CI per algorithm, and performance profiles."""

from __future__ import annotations

import numpy as np
import pandas as pd
from matplotlib.axes import Axes
from matplotlib.figure import Figure

from swarmbox.analysis.figures import label


def aggregates(iqm: pd.DataFrame, profiles: pd.DataFrame, *, metrics: list[str] | None = None,
               tasks: str = "task", compared: str = "algorithm", units: dict[str, str] | None = None,
               ax: Axes | None = None) -> Figure:
    """One row per metric: left, each algorithm's IQM score with its stratified-bootstrap CI (1 = best run
    of every task); right, its performance profile (share of runs scoring above tau). ``ax`` is ignored:
    the grid needs its own figure."""
    chosen = [m for m in (metrics or list(dict.fromkeys(iqm["metric"]))) if (iqm["metric"] == m).any()]
    algorithms = sorted(iqm["algorithm"].unique(), key=str)
    colours = {a: f"C{i % 10}" for i, a in enumerate(algorithms)}
    height = 0.9 + max(2.2, 0.3 * len(algorithms)) * max(len(chosen), 1)
    fig = Figure(figsize=(11.0, height), layout="constrained")
    axes = fig.subplots(max(len(chosen), 1), 2, squeeze=False)
    for (left, right), metric in zip(axes, chosen, strict=False):
        rows = iqm[iqm["metric"] == metric].set_index("algorithm").reindex(algorithms)
        y = np.arange(len(algorithms))
        err = np.vstack([rows["iqm"] - rows["ci_low"], rows["ci_high"] - rows["iqm"]])
        left.errorbar(rows["iqm"], y, xerr=err, fmt="o", color="black", ecolor="0.4", capsize=3)
        n_runs = rows["n_runs"].fillna(0).astype(int)
        left.set_yticks(y, [f"{a} (n={n})" for a, n in zip(algorithms, n_runs, strict=True)])
        left.set_xlim(-0.02, 1.02)
        left.set_xlabel("IQM score (1 = best run of the task) with 95 % CI")
        left.set_title(label(metric, units), fontsize="medium")
        for a, g in profiles[profiles["metric"] == metric].groupby("algorithm"):
            right.plot(g["tau"], g["share_above"], color=colours[a], lw=1.2, label=str(a))
        right.set_xlabel("score tau")
        right.set_ylabel("share of runs scoring > tau")
        right.set_title(f"performance profile over {tasks}", fontsize="medium")
    if chosen:
        axes[0][1].legend(fontsize="x-small", title=compared, title_fontsize="x-small",
                          ncols=2 if len(algorithms) > 6 else 1)
        for left, _ in axes:
            left.set_ylabel(compared)
    fig.suptitle(f"Across {tasks}: interquartile mean and performance profiles (scores within each task)",
                 fontsize="medium")
    return fig
