"""Figures. Every function takes a tidy frame (and keywords), draws on ``ax`` or on a new figure, and
returns the figure; nothing here writes files (the CLI does, through :func:`save`).

Figures are built as ``matplotlib.figure.Figure`` objects, never through pyplot's global state: they
render with the Agg canvas whatever backend the caller has set, and nothing leaks between figures.
"""

from __future__ import annotations

from pathlib import Path

import matplotlib
import numpy as np
import pandas as pd
import seaborn as sns
from matplotlib.axes import Axes
from matplotlib.figure import Figure

from swarmbox.analysis.unify import T

_GROUND = -1


def _axes(ax: Axes | None, size: tuple[float, float] = (6.0, 5.0)) -> tuple[Figure, Axes]:
    if ax is not None:
        return ax.figure, ax
    fig = Figure(figsize=size, layout="constrained")
    return fig, fig.add_subplot()


def save(fig: Figure, directory: Path, name: str, formats: tuple[str, ...] = ("png", "svg")) -> list[Path]:
    """Write ``fig`` as ``<directory>/<name>.<fmt>`` for each format."""
    directory.mkdir(parents=True, exist_ok=True)
    paths = [directory / f"{name}.{fmt}" for fmt in formats]
    for path in paths:
        fig.savefig(path, dpi=150)
    return paths


def normalized(summary: pd.DataFrame, group_by: tuple[str, ...] = ("algo",),
               metrics: list[str] | None = None, rel_tol: float = 1e-4) -> tuple[pd.DataFrame, pd.DataFrame]:
    """(score, mean) matrices group x metric; score in [0, 1] per metric with 1 = best.

    Min-max scaling per metric, flipped for lower-is-better metrics. Only metrics with a direction
    are kept. A metric whose group means agree within ``rel_tol`` (relative) scores 0.5 everywhere,
    so that numerical noise is not painted as a difference.
    """
    data = summary[summary["direction"].isin(["lower", "higher"])]
    if metrics is not None:
        data = data[data["metric"].isin(metrics)]
    data = data.assign(group=data[list(group_by)].astype("str").agg("/".join, axis=1))
    means = data.pivot(index="group", columns="metric", values="mean").astype("float64")
    directions = data.drop_duplicates("metric").set_index("metric")["direction"]
    lo, hi = means.min(), means.max()
    scale = np.maximum(means.abs().max(), 1e-12)
    distinct = (hi - lo) > rel_tol * scale
    score = (means - lo) / (hi - lo).where(distinct)
    lower = (directions.reindex(means.columns) == "lower").to_numpy()
    score.loc[:, lower] = 1 - score.loc[:, lower]
    score.loc[:, ~distinct.to_numpy()] = 0.5
    score = score.where(means.notna())
    order = [m for m in dict.fromkeys(data["metric"]) if m in means.columns]
    return score[order], means[order]


def heatmap(summary: pd.DataFrame, *, group_by: tuple[str, ...] = ("algo",), metrics: list[str] | None = None,
            ax: Axes | None = None) -> Figure:
    """Normalized metric heatmap across groups (paper Fig. 4, left): darker = better, values annotated."""
    score, means = normalized(summary, group_by, metrics)
    fig, ax = _axes(ax, (2.0 + 0.9 * max(len(score.columns), 1), 2.5 + 0.5 * max(len(score), 1)))
    labels = means.map(lambda v: "" if pd.isna(v) else f"{v:.3g}")
    sns.heatmap(score.astype("float64"), ax=ax, cmap="Greens", vmin=0, vmax=1, annot=labels.to_numpy(),
                fmt="", cbar_kws={"label": "1 = best"}, linewidths=0.5)
    ax.set_xlabel("")
    ax.set_ylabel("/".join(group_by))
    ax.tick_params(axis="x", labelrotation=60)
    ax.tick_params(axis="y", labelrotation=0)
    return fig


def boxplot(runs: pd.DataFrame, *, metric: str, by: str = "algo", ax: Axes | None = None) -> Figure:
    """Distribution of one metric across seeds, one box per group, mean as a triangle, runs as dots
    (paper Fig. 4, right)."""
    fig, ax = _axes(ax, (4.0, 4.0))
    data = runs[[by, metric]].replace([np.inf, -np.inf], np.nan).dropna()
    labels = data[by].astype("str")
    order = sorted(labels.unique())
    groups = [data.loc[labels == g, metric].to_numpy(dtype="float64") for g in order]
    positions = list(range(len(order)))
    if groups:
        ax.boxplot(groups, positions=positions, showmeans=True, widths=0.6, patch_artist=True,
                   boxprops={"facecolor": "#9ecae1"}, medianprops={"color": "black"})
        for x, values in zip(positions, groups, strict=True):
            ax.scatter(np.full(values.size, x), values, s=9, color="black", zorder=3)
    ax.set_xticks(positions, order)
    ax.ticklabel_format(axis="y", useOffset=False)
    ax.set_title(metric)
    return fig


