"""Fig. 5-style panel: every drone's horizontal track in each RQ5 scenario, one axis per mission.

    python experiments/rq5_scenarios/panel.py [results/rq5_scenarios]

Reads ``<out>/<name>/logs/drone_*/state.parquet`` (ground truth; the estimate where there is none)
of the runs ``run_all.py`` made and writes ``<out>/fig5_trajectories.{png,svg}`` (the eight
36-drone missions) and, when the 200-drone runs exist, ``<out>/fig5_scale.{png,svg}``. The
tracking panel also draws the target's path (the ground's ``tracking`` markers, dashed black).
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
import pandas as pd
from matplotlib.axes import Axes
from matplotlib.figure import Figure

sys.path.insert(0, str(Path(__file__).resolve().parent))
from run_all import ROOT, SCALE, SCENARIOS  # noqa: E402

STRIDE = 10   # plot every 10th state row (4 Hz)


def tracks(run_dir: Path) -> dict[int, np.ndarray]:
    """drone id -> (k, 2) array of (east, north) while airborne."""
    out = {}
    for path in sorted((run_dir / "logs").glob("drone_*/state.parquet")):
        st = pd.read_parquet(path, columns=["armed", "landed", "true_n", "true_e", "pos_n", "pos_e"])
        st = st[st["armed"] & ~st["landed"]].iloc[::STRIDE]
        n, e = st["true_n"].to_numpy(), st["true_e"].to_numpy()
        if not np.isfinite(n).all():
            n, e = st["pos_n"].to_numpy(), st["pos_e"].to_numpy()
        out[int(path.parent.name.split("_")[1])] = np.column_stack([e, n])
    return out


def target_path(run_dir: Path) -> np.ndarray | None:
    """(k, 2) east/north of the tracking target, from the ground's markers (None if absent)."""
    path = run_dir / "logs" / "ground" / "events.parquet"
    if not path.exists():
        return None
    ev = pd.read_parquet(path)
    rows = [json.loads(x) for x in ev.loc[ev["name"] == "tracking", "data"]]
    if not rows:
        return None
    return np.array([(r["target_e"], r["target_n"]) for r in rows])


def draw(ax: Axes, run_dir: Path, title: str) -> None:
    paths = tracks(run_dir)
    width = 0.6 if len(paths) > 50 else 0.9
    for k, (_, xy) in enumerate(sorted(paths.items())):
        colour = f"C{k % 10}"
        if len(xy):
            ax.plot(xy[:, 0], xy[:, 1], lw=width, color=colour, alpha=0.85)
            ax.plot(xy[0, 0], xy[0, 1], "o", ms=2, color=colour)
    target = target_path(run_dir)
    if target is not None:
        ax.plot(target[:, 0], target[:, 1], "k--", lw=1.2, label="target")
        ax.legend(loc="upper right", fontsize="x-small")
    ax.set_title(f"{title} (N={len(paths)})", fontsize="small")
    ax.set_aspect("equal", adjustable="datalim")
    ax.tick_params(labelsize="x-small")
    ax.set_xlabel("East (m)", fontsize="x-small")
    ax.set_ylabel("North (m)", fontsize="x-small")


def panel(out: Path, scenarios: dict[str, tuple[str, list[str]]], cols: int) -> Figure | None:
    present = [(name, case) for name, (case, _) in scenarios.items() if (out / name / "run.json").exists()]
    if not present:
        return None
    rows = -(-len(present) // cols)
    fig = Figure(figsize=(3.6 * cols, 3.4 * rows), layout="constrained")
    axes = fig.subplots(rows, cols, squeeze=False).ravel()
    for ax, (name, case), letter in zip(axes, present, "abcdefghij", strict=False):
        draw(ax, out / name, f"({letter}) {case}")
    for ax in axes[len(present):]:
        ax.set_visible(False)
    return fig


def main(argv: list[str]) -> int:
    out = Path(argv[0]) if argv else ROOT / "results" / "rq5_scenarios"
    for stem, scenarios, cols in (("fig5_trajectories", SCENARIOS, 4), ("fig5_scale", SCALE, 2)):
        fig = panel(out, scenarios, cols)
        if fig is None:
            continue
        for ext in ("png", "svg"):
            fig.savefig(out / f"{stem}.{ext}", dpi=150)
        print(f"wrote {out / stem}.png/.svg")
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
