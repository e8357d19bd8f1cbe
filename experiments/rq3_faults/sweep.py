"""Run plans of the RQ3 study and of the diagnosis benchmark, and their execution.

Every run is one configuration of ``python -m swarmbox.run`` (its overrides are listed in
``plan.csv``, so any run can be replayed on its own). Runs execute in-process, two at a time in
joblib workers (the shared machine's cores); a run directory that already holds a finished run is
skipped, so an interrupted sweep resumes where it stopped. After each run its diagnosis rows
(:func:`swarmbox.analysis.detection.evaluate_run`) are written next to it as ``diagnosis.parquet``.

    python experiments/rq3_faults/sweep.py rq3   OUT      # the paper's 135 runs
    python experiments/rq3_faults/sweep.py bench OUT      # the detection benchmark
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd

ROOT = Path(__file__).resolve().parents[2]
#: The benchmark's magnitudes, from below the noise floor up (fault model -> override, values).
MAGNITUDES = {
    "gps_drift": ("fault.rate_m_s", (0.25, 0.5, 1.0, 2.0)),
    "gps_bias": ("fault.bias_ned_m", ([0.5, 0, 0], [1.0, 0, 0], [2.0, 0, 0], [4.0, 0, 0])),
    "gps_noise": ("fault.noise_scale", (5.0, 10.0, 20.0, 40.0)),
    "latency": ("fault.latency_ms", (0.5, 1.0, 2.0, 5.0)),
    "packet_loss": ("fault.loss_prob", (0.02, 0.05, 0.1, 0.2)),
    "burst_loss": ("fault.p_enter_burst", (0.005, 0.01, 0.02, 0.05)),
}
WINDOW = ("fault.onset_s=25.0", "fault.duration_s=20.0")
#: The benchmark flies the RQ3 circle at the same speed on half the radius (one lap in ~24 s), and
#: the fault is on from 12 s to 27 s: half the simulation of the RQ3 runs, so that ~1,000 runs fit
#: the shared 2-core machine.
SHORT = ("algo.params.radius_m=25.0", "algo.params.angular_rate_rad_s=0.26667")
BENCH_WINDOW = ("fault.onset_s=12.0", "fault.duration_s=15.0")
#: With 36 drones (eight times the simulation and analysis per run) the sweep keeps the paper's
#: three faults and the magnitudes around the 9-drone noise floor.
MAGNITUDES_36 = {"gps_drift": (0.5, 1.0, 2.0), "latency": (1.0, 2.0, 5.0), "packet_loss": (0.05, 0.1, 0.2)}
NETWORKS = {"ideal": ("network=ideal", "network.latency_ms=1.0", "network.jitter_ms=1.0"),
            "wifi": ("network=wifi",)}
SIZES = {9: "mission=formation9", 36: "mission=formation36"}
RQ3 = {"drift": ("gps_drift", "fault.rate_m_s", (1.0, 2.0, 3.0, 4.0, 5.0)),
       "latency": ("latency", "fault.latency_ms", (5.0, 10.0, 15.0, 20.0, 25.0)),
       "loss": ("packet_loss", "fault.loss_prob", (0.1, 0.2, 0.3, 0.4, 0.5))}


def execute(run_dir: Path, overrides: list[str]) -> None:
    """Compose and run one configuration exactly as ``python -m swarmbox.run <overrides>`` does."""
    from hydra import compose, initialize_config_dir
    from hydra.core.global_hydra import GlobalHydra
    from omegaconf import OmegaConf, open_dict

    from swarmbox.run.config import register
    from swarmbox.run.runner import execute as run
    from swarmbox.run.runner import run_choices

    register()
    GlobalHydra.instance().clear()
    with initialize_config_dir(config_dir=str(ROOT / "swarmbox" / "conf"), version_base="1.3"):
        cfg = compose("config", overrides=list(overrides), return_hydra_config=True)
    choices = run_choices(cfg, OmegaConf.to_container(cfg.hydra.runtime.choices))
    with open_dict(cfg):
        del cfg["hydra"]
    run(cfg, run_dir, choices, list(overrides))


def _value(v) -> str:
    return f"[{','.join(str(float(x)) for x in v)}]" if isinstance(v, list | tuple) else str(v)


def rq3_plan() -> list[tuple[str, list[str]]]:
    """The paper's study: 3 faults x 5 magnitudes x 9 target drones, seed 0, 9 drones, base network."""
    plan = []
    for kind, (model, key, values) in RQ3.items():
        for i, v in enumerate(values):
            for target in range(9):
                plan.append((f"{kind}/m{i}_t{target}",
                             ["+experiment=rq3_bench", f"fault={model}", f"{key}={v}",
                              f"fault.targets=[{target}]", *WINDOW, *NETWORKS["ideal"], SIZES[9], "seed=0"]))
    return plan


