"""Figures. Every function takes a tidy frame (and keywords), draws on ``ax`` or on a new figure, and
returns the figure; nothing here writes files (the CLI does, through :func:`save`).

Figures are built as ``matplotlib.figure.Figure`` objects, never through pyplot's global state: they
render with the Agg canvas whatever backend the caller has set, and nothing leaks between figures.
"""

from __future__ import annotations

import textwrap
from pathlib import Path

import matplotlib
import numpy as np
import pandas as pd
import seaborn as sns
from matplotlib.axes import Axes
from matplotlib.figure import Figure

from swarmbox.analysis.catalog import MACHINE_METRICS, unit_of
from swarmbox.analysis.unify import T

_GROUND = -1
MIN_N_BOX = 5     # fewer runs in a group: dots and the mean, no quartile box


def _axes(ax: Axes | None, size: tuple[float, float] = (6.0, 5.0)) -> tuple[Figure, Axes]:
    if ax is not None:
        return ax.figure, ax
    fig = Figure(figsize=size, layout="constrained")
    return fig, fig.add_subplot()


def save(fig: Figure, directory: Path, name: str, formats: tuple[str, ...] = ("png", "svg")) -> list[Path]:
    """Write ``fig`` as ``<directory>/<name>.<fmt>`` for each format.

    The layout is solved once, for the first format, and then kept: the constrained-layout solver
    measures every tick label and was half of the time spent saving a large run's figures.
    """
    directory.mkdir(parents=True, exist_ok=True)
    paths = [directory / f"{name}.{fmt}" for fmt in formats]
    engine = fig.get_layout_engine()
    try:
        for i, path in enumerate(paths):
            fig.savefig(path, dpi=150)
            if i == 0 and engine is not None:
                fig.set_layout_engine("none")   # positions stay where the first draw put them
    finally:
        if engine is not None:
            fig.set_layout_engine(engine)
    return paths


def label(metric: str, units: dict[str, str] | None = None) -> str:
    """Axis label of a metric: its name (as in the tables) and its unit, from the catalog or the
    algorithm's declaration (``units``); nothing is guessed from the name, and a count has none."""
    unit = unit_of(metric, units)
    return f"{metric} [{unit}]" if unit else metric


def gaps(summary: pd.DataFrame, group_by: tuple[str, ...] = ("algo",), metrics: list[str] | None = None,
         rel_tol: float = 1e-4, strata: tuple[str, ...] = ()) -> tuple[pd.DataFrame, pd.DataFrame]:
    """(gap, mean) matrices group x metric: how far each group's mean is from the best group's of its
    stratum (``strata``: the summary columns groups are compared within, e.g. the mission).

    gap = |mean - best mean| / largest |mean| of the metric in the stratum, in [0, 1]; 0 is the best
    group (or a tie within ``rel_tol``). Unlike min-max scaling, this stays meaningful with two groups: a 3 %
    difference reads as 3 %, not as best vs worst. Only algorithm metrics with a direction are kept (never
    machine figures or run counts), and only where a stratum holds two groups with values.
    """
    data = summary[summary["direction"].isin(["lower", "higher"]) & ~summary["metric"].isin(MACHINE_METRICS)
                   & (summary.get("kind", "metric") != "runs")]
    if metrics is not None:
        data = data[data["metric"].isin(metrics)]
    keys = [*group_by, *[s for s in strata if s not in group_by]]
    data = data.assign(group=data[keys].astype("str").agg("/".join, axis=1) if keys else "all",
                       stratum=data[list(strata)].astype("str").agg("/".join, axis=1) if strata else "all")
    means = data.pivot(index="group", columns="metric", values="mean").astype("float64")
    directions = data.drop_duplicates("metric").set_index("metric")["direction"].reindex(means.columns)
    stratum = data.drop_duplicates("group").set_index("group")["stratum"].reindex(means.index)
    by = means.groupby(stratum)
    lower = np.broadcast_to((directions == "lower").to_numpy(), means.shape)
    best = by.transform("min").where(lower, by.transform("max"))
    scale = np.maximum(means.abs().groupby(stratum).transform("max"), 1e-12)
    gap = (means - best).abs() / scale
    enough = means.notna().groupby(stratum).transform("sum") >= 2   # one group alone: nothing to compare
    gap = gap.where(gap > rel_tol, 0.0).where(means.notna() & enough)
    gap = gap.loc[:, gap.notna().any()]
    means = means[gap.columns]
    order = [m for m in dict.fromkeys(data["metric"]) if m in means.columns]
    return gap[order], means[order]


