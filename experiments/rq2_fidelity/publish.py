"""The RQ2 sim-vs-PX4 tables of the documentation, from the committed PX4 flights and fresh sim runs.

    python experiments/rq2_fidelity/publish.py              # flies sim and sim_px4 (six runs, ~1 min)
    python experiments/rq2_fidelity/publish.py --runs DIR   # keeps (and reuses) the runs in DIR
    python -m experiments.published --write                 # then copies them into the documents

The PX4 side is ``data/px4_formation.parquet`` (four recorded PX4 SIH flights, committed); the sim
side is deterministic, so the same code gives the same tables. Written to ``results/``:

- ``formation_full.csv`` (docs/fidelity.md): per drone, lag, RMSE vs setpoint, sim-vs-PX4 and the
  PX4-vs-PX4 floor with every pair;
- ``formation_summary.csv`` (experiments/rq2_fidelity/README.md): the same, shortened, with the LTI
  bound;
- ``decomposition.csv`` (docs/fidelity.md): where the sim_px4-vs-PX4 error comes from
  (``decompose.py``);
- ``legs.csv`` (docs/fidelity.md): the leg pair of ``data/px4_legs.parquet`` flown in both orders,
  seconds per leg on PX4, sim and sim_px4.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
import pandas as pd

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
import decompose  # noqa: E402
import fidelity as F  # noqa: E402
from flights import load_reference, run_flights  # noqa: E402

RESULTS = HERE / "results"
REFERENCE = HERE / "data" / "px4_formation.parquet"
LEGS = HERE / "data" / "px4_legs.parquet"
BACKENDS = ("sim", "sim_px4")
#: The leg pair's two orders: the delivery algorithm's sort rule picks it (P0 = 24.8 m out first, or
#: P1 = 18.2 m out first); mission rq2_legs lives in this experiment's conf directory.
ORDERS = {"P0 then P1": "algo=delivery_none_rr", "P1 then P0": "algo=delivery_distance_rr"}
LEGS_MISSION = ("mission=rq2_legs", "seed=2", f"hydra.searchpath=[file://{HERE / 'conf'}]")


def _fly_one(run_dir: Path, overrides: list[str]) -> Path:
    """One run in its own process (run.py's single-run entry point); a finished run is kept."""
    if not (run_dir / "run.json").exists():
        subprocess.run([sys.executable, str(HERE / "run.py"), "--one", str(run_dir), "0", *overrides],
                       check=True, cwd=HERE.parents[1])
    return run_dir


def fly(out: Path) -> dict[str, Path]:
    """The formation (seed 0) on sim and sim_px4 (``out/<backend>``), and the leg pair in both orders
    (``out/legs_<backend>_<k>``, k the order's index)."""
    runs = {}
    for label in BACKENDS:
        formation = ["algo=formation", "mission=formation", "seed=0", f"backend={label}"]
        runs[label] = _fly_one(out / label, formation)
        for k, algo in enumerate(ORDERS.values()):
            name = f"legs_{label}_{k}"
            runs[name] = _fly_one(out / name, [algo, *LEGS_MISSION, f"backend={label}"])
    return runs


def leg_times(f: pd.DataFrame) -> list[float]:
    """Seconds per leg of a one-drone delivery flight: from each new position setpoint to the next
    (the algorithm sends it when the arrival test passes), the last leg to LANDING entry."""
    sp = f[["sp_n", "sp_e", "sp_d"]].to_numpy(dtype="float64")
    t = f["t_s"].to_numpy(dtype="float64")
    moved = np.all(np.isfinite(sp[1:]), axis=1) & np.any(np.abs(np.diff(sp, axis=0)) > 1e-3, axis=1)
    starts = list(t[1:][moved])
    landing = t[f["stage"].to_numpy() >= F.LANDING]
    ends = [*starts[1:], float(landing[0]) if len(landing) else np.nan]
    return [e - s for s, e in zip(starts, ends, strict=True)]


def _legs_cell(times: list[float]) -> str:
    return f"{', '.join(f'{v:.2f}' for v in times)} ({sum(times):.1f})"


def legs_table(runs: dict[str, Path], reference: Path = LEGS) -> pd.DataFrame:
    """Per order: every PX4 flight's legs (out, back, out, back) with their total, then sim and sim_px4."""
    px4 = load_reference(reference)
    out = []
    for k, (order, algo) in enumerate(ORDERS.items()):
        flights = [fl[0] for label, fl in px4.items() if _order_of(reference, label) == algo]
        row = {"order": order, "PX4 SIH flights": "; ".join(_legs_cell(leg_times(f)) for f in flights)}
        for label in BACKENDS:
            row[label] = _legs_cell(leg_times(run_flights(runs[f"legs_{label}_{k}"])[0]))
        out.append(row)
    return pd.DataFrame(out)


def _order_of(reference: Path, label: str) -> str:
    import json

    note = json.loads(reference.with_suffix(".json").read_text())
    return next(o for o in note["runs"][label]["overrides"] if o.startswith("algo="))


def _f(v: float) -> str:
    return f"{v:.2f}".replace("-", "−")


def _signed(v: float) -> str:
    return ("+" if v >= 0 else "−") + f"{abs(v):.2f}"


def tables(runs: dict[str, Path], reference: Path = REFERENCE) -> dict[str, pd.DataFrame]:
    """The three tables, as strings formatted once here."""
    px4 = load_reference(reference)
    sims = {label: run_flights(runs[label]) for label in BACKENDS}
    tab = {label: F.table(f, px4).set_index("drone") for label, f in sims.items()}
    full, summary, parts = [], [], []
    for i in sorted(sims["sim"]):
        s, p = tab["sim"].loc[i], tab["sim_px4"].loc[i]
        lags = [F.lag_s(r[i]) for r in px4.values()]
        name = f"{i} (leader)" if i == 0 else str(i)
        full.append({"drone": name, "lag sim (s)": _f(s["sim_lag_s"]), "lag sim_px4 (s)": _f(p["sim_lag_s"]),
                     "lag PX4 (s), runs 1–4 → mean":
                         f"{', '.join(_f(v) for v in lags)} → {_f(np.mean(lags))}",
                     "RMSE vs setpoint sim / sim_px4 / PX4 (m)":
                         f"{_f(s['sim_rmse_sp_m'])} / {_f(p['sim_rmse_sp_m'])} / {_f(s['px4_rmse_sp_m'])}",
                     "sim-vs-PX4 (m)": _f(s["sim_vs_px4_m"]), "sim_px4-vs-PX4 (m)": _f(p["sim_vs_px4_m"]),
                     "PX4-vs-PX4 (m), mean over the independent pairs (1-2/1-3/1-4/2-3/2-4/3-4)":
                         f"{_f(s['px4_vs_px4_m'])} ({s['px4_pairs_m']})"})
        b = decompose.bounds(px4, i)
        summary.append({"drone": str(i),
                        "lag sim / sim_px4 / PX4 (s)":
                            f"{_f(s['sim_lag_s'])} / {_f(p['sim_lag_s'])} / {_f(s['px4_lag_s'])}",
                        "sim-vs-PX4 / sim_px4-vs-PX4 (m)":
                            f"{_f(s['sim_vs_px4_m'])} / {_f(p['sim_vs_px4_m'])}",
                        "PX4-vs-PX4, independent pairs (m)": _f(s["px4_vs_px4_m"]),
                        "LTI bound (m)": _f(b["lti_bound_m"])})
        d = decompose.split(sims["sim_px4"][i], px4, i)
        parts.append({"drone": str(i), "sim_px4-vs-PX4": _f(d["sim_vs_px4_m"]),
                      "best shift (s) → RMSE": f"{_signed(d['best_shift_s'])} → {_f(d['shifted_m'])}",
                      "mean offset n, e → RMSE without":
                          f"{_signed(d['offset_n_m'])}, {_signed(d['offset_e_m'])} → {_f(d['no_offset_m'])}",
                      "hover / circle / stop":
                          " / ".join(_f(d[k]) for k in ("hover_m", "circle_m", "stop_m")),
                      "LTI bound": _f(b["lti_bound_m"]), "PX4 mean": _f(b["px4_mean_m"]),
                      "PX4 residual (own LTI fit)": _f(b["px4_resid_m"])})
    return {"formation_full": pd.DataFrame(full), "formation_summary": pd.DataFrame(summary),
            "decomposition": pd.DataFrame(parts), "legs": legs_table(runs)}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--runs", type=Path, help="keep the sim runs here (finished ones are reused)")
    ap.add_argument("--out", type=Path, default=RESULTS)
    args = ap.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        runs = fly(args.runs or Path(tmp))
        built = tables(runs)
    args.out.mkdir(parents=True, exist_ok=True)
    for name, frame in built.items():
        frame.to_csv(args.out / f"{name}.csv", index=False)
        print(f"{args.out / name}.csv\n{frame.to_string(index=False)}\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
