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
and between drones: near 1 when the SIH instances draw the same noise sequence.

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
FIR_S = 4.0


def _z(f: pd.DataFrame, rel: np.ndarray, prefix: str = "pos", shift_s: float = 0.0) -> np.ndarray:
    """Horizontal series as complex n + i·e on the clock ``rel`` from the flight's circle start."""
    h = F._h(f, prefix, F.circle_window(f)[0] + rel - shift_s)
    return h[0] + 1j * h[1]


def _rms(d: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.abs(d) ** 2)))


def _clock(flights: list[pd.DataFrame]) -> np.ndarray:
    span = min(b - a for a, b in map(F.circle_window, flights))
    return np.arange(-F.MARGIN_S, span + F.MARGIN_S, F.RESAMPLE_S)


def lti_fit(sp_flight: pd.DataFrame, target: np.ndarray, rel: np.ndarray) -> np.ndarray:
    """The best FIR (FIR_S long) + constant response to ``sp_flight``'s setpoint, fitted to ``target``."""
    taps = round(FIR_S / F.RESAMPLE_S)
    wide = _z(sp_flight, np.concatenate([rel[0] - F.RESAMPLE_S * np.arange(taps - 1, 0, -1), rel]), "sp")
    x = np.array([wide[taps - 1 - k: taps - 1 - k + len(rel)] for k in range(taps)] + [np.ones(len(rel))]).T
    # normal equations with a tiny ridge (einsum, and a 41x41 solve: multi-threaded BLAS lstsq on
    # this small problem stalls for seconds on a loaded machine)
    gram = np.einsum("ti,tj->ij", x.conj(), x)
    gram += 1e-9 * np.trace(gram).real / len(gram) * np.eye(len(gram))
    h = np.linalg.solve(gram, np.einsum("ti,t->i", x.conj(), target))
    return np.einsum("ti,i->t", x, h)


def bounds(px4: dict[str, dict[int, pd.DataFrame]], drone: int) -> dict[str, float]:
    """PX4-only figures for one drone: the LTI bound, the PX4 mean, the floors."""
    runs = [r[drone] for r in px4.values()]
    rel = _clock(runs)
    zp = [_z(r, rel) for r in runs]
    mean = np.mean(zp, axis=0)
    lti = lti_fit(runs[0], mean, rel)
    pairs = [_rms(a - b) for k, a in enumerate(zp) for b in zp[k + 1:]]
    resid = [z - lti_fit(r, z, rel) for r, z in zip(runs, zp)]
    corr = [float(np.real(np.vdot(a, b)) / np.linalg.norm(a) / np.linalg.norm(b))
            for k, a in enumerate(resid) for b in resid[k + 1:]]
    return {"lti_bound_m": float(np.mean([_rms(lti - z) for z in zp])),
            "px4_mean_m": float(np.mean([_rms(mean - z) for z in zp])),
            "floor_mean_pairs_m": float(np.mean(pairs)), "floor_max_pair_m": float(max(pairs)),
            "px4_resid_m": float(np.mean([_rms(r) for r in resid])),
            "resid_corr_pairs": "/".join(f"{c:.2f}" for c in corr)}


def split(sim: pd.DataFrame, px4: dict[str, dict[int, pd.DataFrame]], drone: int) -> dict[str, float]:
    """The sim-vs-PX4 RMSE of one drone, split (mean over the PX4 flights)."""
    runs = [r[drone] for r in px4.values()]
    rel = _clock([sim, *runs])
    zs, zp = _z(sim, rel), [_z(r, rel) for r in runs]
    score = lambda z: float(np.mean([_rms(z - p) for p in zp]))  # noqa: E731
    shifts = np.arange(-1.0, 1.0, 0.02)
    errs = [score(_z(sim, rel, shift_s=-s)) for s in shifts]
    end = rel[-1] - F.MARGIN_S
    phase = {name: float(np.mean([_rms((zs - p)[m]) for p in zp]))
             for name, m in (("hover_m", rel < 0), ("circle_m", (rel >= 0) & (rel <= end)), ("stop_m", rel > end))}
    offset = np.mean([np.mean(zs - p) for p in zp])
    return {"sim_vs_px4_m": score(zs), "best_shift_s": float(shifts[int(np.argmin(errs))]),
            "shifted_m": float(min(errs)), "offset_n_m": float(offset.real), "offset_e_m": float(offset.imag),
            "no_offset_m": float(np.mean([_rms(zs - p - np.mean(zs - p)) for p in zp])), **phase}


def residual_corr_between_drones(px4: dict[str, dict[int, pd.DataFrame]], run: str) -> float:
    """Mean correlation of the residuals (path minus its LTI fit) of different drones in one run."""
    flights = px4[run]
    rel = _clock(list(flights.values()))
    res = [(_z(f, rel) - lti_fit(f, _z(f, rel), rel)) for f in flights.values()]
    cs = [float(np.real(np.vdot(a, b)) / np.linalg.norm(a) / np.linalg.norm(b))
          for k, a in enumerate(res) for b in res[k + 1:]]
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
