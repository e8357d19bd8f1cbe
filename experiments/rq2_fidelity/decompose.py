"""Where the sim-vs-PX4 circle error comes from, and the least any deterministic sim can score.

For one sim flight per drone against the recorded PX4 flights (``data/px4_formation.parquet``), on
the window :func:`fidelity.rmse_flights` compares (each flight timed from its own circle start, 5 s
margins), the sim-vs-PX4 RMSE is split into:

- *best time shift*: the RMSE after shifting the sim by the time that minimises it (a start-up or
  lag mismatch would show here);
- *mean offset removed*: the RMSE after removing the mean sim − PX4 difference (a constant offset of
  PX4's estimate);
- *per phase*: before the circle (hover), on the circle, after it (stop and LAND);
- *LTI bound*: the best linear time-invariant response to the setpoint — a 4 s complex FIR filter
  plus a constant, least squares, fitted to the mean of the PX4 flights themselves (in-sample, so
  optimistic) — scored against each PX4 flight like the sim. The cascaded controller is linear on
  this mission (no saturation on a 1.2–1.6 m/s circle), so no choice of its gains, delays or limits
  can score below this;
- *PX4 mean*: the mean of the PX4 flights scored against each of them — only reachable by a model
  that reproduces PX4's own sensor-noise realisation.

Also the correlation of the PX4 flights' residuals (flown path minus its own LTI fit) between runs
(:func:`fidelity.noise_corr`, the largest over time shifts up to 10 s) and between drones: near 1
when the SIH instances draw the same noise sequence.

    python experiments/rq2_fidelity/decompose.py RUN_DIR      # a sim run of the RQ2 formation
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
import pandas as pd

sys.path.insert(0, str(Path(__file__).resolve().parent))
import fidelity as F  # noqa: E402
from flights import load_reference, run_flights  # noqa: E402

REFERENCE = Path(__file__).resolve().parent / "data" / "px4_formation.parquet"
_z, _rms, _corr = F._z, F._rms, F._corr


def bounds(px4: dict[str, dict[int, pd.DataFrame]], drone: int) -> dict[str, float]:
    """PX4-only figures for one drone: the LTI bound, the PX4 mean, the floor (mean over the pairs
    of independent noise, as fidelity.table) and the largest pair."""
    runs = [r[drone] for r in px4.values()]
    rel = F.clock(runs)
    zp = [_z(r, rel) for r in runs]
    mean = np.mean(zp, axis=0)
    lti = F.lti_fit(runs[0], mean, rel)
    pairs = [_rms(a - b) for k, a in enumerate(zp) for b in zp[k + 1:]]
    resid = [F.residual(r, rel) for r in runs]
    corr = [F.noise_corr(a, b) for k, a in enumerate(runs) for b in runs[k + 1:]]
    free = [p for p, c in zip(pairs, corr, strict=True) if c < F.SAME_NOISE]
    return {"lti_bound_m": float(np.mean([_rms(lti - z) for z in zp])),
            "px4_mean_m": float(np.mean([_rms(mean - z) for z in zp])),
            "floor_mean_pairs_m": float(np.mean(free)) if free else np.nan,
            "floor_max_pair_m": float(max(pairs)),
            "px4_resid_m": float(np.mean([_rms(r) for r in resid])),
            "resid_corr_pairs": "/".join(f"{c:.2f}" for c in corr)}


def split(sim: pd.DataFrame, px4: dict[str, dict[int, pd.DataFrame]], drone: int) -> dict[str, float]:
    """The sim-vs-PX4 RMSE of one drone, split (mean over the PX4 flights)."""
    runs = [r[drone] for r in px4.values()]
    rel = F.clock([sim, *runs])
    zs, zp = _z(sim, rel), [_z(r, rel) for r in runs]
    score = lambda z: float(np.mean([_rms(z - p) for p in zp]))  # noqa: E731
    shifts = np.arange(-1.0, 1.0, 0.02)
    errs = [score(_z(sim, rel, shift_s=-s)) for s in shifts]
    end = rel[-1] - F.MARGIN_S
    masks = (("hover_m", rel < 0), ("circle_m", (rel >= 0) & (rel <= end)), ("stop_m", rel > end))
    phase = {name: float(np.mean([_rms((zs - p)[m]) for p in zp])) for name, m in masks}
    offset = np.mean([np.mean(zs - p) for p in zp])
    return {"sim_vs_px4_m": score(zs), "best_shift_s": float(shifts[int(np.argmin(errs))]),
            "shifted_m": float(min(errs)), "offset_n_m": float(offset.real), "offset_e_m": float(offset.imag),
            "no_offset_m": float(np.mean([_rms(zs - p - np.mean(zs - p)) for p in zp])), **phase}


def residual_corr_between_drones(px4: dict[str, dict[int, pd.DataFrame]], run: str) -> float:
    """Mean correlation of the residuals (path minus its LTI fit) of different drones in one run."""
    flights = px4[run]
    rel = F.clock(list(flights.values()))
    res = [F.residual(f, rel) for f in flights.values()]
    cs = [_corr(a, b) for k, a in enumerate(res) for b in res[k + 1:]]
    return float(np.mean(cs))


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("run_dir", type=Path, help="a sim run of the RQ2 formation")
    ap.add_argument("--reference", type=Path, default=REFERENCE)
    args = ap.parse_args(argv)
    px4, sim = load_reference(args.reference), run_flights(args.run_dir)
    rows = [{"drone": i, **split(sim[i], px4, i), **bounds(px4, i)} for i in sorted(sim)]
    pd.set_option("display.width", 200)
    print(pd.DataFrame(rows).round(3).to_string(index=False))
    for run in px4:
        print(f"{run}: residual correlation between drones {residual_corr_between_drones(px4, run):.2f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
