"""Figures of the onset-agnostic diagnosis and of the detection benchmark.

What the analyzer found is drawn from its own output only (series and alarms); the injected ground
truth, when given, is one separate layer — a shaded fault window and a label starting with
"ground truth" — so that a figure without it is exactly the figure of a run whose fault events were
never logged.
"""

from __future__ import annotations

import numpy as np
import pandas as pd
from matplotlib.figure import Figure
from matplotlib.ticker import NullFormatter

from swarmbox.analysis.catalog import FAULT_UNITS
from swarmbox.analysis.diagnosis import Series
from swarmbox.analysis.scoring import Truth
from swarmbox.analysis.unify import T

TRUTH_GID = "ground-truth"


def _metric_of(series: Series, alarms: pd.DataFrame) -> str:
    """The first alarm's metric; without alarms, the metric whose largest robust deviation is biggest."""
    if len(alarms):
        return str(alarms.iloc[0]["metric"])
    best, name = -1.0, next(iter(series.values))
    for metric, mat in series.values.items():
        if not np.isfinite(mat).any():
            continue
        dev = np.nanmax(np.abs(mat - np.nanmedian(mat, axis=1, keepdims=True)))
        if dev > best:
            best, name = dev, metric
    return name


def timeline(series: Series, alarms: pd.DataFrame, *, truth: Truth | None = None,
             metric: str | None = None) -> Figure:
    """One metric of every drone over the scan, the analyzer's flagged drone and first alarm marked;
    ``truth`` adds the injected fault's window as a separate, labelled overlay."""
    metric = metric or _metric_of(series, alarms)
    fig = Figure(figsize=(8.0, 4.0), layout="constrained")
    ax = fig.add_subplot()
    flagged = int(alarms.iloc[0]["drone"]) if len(alarms) else None
    times = series.times()
    mat = series.values[metric]
    for j, drone in enumerate(series.drones):
        mine = drone == flagged
        ax.plot(times, mat[:, j], lw=1.6 if mine else 0.6, color="C3" if mine else "0.6",
                label=f"drone {drone} (flagged)" if mine else None, zorder=3 if mine else 2)
    ax.plot([], [], lw=0.6, color="0.6", label="other drones")
    if flagged is not None:
        ax.axvline(float(alarms.iloc[0][T]), color="black", ls=":", label="first alarm")
    if truth is not None:
        end = truth.end_u if truth.end_u is not None else float(times[-1])
        ax.axvspan(truth.onset_u, end, color="tab:blue", alpha=0.12, gid=TRUTH_GID,
                   label=f"ground truth: {truth.name} on drone {truth.target}")
    ax.set_xlabel("unified time (s)")
    ax.set_ylabel(metric)
    ax.legend(loc="upper left", fontsize="small")
    title = f"first alarm: drone {flagged}, {metric}" if flagged is not None else f"no alarm ({metric})"
    ax.set_title(title)
    return fig


def _grid(n: int) -> tuple[Figure, np.ndarray]:
    cols = min(3, max(n, 1))
    rows = int(np.ceil(n / cols)) or 1
    fig = Figure(figsize=(4.2 * cols, 3.3 * rows), layout="constrained")
    return fig, fig.subplots(rows, cols, squeeze=False).ravel()


#: How each detector is drawn: colour and marker differ, so print and colour-blind readers tell them apart.
DETECTOR_STYLE = {"swarmbox": ("tab:blue", "o", "swarm analyzer"),
                  "baseline": ("tab:orange", "s", "per-drone baseline")}
_LINES = ("-", "--", ":", "-.")
DETECTION_TARGET = 0.9


def detection_curves(det: pd.DataFrame, *, units: dict[str, str] | None = None) -> Figure:
    """Detection rate against fault magnitude, one panel per fault. Each detector has its own colour and
    marker; each swarm size and network its own line style; the legend names both. The 90 % target is a
    labelled line; the magnitude axis carries the fault's unit (``units``, default
    :data:`~swarmbox.analysis.catalog.FAULT_UNITS`)."""
    units = {**FAULT_UNITS, **(units or {})}
    faults = sorted(det["fault"].unique())
    fig, axes = _grid(len(faults))
    for ax, fault in zip(axes, faults, strict=False):
        part = det[det["fault"] == fault]
        for i, ((n, net), g) in enumerate(part.groupby(["n_drones", "network"], sort=True)):
            for detector, (colour, marker, name) in DETECTOR_STYLE.items():
                d = g[g["detector"] == detector].sort_values("magnitude")
                if len(d):
                    ax.plot(d["magnitude"], d["detection_rate"], ls=_LINES[i % len(_LINES)], marker=marker,
                            ms=4, color=colour, alpha=0.85, label=f"{name}, {n} drones, {net}")
        ax.axhline(DETECTION_TARGET, color="0.4", lw=0.8, ls=":", label="90 % detection")
        ax.annotate("90 %", (1.0, DETECTION_TARGET), xycoords=("axes fraction", "data"), ha="right",
                    va="bottom", fontsize="x-small", color="0.3")
        ax.set_xscale("log")
        mags = sorted(part["magnitude"].dropna().unique())
        ax.xaxis.set_minor_formatter(NullFormatter())
        ax.set_xticks(mags, [f"{m:g}" for m in mags])
        ax.set_ylim(-0.03, 1.03)
        ax.set_title(fault, wrap=True)
        unit = units.get(fault, "")
        ax.set_xlabel(f"magnitude [{unit}]" if unit else "magnitude")
        ax.set_ylabel("detection rate (share of runs)")
        ax.legend(fontsize="x-small")
    for ax in axes[len(faults):]:
        ax.set_visible(False)
    return fig


def roc_curves(curves: pd.DataFrame) -> Figure:
    """Detection rate against false alarms per drone-hour over the detector's threshold, one panel
    per fault, one curve per magnitude (the paper's rule as a cross)."""
    faults = sorted(curves["fault"].unique())
    fig, axes = _grid(len(faults))
    for ax, fault in zip(axes, faults, strict=False):
        part = curves[(curves["fault"] == fault) & (curves["detector"] == "swarmbox")]
        for i, (mag, g) in enumerate(part.groupby("magnitude", sort=True)):
            tukey = g[g["rule"] == "tukey"].sort_values("threshold_scale")
            ax.plot(tukey["fa_per_drone_h"], tukey["detection_rate"], marker="o", ms=3, color=f"C{i}",
                    label=f"{mag:g}")
            paper = g[g["rule"] == "paper"]
            ax.scatter(paper["fa_per_drone_h"], paper["detection_rate"], marker="x", color=f"C{i}")
        ax.axvline(1.0, color="0.5", lw=0.6, ls=":")
        ax.set_xscale("symlog", linthresh=0.1)
        ax.set_xlim(left=0.0)
        ax.set_ylim(-0.03, 1.03)
        ax.set_title(fault)
        ax.set_xlabel("false alarms per drone-hour")
        ax.set_ylabel("detection rate")
        ax.legend(title="magnitude", fontsize="x-small")
    for ax in axes[len(faults):]:
        ax.set_visible(False)
    return fig