def _group_runs(summary: pd.DataFrame, keys: list[str]) -> dict[str, str]:
    """Per group label: "ok/attempted" runs, from the summary's run counts."""
    counts = summary[summary["metric"].isin(["runs_ok", "runs_attempted"])]
    if counts.empty:
        return {}
    counts = counts.assign(group=counts[keys].astype("str").agg("/".join, axis=1) if keys else "all")
    wide = counts.pivot_table(index="group", columns="metric", values="mean", aggfunc="first")
    return {g: f"{int(r.runs_ok)}/{int(r.runs_attempted)} runs ok" for g, r in wide.iterrows()}


def heatmap(summary: pd.DataFrame, *, group_by: tuple[str, ...] = ("algo",), metrics: list[str] | None = None,
            strata: tuple[str, ...] = (), units: dict[str, str] | None = None,
            ax: Axes | None = None) -> Figure:
    """Group x metric: each cell shows the group's mean; colour = gap to the best group of its stratum
    (white = best). Each group's runs ok / attempted under its name; a cell whose mean stands on fewer
    values than the group's ok runs says on how many (n=).

    Metrics run down the rows (names stay readable), groups across the columns. The colour scale
    runs from 0 to the largest gap (at least 10 %), so small differences are not painted as large.
    """
    gap, means = gaps(summary, group_by, metrics, strata=strata)
    gap, means = gap.T, means.T
    fig, ax = _axes(ax, (3.5 + 1.5 * max(len(gap.columns), 1), 1.8 + 0.45 * max(len(gap), 1)))
    keys = [*group_by, *[s for s in strata if s not in group_by]]
    if gap.empty:
        ax.text(0.5, 0.5, "no metric with a direction in two or more groups of one stratum:\n"
                "nothing to compare",
                ha="center", va="center", wrap=True)
        ax.set_axis_off()
        return fig
    runs = _group_runs(summary, keys)
    cells = _cells(summary, keys, means, {g: int(t.split("/")[0]) for g, t in runs.items()})
    vmax = float(np.clip(np.nanmax(gap.to_numpy(dtype="float64"), initial=0.0), 0.1, 1.0))
    sns.heatmap(100 * gap.astype("float64"), ax=ax, cmap="OrRd", vmin=0, vmax=100 * vmax,
                annot=cells.to_numpy(), fmt="", linewidths=0.5, linecolor="white",
                cbar_kws={"label": "gap to the best group (% of the largest mean)"})
    ax.set_yticks(np.arange(len(gap)) + 0.5, [label(m, units) for m in gap.index], rotation=0)
    ax.set_xticks(np.arange(len(gap.columns)) + 0.5,
                  [f"{g}\n({runs[g]})" if g in runs else g for g in gap.columns])
    ax.set_xlabel("/".join(keys))
    ax.set_ylabel("")
    ax.tick_params(axis="x", labelrotation=30)
    within = f"; compared within {'/'.join(strata)}" if strata else ""
    values = summary.loc[summary["metric"].isin(means.index), "n"]
    title = f"Mean per {'/'.join(keys)} (n per mean: {_n_range(values)}); white = best{within}"
    ax.set_title(_wrapped(title, fig, 12.0))
    return fig


def _n_range(n: pd.Series) -> str:
    lo, hi = int(n.min()), int(n.max())
    return f"{lo}" if lo == hi else f"{lo}-{hi}"


def _cells(summary: pd.DataFrame, keys: list[str], means: pd.DataFrame, ok: dict[str, int]) -> pd.DataFrame:
    """Cell texts (metric x group): the mean, and its n where it is below the group's ok runs."""
    n = summary.assign(group=summary[keys].astype("str").agg("/".join, axis=1) if keys else "all")
    n = n.pivot_table(index="metric", columns="group", values="n", aggfunc="first").reindex_like(means)
    return pd.DataFrame([[_annot(means.iloc[i, j], n.iloc[i, j], ok.get(g))
                          for j, g in enumerate(means.columns)] for i in range(len(means))])


def _annot(mean: float, n: float, ok: int | None) -> str:
    if pd.isna(mean):
        return ""
    return f"{mean:.3g}" if ok is None or n == ok else f"{mean:.3g}\n(n={int(n)})"