def bench_plan(reps: dict[int, int], healthy: dict[int, int], seed: int = 17) -> list[tuple[str, list[str]]]:
    """Faults x magnitudes x sizes x networks x ``reps[size]`` seeds (a seeded random target per run),
    plus ``healthy[size]`` fault-free runs per size and network; ordered replicate by replicate, so
    that a sweep cut short still covers every cell."""
    rng = np.random.default_rng(seed)
    plan = []
    for n, mission in SIZES.items():
        for net, net_over in NETWORKS.items():
            common = ["+experiment=rq3_bench", *SHORT, *net_over, mission]
            for r in range(healthy[n]):
                plan.append((r, f"n{n}/{net}/none/r{r}", [*common, "fault=none", f"seed={100 + r}"]))
            for model, (key, values) in MAGNITUDES.items():
                for i, v in enumerate(values):
                    if n == 36 and v not in MAGNITUDES_36.get(model, ()):
                        continue
                    for r in range(reps[n]):
                        target = int(rng.integers(n))
                        plan.append((r, f"n{n}/{net}/{model}/m{i}_r{r}",
                                     [*common, f"fault={model}", f"{key}={_value(v)}",
                                      f"fault.targets=[{target}]", *BENCH_WINDOW, f"seed={r}"]))
    return [(name, overrides) for _, name, overrides in sorted(plan, key=lambda p: p[0])]


def run_one(out: Path, name: str, overrides: list[str]) -> str:
    """Execute one planned run (unless finished) and write its diagnosis rows; returns a status line."""
    from swarmbox.analysis.detection import default_settings, evaluate_run

    run_dir = out / name
    t0 = time.time()
    if not (run_dir / "run.json").exists():
        execute(run_dir, overrides)
    status = json.loads((run_dir / "run.json").read_text())["status"]
    t1 = time.time()
    if not (run_dir / "diagnosis.parquet").exists():
        rows = evaluate_run(run_dir, default_settings())
        rows.to_parquet(run_dir / "diagnosis.parquet.tmp", index=False)
        (run_dir / "diagnosis.parquet.tmp").rename(run_dir / "diagnosis.parquet")
    return f"{name} {status} run {t1 - t0:.1f}s diag {time.time() - t1:.1f}s"


def collect(out: Path) -> pd.DataFrame:
    """Every run's diagnosis rows below ``out``."""
    parts = [pd.read_parquet(p) for p in sorted(out.rglob("diagnosis.parquet"))]
    return pd.concat(parts, ignore_index=True) if parts else pd.DataFrame()


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("which", choices=["rq3", "bench"])
    p.add_argument("out", type=Path)
    p.add_argument("--jobs", type=int, default=2)
    p.add_argument("--reps", type=int, nargs=2, default=(3, 2), metavar=("N9", "N36"),
                   help="seeds per fault and magnitude, for 9 and for 36 drones (3 2)")
    p.add_argument("--healthy", type=int, nargs=2, default=(4, 2), metavar=("N9", "N36"),
                   help="fault-free runs per network, for 9 and for 36 drones (4 2)")
    args = p.parse_args(argv)
    from joblib import Parallel, delayed

    if args.which == "rq3":
        plan = rq3_plan()
    else:
        reps = dict(zip(SIZES, args.reps, strict=True))
        plan = bench_plan(reps, dict(zip(SIZES, args.healthy, strict=True)))
    args.out.mkdir(parents=True, exist_ok=True)
    listing = pd.DataFrame([{"run": n, "overrides": " ".join(o)} for n, o in plan])
    listing.to_csv(args.out / "plan.csv", index=False)
    start = time.time()
    jobs = (delayed(run_one)(args.out, n, o) for n, o in plan)
    for line in Parallel(n_jobs=args.jobs, return_as="generator")(jobs):
        print(f"[{time.time() - start:7.1f}s] {line}", flush=True)
    print(f"{len(plan)} runs in {time.time() - start:.0f} s wall", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