def boxplots(runs: pd.DataFrame, *, metrics: list[str], by: str = "algo", ax: Axes | None = None) -> Figure:
    """A grid of :func:`boxplot` s, one per metric (``ax`` is ignored: the grid needs its own figure)."""
    cols = min(4, max(len(metrics), 1))
    rows = int(np.ceil(len(metrics) / cols)) or 1
    fig = Figure(figsize=(3.5 * cols, 3.2 * rows), layout="constrained")
    axes = fig.subplots(rows, cols, squeeze=False).ravel()
    for metric, axis in zip(metrics, axes, strict=False):
        boxplot(runs, metric=metric, by=by, ax=axis)
    for axis in axes[len(metrics):]:
        axis.set_visible(False)
    return fig


def _track(rows: pd.DataFrame) -> tuple[np.ndarray, np.ndarray]:
    true = rows[["true_n", "true_e"]].to_numpy(dtype="float64")
    if len(true) and np.isfinite(true).all():
        return true[:, 1], true[:, 0]
    return rows["pos_e"].to_numpy(dtype="float64"), rows["pos_n"].to_numpy(dtype="float64")


#: Above this many drones a per-drone line and legend entry stops helping; figures summarize instead.
MANY_DRONES = 30
#: Tracks drawn on top of the density when the swarm is large.
SAMPLED_TRACKS = 12


def trajectories(state: pd.DataFrame, *, ax: Axes | None = None) -> Figure:
    """Every drone's horizontal path (x = East, y = North, equal axes), start marked with its id.

    Above :data:`MANY_DRONES` drones: a log-scaled density of every position sample, every start as
    a dot, and :data:`SAMPLED_TRACKS` evenly chosen drones' tracks — readable at 1,000 drones, and
    the heavy layers are rasterized so an SVG stays small.
    """
    fig, ax = _axes(ax)
    drones = np.sort(state["node"].unique())
    if len(drones) > MANY_DRONES:
        return _trajectory_density(state, drones, fig, ax)
    for drone, rows in state.sort_values(T).groupby("node", sort=True):
        east, north = _track(rows)
        (line,) = ax.plot(east, north, lw=1.2, label=f"drone {drone}")
        if len(east):
            ax.scatter([east[0]], [north[0]], marker="o", color=line.get_color(), zorder=3)
            ax.annotate(str(drone), (east[0], north[0]), textcoords="offset points", xytext=(4, 4))
    ax.set_xlabel("East (m)")
    ax.set_ylabel("North (m)")
    ax.set_aspect("equal", adjustable="datalim")
    ax.legend(loc="best", fontsize="small")
    return fig


def _trajectory_density(state: pd.DataFrame, drones: np.ndarray, fig: Figure, ax: Axes) -> Figure:
    east, north = _track(state)
    ok = np.isfinite(east) & np.isfinite(north)
    if ok.any():
        hb = ax.hexbin(east[ok], north[ok], gridsize=120, bins="log", cmap="Greys", mincnt=1, linewidths=0)
        hb.set_rasterized(True)
        fig.colorbar(hb, ax=ax, label="samples (log)")
    firsts = state.sort_values(T).groupby("node", sort=True).head(1)
    e0, n0 = _track(firsts)
    ax.scatter(e0, n0, s=4, color="tab:blue", label=f"start ({len(drones)} drones)", rasterized=True)
    chosen = drones[np.linspace(0, len(drones) - 1, SAMPLED_TRACKS).round().astype(int)]
    for drone in np.unique(chosen):
        e, n = _track(state[state["node"] == drone].sort_values(T))
        ax.plot(e, n, lw=0.9, color="tab:orange", alpha=0.9)
    ax.plot([], [], color="tab:orange", label=f"{len(np.unique(chosen))} sampled tracks")
    ax.set_xlabel("East (m)")
    ax.set_ylabel("North (m)")
    ax.set_aspect("equal", adjustable="datalim")
    ax.legend(loc="upper right", fontsize="small")
    return fig