def boxplot(runs: pd.DataFrame, *, metric: str, by: str = "algo", units: dict[str, str] | None = None,
            ax: Axes | None = None) -> Figure:
    """One metric across seeds, one column per group: every run as a dot, the mean as a bar; a box
    (quartiles) only from 5 runs up, since quartiles of 2-4 points are not a distribution
    (paper Fig. 4, right)."""
    fig, ax = _axes(ax, (4.0, 4.0))
    data = runs[[by, metric]].replace([np.inf, -np.inf], np.nan).dropna()
    labels = data[by].astype("str")
    order = sorted(labels.unique())
    groups = [data.loc[labels == g, metric].to_numpy(dtype="float64") for g in order]
    positions = list(range(len(order)))
    boxed = [(x, v) for x, v in zip(positions, groups, strict=True) if v.size >= MIN_N_BOX]
    if boxed:
        ax.boxplot([v for _, v in boxed], positions=[x for x, _ in boxed], widths=0.6, patch_artist=True,
                   boxprops={"facecolor": "#9ecae1"}, medianprops={"color": "black"}, showfliers=False)
    for x, values in zip(positions, groups, strict=True):
        jitter = np.linspace(-0.12, 0.12, values.size) if values.size > 1 else np.zeros(1)
        ax.scatter(x + jitter[: values.size], values, s=12, color="black", zorder=3,
                   label="one run" if x == 0 else None)
        if values.size:
            ax.hlines(values.mean(), x - 0.3, x + 0.3, color="#d62728", lw=2, zorder=4,
                      label="mean" if x == 0 else None)
    ax.set_xticks(positions, [f"{g}\n(n={v.size})" for g, v in zip(order, groups, strict=True)])
    ax.ticklabel_format(axis="y", useOffset=False)
    ax.set_ylabel(label(metric, units))
    ax.set_title(metric, fontsize="medium")
    return fig


def boxplots(runs: pd.DataFrame, *, metrics: list[str], by: str = "algo", units: dict[str, str] | None = None,
             ax: Axes | None = None) -> Figure:
    """A grid of :func:`boxplot` s, one per metric that varies (``ax`` is ignored: the grid needs its
    own figure). Metrics with the same value in every run get no panel; a footnote lists them."""
    varying, constant = [], []
    for m in metrics:
        values = runs[m].replace([np.inf, -np.inf], np.nan).dropna()
        (varying if values.nunique() > 1 else constant).append(m)
    cols = min(4, max(len(varying), 1))
    rows = int(np.ceil(len(varying) / cols)) or 1
    fig = Figure(figsize=(3.8 * cols, 3.4 * rows + 0.6), layout="constrained")
    axes = fig.subplots(rows, cols, squeeze=False).ravel()
    for metric, axis in zip(varying, axes, strict=False):
        boxplot(runs, metric=metric, by=by, units=units, ax=axis)
    for axis in axes[len(varying):]:
        axis.set_visible(False)
    if varying:
        axes[0].legend(loc="best", fontsize="x-small")
    title = f"Per-run values by {by} (box: quartiles, from {MIN_N_BOX} runs up)"
    if constant:
        same = ", ".join(f"{m} = {runs[m].dropna().iloc[0]:.3g}" if runs[m].notna().any() else f"{m}: no data"
                         for m in constant)
        title += f". The same in every run, not drawn: {same}"
    fig.suptitle(_wrapped(title, fig), fontsize="medium")
    return fig


def _wrapped(text: str, fig: Figure, points: float = 10.0) -> str:
    """``text`` broken into lines that fit the figure's width (about 0.55 em a character), so that a
    title is never cut at the figure's edge."""
    per_line = max(20, int(fig.get_figwidth() * 72 / (0.55 * points)) - 4)
    return "\n".join(textwrap.wrap(text, per_line, break_long_words=True))


def _track(rows: pd.DataFrame) -> tuple[np.ndarray, np.ndarray, str]:
    """(east, north, source): true positions where the backend logged them, else the estimate."""
    true = rows[["true_n", "true_e"]].to_numpy(dtype="float64")
    if len(true) and np.isfinite(true).all():
        return true[:, 1], true[:, 0], "true"
    return rows["pos_e"].to_numpy(dtype="float64"), rows["pos_n"].to_numpy(dtype="float64"), "estimated"


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
    sources = set()
    for drone, rows in state.sort_values(T).groupby("node", sort=True):
        east, north, source = _track(rows)
        sources.add(source)
        (line,) = ax.plot(east, north, lw=1.2, label=f"drone {drone}")
        if len(east):
            ax.scatter([east[0]], [north[0]], marker="o", color=line.get_color(), zorder=3)
            ax.annotate(str(drone), (east[0], north[0]), textcoords="offset points", xytext=(4, 4))
    ax.set_xlabel("East (m)")
    ax.set_ylabel("North (m)")
    ax.set_aspect("equal", adjustable="datalim")
    ax.legend(loc="best", fontsize="small")
    what = " and ".join(sorted(sources)) or "no"
    ax.set_title(f"Horizontal paths ({what} positions; dot = start)")
    return fig


