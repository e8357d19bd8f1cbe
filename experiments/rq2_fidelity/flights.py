"""Per-drone flight series of RQ2 runs, and the small reference file recorded on real PX4.

A *flight* is one drone's run as one table on a common 20 Hz clock (the drone's own log clock):
``t_s``, the setpoint in force (``sp_n/e/d``, position setpoints only), the estimated position the
vehicle flies on (``pos_n/e/d``), the true position where the backend knows it (``true_n/e/d``,
NaN otherwise) and the swarm stage (``stage``). That is everything the fidelity measures need, so
real PX4 flights can be kept in the repository (``data/px4_reference.parquet``, a few hundred KB)
and the sim tuned and tested against them without PX4.

    python experiments/rq2_fidelity/flights.py RUN_DIR [RUN_DIR ...] --out data/px4_reference.parquet
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
import pandas as pd

SAMPLE_S = 0.05
AXES = ("n", "e", "d")
COLUMNS = ("t_s", *(f"sp_{a}" for a in AXES), *(f"pos_{a}" for a in AXES),
           *(f"true_{a}" for a in AXES), "stage")


def drone_ids(run_dir: Path) -> list[int]:
    """The drone ids that logged a state table in ``run_dir``."""
    return sorted(int(p.name.split("_")[1]) for p in (Path(run_dir) / "logs").glob("drone_*")
                  if (p / "state.parquet").is_file())


def flight(run_dir: Path, drone: int) -> pd.DataFrame:
    """One drone's flight from a run directory, resampled at :data:`SAMPLE_S`."""
    node = Path(run_dir) / "logs" / f"drone_{drone}"
    if not (node / "state.parquet").is_file():
        raise FileNotFoundError(f"{node}: no state.parquet (not a run directory, or drone {drone} absent)")
    state = pd.read_parquet(node / "state.parquet")
    sps = pd.read_parquet(node / "setpoints.parquet")
    sps = sps[(sps["kind"] == "position") & (sps["verdict"] != "refused")]
    t = np.arange(state["t_s"].iloc[0], state["t_s"].iloc[-1], SAMPLE_S)
    out = {"t_s": t}
    for a in AXES:
        for prefix in ("pos", "true"):
            out[f"{prefix}_{a}"] = np.interp(t, state["t_s"], state[f"{prefix}_{a}"])
        # the setpoint in force: the last one handed over at or before t (NaN before the first)
        k = np.searchsorted(sps["t_s"].to_numpy(), t, side="right") - 1
        vals = sps[a].to_numpy()
        out[f"sp_{a}"] = np.where(k >= 0, vals[np.maximum(k, 0)], np.nan) if len(vals) else np.nan
    k = np.searchsorted(state["t_s"].to_numpy(), t, side="right") - 1
    out["stage"] = state["stage"].to_numpy()[np.maximum(k, 0)]
    frame = pd.DataFrame(out)
    return frame.astype({c: "float32" for c in COLUMNS if c not in ("t_s", "stage")} | {"stage": "int8"})


def run_flights(run_dir: Path) -> dict[int, pd.DataFrame]:
    return {i: flight(run_dir, i) for i in drone_ids(run_dir)}


def save_reference(runs: dict[str, Path], out: Path, note: dict) -> pd.DataFrame:
    """Write the flights of ``runs`` (label -> run dir) as one Parquet file with a JSON note."""
    frames = []
    for label, run_dir in runs.items():
        for i, f in run_flights(run_dir).items():
            frames.append(f.assign(run=label, drone=np.int16(i)))
    table = pd.concat(frames, ignore_index=True)
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = out.with_suffix(".tmp")
    table.to_parquet(tmp, index=False, compression="zstd")
    tmp.replace(out)
    out.with_suffix(".json").write_text(json.dumps(note, indent=2) + "\n")
    return table


def load_reference(path: Path) -> dict[str, dict[int, pd.DataFrame]]:
    """run label -> drone -> flight, from a file written by :func:`save_reference`."""
    table = pd.read_parquet(path)
    missing = {*COLUMNS, "run", "drone"} - set(table.columns)
    if missing:
        raise ValueError(f"{path}: not a flight reference file (missing {sorted(missing)})")
    return {str(r): {int(i): g.drop(columns=["run", "drone"]).reset_index(drop=True)
                     for i, g in rg.groupby("drone")}
            for r, rg in table.groupby("run", sort=False)}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description="Keep RQ2 runs as a flight reference file.")
    ap.add_argument("runs", nargs="+", type=Path, help="run directories (labelled px4_1, px4_2, ...)")
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--label", default="px4")
    ap.add_argument("--note", default="", help="free text kept in the .json beside the file")
    args = ap.parse_args(argv)
    runs = {f"{args.label}_{k + 1}": d for k, d in enumerate(args.runs)}
    notes = {label: json.loads((d / "run.json").read_text()) for label, d in runs.items()
             if (d / "run.json").is_file()}
    note = {"note": args.note, "sample_s": SAMPLE_S,
            "runs": {label: {key: n.get(key) for key in ("status", "sim_time_s", "wall_time_s", "overrides")}
                     for label, n in notes.items()}}
    table = save_reference(runs, args.out, note)
    print(f"{args.out}: {len(table)} rows, {args.out.stat().st_size / 1e3:.0f} KB")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
