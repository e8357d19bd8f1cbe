"""RQ2 fidelity metrics and figure: pure functions over run directories (pandas, scipy, matplotlib).

- :func:`rmse_time_aligned`: both tracks resampled on one clock that starts at each drone's own
  EXECUTION entry, over the EXECUTION time both runs share; horizontal RMSE.
- :func:`rmse_path`: the paper's measure — for every sample of the other track, the distance to the
  nearest sample of the reference track (scipy cKDTree), over the whole log; horizontal RMSE. It
  ignores timing, so a late but identical path scores 0.
- :func:`trajectories`: the overlaid tracks (paper Fig. 3), numbered markers at the launch points.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
from scipy.spatial import cKDTree

EXECUTION, LANDING = 3, 4
RESAMPLE_S = 0.1


class Track:
    """One drone's estimated positions (mission frame) and its EXECUTION window, from a run dir."""

    def __init__(self, run_dir: Path, drone: int) -> None:
        node = Path(run_dir) / "logs" / f"drone_{drone}"
        state = pd.read_parquet(node / "state.parquet", columns=["t_s", "pos_n", "pos_e", "pos_d"])
        stages = pd.read_parquet(node / "stages.parquet", columns=["t_s", "stage"])
        self.drone = drone
        self.t_s = state["t_s"].to_numpy()
        self.ned = state[["pos_n", "pos_e", "pos_d"]].to_numpy()
        self.exec_start_s = _entry(stages, EXECUTION)
        self.exec_end_s = _entry(stages, LANDING, default=float(self.t_s[-1]))

    def since_exec(self) -> tuple[np.ndarray, np.ndarray]:
        """(time since EXECUTION entry, n/e/d) of the samples inside EXECUTION."""
        inside = (self.t_s >= self.exec_start_s) & (self.t_s < self.exec_end_s)
        return self.t_s[inside] - self.exec_start_s, self.ned[inside]


def _entry(stages: pd.DataFrame, stage: int, default: float | None = None) -> float:
    rows = stages.loc[stages["stage"] == stage, "t_s"]
    if rows.empty:
        if default is None:
            raise ValueError(f"the run never entered stage {stage}")
        return default
    return float(rows.iloc[0])


def rmse_time_aligned(ref: Track, other: Track) -> tuple[float, float]:
    """(horizontal RMSE, seconds compared), both tracks on a common clock from EXECUTION entry."""
    t_a, p_a = ref.since_exec()
    t_b, p_b = other.since_exec()
    span = min(t_a[-1], t_b[-1])
    grid = np.arange(0.0, span, RESAMPLE_S)
    diff = [np.interp(grid, t_a, p_a[:, k]) - np.interp(grid, t_b, p_b[:, k]) for k in (0, 1)]
    return float(np.sqrt(np.mean(diff[0] ** 2 + diff[1] ** 2))), float(span)


def rmse_path(ref: Track, other: Track) -> float:
    """Horizontal RMSE of the nearest-point distance from ``other``'s samples to ``ref``'s path."""
    dist, _ = cKDTree(ref.ned[:, :2]).query(other.ned[:, :2])
    return float(np.sqrt(np.mean(dist ** 2)))


def compare(ref_dir: Path, other_dir: Path, drones: list[int], label: str) -> pd.DataFrame:
    """One row per drone: both RMSE measures of ``other`` against ``ref``."""
    rows = []
    for i in drones:
        ref, other = Track(ref_dir, i), Track(other_dir, i)
        rmse_t, span = rmse_time_aligned(ref, other)
        rows.append({"pair": label, "drone": i, "rmse_time_aligned_m": rmse_t,
                     "rmse_path_m": rmse_path(ref, other), "compared_s": span})
    return pd.DataFrame(rows)


def trajectories(runs: dict[str, Path], drones: list[int], *, ax=None):
    """Overlaid north/east tracks of every drone in every run; numbered markers at launch points."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = (plt.subplots(figsize=(6.5, 6.0)) if ax is None else (ax.figure, ax))
    colors = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    styles = ["-", "--", ":", "-."]
    for k, (label, run_dir) in enumerate(runs.items()):
        for i in drones:
            tr = Track(run_dir, i)
            ax.plot(tr.ned[:, 1], tr.ned[:, 0], styles[k % len(styles)], color=colors[i % len(colors)],
                    lw=1.2, label=label if i == drones[0] else None, alpha=0.9)
            if k == 0:
                ax.plot(tr.ned[0, 1], tr.ned[0, 0], "o", ms=14, mfc="white", mec=colors[i % len(colors)])
                ax.annotate(str(i), (tr.ned[0, 1], tr.ned[0, 0]), ha="center", va="center", fontsize=9)
    ax.set_xlabel("east (m)")
    ax.set_ylabel("north (m)")
    ax.set_aspect("equal")
    ax.grid(alpha=0.3)
    ax.legend(title="backend (line style)", loc="upper right")
    ax.set_title("RQ2 formation: estimated tracks per drone")
    return fig