def _trajectory_density(state: pd.DataFrame, drones: np.ndarray, fig: Figure, ax: Axes) -> Figure:
    east, north, source = _track(state)
    ok = np.isfinite(east) & np.isfinite(north)
    if ok.any():
        hb = ax.hexbin(east[ok], north[ok], gridsize=120, bins="log", cmap="Greys", mincnt=1, linewidths=0)
        hb.set_rasterized(True)
        fig.colorbar(hb, ax=ax, label="samples (log)")
    e0, n0, _ = _track(state.sort_values(T).groupby("node", sort=True).head(1))
    ax.scatter(e0, n0, s=4, color="tab:blue", label=f"start ({len(drones)} drones)", rasterized=True)
    chosen = np.unique(drones[np.linspace(0, len(drones) - 1, SAMPLED_TRACKS).round().astype(int)])
    for drone in chosen:
        e, n, _ = _track(state[state["node"] == drone].sort_values(T))
        ax.plot(e, n, lw=0.9, color="tab:orange", alpha=0.9)
    ax.plot([], [], color="tab:orange", label=f"{len(chosen)} sampled tracks")
    ax.set_xlabel("East (m)")
    ax.set_ylabel("North (m)")
    ax.set_aspect("equal", adjustable="datalim")
    ax.legend(loc="upper right", fontsize="small")
    ax.set_title(f"Horizontal paths of {len(drones)} drones ({source} positions; density + sampled tracks)")
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
    name, unit = TIMELINE_LABELS.get(metric, (metric, ""))
    ax.set_xlabel("unified time [s] (ground clock)")
    ax.set_ylabel(f"{name} [{unit}]" if unit else name)
    ax.set_title(f"{name[0].upper()}{name[1:]} per drone")
    ax.legend(loc="best", fontsize="small")
    return fig


def _band(data: pd.DataFrame, ax: Axes, target: int | None) -> None:
    """Many drones: the median over drones per window, the 5-95 % band, the extremes, the target."""
    q = data.groupby(T)["value"].quantile([0.0, 0.05, 0.5, 0.95, 1.0]).unstack()
    ax.fill_between(q.index, q[0.0], q[1.0], color="tab:blue", alpha=0.12, lw=0, label="min-max")
    ax.fill_between(q.index, q[0.05], q[0.95], color="tab:blue", alpha=0.3, lw=0, label="5-95 %")
    ax.plot(q.index, q[0.5], color="tab:blue", lw=1.2, label=f"median of {data['drone'].nunique()} drones")
    if target is not None:
        rows = data[data["drone"] == target]
        ax.plot(rows[T], rows["value"], color="tab:red", lw=1.5, label=f"drone {target} (target)")


#: Timeline metrics (:data:`swarmbox.analysis.timeline.MONITORED`): readable name and unit.
TIMELINE_LABELS = {
    "latency_ms": ("one-way latency of delivered messages", "ms"),
    "loss_ratio": ("share of messages lost", "0-1"),
    "disc_n_m": ("GNSS - estimate, north", "m"),
    "disc_e_m": ("GNSS - estimate, east", "m"),
    "disc_d_m": ("GNSS - estimate, down", "m"),
}


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
    vmax = max(float(finite.max()), 1e-3) if len(finite) else 1.0
    cmap = matplotlib.colormaps["viridis"]
    norm = matplotlib.colors.Normalize(vmin=0.0, vmax=vmax)
    for a, b in pairs:
        parts, values = [], []
        for s, d in ((a, b), (b, a)):
            if (s, d) in lat.index:
                row = lat.loc[(s, d)]
                loss_pct = 100 * row["loss_ratio"]
                parts.append(f"{_name(s)}>{_name(d)} {row['latency_ms_mean']:.1f} ms {loss_pct:.0f}%")
                values.append(row["latency_ms_mean"])
        mean = float(np.nanmean(values)) if np.isfinite(values).any() else np.nan
        colour = cmap(norm(mean)) if np.isfinite(mean) else "grey"
        (xa, ya), (xb, yb) = pos[a], pos[b]
        ax.plot([xa, xb], [ya, yb], color=colour, lw=2)
        ax.text((xa + xb) / 2, (ya + yb) / 2, "\n".join(parts), fontsize=6, ha="center", va="center",
                bbox={"fc": "white", "alpha": 0.7, "lw": 0})
    for node, (x, y) in pos.items():
        ax.scatter([x], [y], s=400, color="#fdae6b" if node == _GROUND else "#9ecae1", zorder=3)
        ax.text(x, y, _name(node), ha="center", va="center", fontsize=8, zorder=4)
    ax.set_axis_off()
    ax.set_aspect("equal")
    fig.colorbar(matplotlib.cm.ScalarMappable(norm=norm, cmap=cmap), ax=ax, shrink=0.7,
                 label="mean one-way latency of the link [ms] (grey: no delivery)")
    ax.set_title("Communication graph (labels: latency and loss each way)")
    return fig


def _name(node: int) -> str:
    return "G" if node == _GROUND else f"d{node}"