def timeline(frame: pd.DataFrame, *, metric: str, onset: float | None = None, detection: float | None = None,
             target: int | None = None, ax: Axes | None = None) -> Figure:
    """One metric per drone over unified time, with the fault onset and the first detection marked."""
    fig, ax = _axes(ax, (8.0, 4.0))
    data = frame[frame["metric"] == metric]
    if data["drone"].nunique() > MANY_DRONES:
        _band(data, ax, target)
    else:
        for drone, rows in data.groupby("drone", sort=True):
            ax.plot(rows[T], rows["value"], lw=2.0 if drone == target else 1.0,
                    label=f"drone {drone}" + (" (target)" if drone == target else ""))
    if onset is not None:
        ax.axvline(onset, color="red", ls="--", label="fault onset")
    if detection is not None:
        ax.axvline(detection, color="black", ls=":", label="first anomaly")
    ax.set_xlabel("unified time (s)")
    ax.set_ylabel(metric)
    ax.legend(loc="best", fontsize="small")
    return fig


def _band(data: pd.DataFrame, ax: Axes, target: int | None) -> None:
    """Many drones: the median over drones per window, the 5-95 % band, the extremes, the target."""
    per = data.groupby(T)["value"]
    q = per.quantile([0.0, 0.05, 0.5, 0.95, 1.0]).unstack()
    ax.fill_between(q.index, q[0.0], q[1.0], color="tab:blue", alpha=0.12, lw=0, label="min-max")
    ax.fill_between(q.index, q[0.05], q[0.95], color="tab:blue", alpha=0.3, lw=0, label="5-95 %")
    ax.plot(q.index, q[0.5], color="tab:blue", lw=1.2, label=f"median of {data['drone'].nunique()} drones")
    if target is not None:
        rows = data[data["drone"] == target]
        ax.plot(rows[T], rows["value"], color="tab:red", lw=1.5, label=f"drone {target} (target)")


def _layout(nodes: list[int]) -> dict[int, tuple[float, float]]:
    drones = [n for n in nodes if n != _GROUND]
    angle = np.linspace(0, 2 * np.pi, len(drones), endpoint=False) + np.pi / 2
    pos = {n: (float(np.cos(a)), float(np.sin(a))) for n, a in zip(drones, angle, strict=True)}
    pos[_GROUND] = (0.0, 0.0)
    return pos


def comm_graph(links: pd.DataFrame, *, ax: Axes | None = None) -> Figure:
    """Communication graph: one edge per node pair, colour = mean latency, label = latency / loss each way."""
    fig, ax = _axes(ax, (6.5, 6.0))
    nodes = sorted(set(links["src"]) | set(links["dst"]))
    pos = _layout(nodes)
    lat = links.set_index(["src", "dst"])
    pairs = sorted({(min(a, b), max(a, b)) for a, b in zip(links["src"], links["dst"], strict=True)})
    finite = links["latency_ms_mean"].dropna()
    vmax = float(finite.max()) if len(finite) else 1.0
    cmap = matplotlib.colormaps["viridis"]
    for a, b in pairs:
        parts, values = [], []
        for s, d in ((a, b), (b, a)):
            if (s, d) in lat.index:
                row = lat.loc[(s, d)]
                loss_pct = 100 * row["loss_ratio"]
                parts.append(f"{_name(s)}>{_name(d)} {row['latency_ms_mean']:.1f} ms {loss_pct:.0f}%")
                values.append(row["latency_ms_mean"])
        mean = float(np.nanmean(values)) if np.isfinite(values).any() else np.nan
        colour = cmap(mean / vmax) if np.isfinite(mean) and vmax > 0 else "grey"
        (xa, ya), (xb, yb) = pos[a], pos[b]
        ax.plot([xa, xb], [ya, yb], color=colour, lw=2)
        ax.text((xa + xb) / 2, (ya + yb) / 2, "\n".join(parts), fontsize=6, ha="center", va="center",
                bbox={"fc": "white", "alpha": 0.7, "lw": 0})
    for node, (x, y) in pos.items():
        ax.scatter([x], [y], s=400, color="#fdae6b" if node == _GROUND else "#9ecae1", zorder=3)
        ax.text(x, y, _name(node), ha="center", va="center", fontsize=8, zorder=4)
    ax.set_axis_off()
    ax.set_title("communication graph (colour: mean latency)")
    return fig


def _name(node: int) -> str:
    return "G" if node == _GROUND else f"d{node}"
